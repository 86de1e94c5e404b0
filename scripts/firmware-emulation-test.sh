#!/usr/bin/env bash
# The RP2040 release binary in the loop: runs the emulator glue's unit tests
# (emulator/test/) and the firmware-emulation system tests
# (tests/tests/firmware_emulation.rs) against the ELF that `cargo build --release` in
# firmware/rp2040 produced, in the emulated chip of emulator/ (rp2040js, pinned by
# emulator/package-lock.json). Needs Node.js >= 20 and `npm ci` in emulator/ (.ci/run does
# both). Prints "N passed, M failed" last; exits non-zero if any test failed or none ran.
#
#   scripts/firmware-emulation-test.sh            # uses firmware/rp2040/target/.../tactile-rp2040
#   TACTILE_FIRMWARE_ELF=path/to.elf scripts/firmware-emulation-test.sh
set -uo pipefail
cd "$(dirname "$0")/.."

elf="${TACTILE_FIRMWARE_ELF:-firmware/rp2040/target/thumbv6m-none-eabi/release/tactile-rp2040}"
if [ ! -f "$elf" ]; then
    echo "firmware ELF $elf not found: cd firmware/rp2040 && cargo build --release" >&2
    echo "0 passed, 1 failed"
    exit 1
fi
if ! command -v node >/dev/null; then
    echo "node not found (Node.js >= 20 runs the emulator)" >&2
    echo "0 passed, 1 failed"
    exit 1
fi
if [ ! -f emulator/node_modules/rp2040js/package.json ]; then
    echo "emulator packages missing: (cd emulator && npm ci)" >&2
    echo "0 passed, 1 failed"
    exit 1
fi
export TACTILE_FIRMWARE_ELF="$(cd "$(dirname "$elf")" && pwd)/$(basename "$elf")"

start=$(date +%s)
log=$(mktemp)
trap 'rm -f "$log"' EXIT

# The glue's own unit tests (no firmware image needed).
node --test emulator/test/ 2>&1 | tee "$log"
node_status=${PIPESTATUS[0]}
node_passed=$(grep -Eo '^# pass [0-9]+' "$log" | grep -Eo '[0-9]+' | tail -1)
node_failed=$(grep -Eo '^# fail [0-9]+' "$log" | grep -Eo '[0-9]+' | tail -1)
node_passed=${node_passed:-0}
node_failed=${node_failed:-0}
if [ "$node_status" -ne 0 ] && [ "$node_failed" -eq 0 ]; then
    node_failed=1
fi
# One test at a time: each runs an emulated chip in real time or slower; two at once on a
# 2-core machine would only slow both. The timeout bounds a wedged emulator.
timeout 600 cargo test -p system-tests --test firmware_emulation -- \
    --ignored --test-threads=1 2>&1 | tee "$log"
status=${PIPESTATUS[0]}

passed=$(grep -Eo '^test result: .* ([0-9]+) passed' "$log" | grep -Eo '[0-9]+ passed' | grep -Eo '[0-9]+' | tail -1)
failed=$(grep -Eo '^test result: .* ([0-9]+) failed' "$log" | grep -Eo '[0-9]+ failed' | grep -Eo '[0-9]+' | tail -1)
passed=${passed:-0}
failed=${failed:-0}
if [ "$status" -ne 0 ] && [ "$failed" -eq 0 ]; then
    failed=1   # build failure, timeout or crash: count it
fi
passed=$(( passed + node_passed ))
failed=$(( failed + node_failed ))
echo "firmware emulation tier: $(( $(date +%s) - start )) s"
echo "$passed passed, $failed failed"
[ "$status" -eq 0 ] && [ "$node_status" -eq 0 ] && [ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
