#!/usr/bin/env bash
# The whole test suite: the repository's text checks, formatting, lints, the no_std checks,
# every test of the workspace, the RP2040 firmware's release build with its size budget, and
# that binary in the emulated chip against hil-sim's plant (scripts/firmware-emulation-test.sh),
# the daemon's web dashboard in headless Chromium (scripts/dashboard-browser-test.sh), and the
# release binaries over Linux's own USB serial and V4L2 drivers in a virtual machine
# (scripts/vm-test.sh). This is what CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }
start=$(date +%s)

step "text checks (scripts/check-words.sh)"
scripts/check-words.sh

step "cargo fmt --check (host workspace)"
cargo fmt --all --check
if [ -f firmware/rp2040/Cargo.toml ]; then
    step "cargo fmt --check (firmware/rp2040)"
    (cd firmware/rp2040 && cargo fmt --check)
fi

step "no_std: protocol and the controller logic for thumbv6m-none-eabi"
cargo check -p protocol -p controller --target thumbv6m-none-eabi
cargo check -p protocol --features defmt --target thumbv6m-none-eabi

step "cargo clippy (host workspace)"
cargo clippy --workspace --all-targets -- -D warnings

step "cargo test --workspace"
cargo test --workspace

if [ -f firmware/rp2040/Cargo.toml ]; then
    step "firmware/rp2040: clippy and release build"
    (cd firmware/rp2040 && cargo clippy --release -- -D warnings && cargo build --release)
    if [ -x scripts/check-firmware-size.sh ]; then
        step "firmware/rp2040: size budget"
        scripts/check-firmware-size.sh
    fi
    step "firmware/rp2040: the release binary in the emulated chip"
    scripts/firmware-emulation-test.sh
fi

step "the web dashboard in headless Chromium (scripts/dashboard-browser-test.sh)"
scripts/dashboard-browser-test.sh

step "kernel-driver tier: the release binaries in a virtual machine (scripts/vm-test.sh)"
if [ "${VM_TEST:-1}" = 0 ]; then
    echo "SKIPPED: VM_TEST=0 (CI runs it)"
else
    scripts/vm-test.sh
fi

printf '\nAll checks passed in %ss.\n' "$(( $(date +%s) - start ))"
