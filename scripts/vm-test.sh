#!/usr/bin/env bash
# The kernel-driver tier: the release binaries of `tactile` and `hil-sim` in a virtual
# machine (qemu-system-x86_64, Debian's stock kernel, a busybox initramfs), talking through
# Linux's own drivers: a CDC-ACM USB gadget on dummy_hcd (cdc-acm on the host side,
# /dev/ttyACM0, VID:PID 1209:7AC7) served by hil-sim on /dev/ttyGS0, an RP2040 boot ROM
# (2E8A:0003, PICOBOOT through FunctionFS, served by hil-sim's picoboot-gadget) that
# `tactile flash` writes through libusb, and vivid's video output -> capture loop carrying
# hil-sim's rendered frames to `tactile`'s V4L2 capture (and v4l2loopback, the loopback a
# workstation uses, built from Debian's source against that kernel).
# The cases themselves are scripts/vm/cases.sh (run by scripts/vm/init.sh as PID 1).
#
# Installs what it needs (idempotent): qemu-system-x86, busybox-static and v4l-utils (its
# v4l2-ctl sets vivid up inside the machine) from Debian, and Debian's kernel package,
# downloaded once into target/vm-cache (never into git), with its linux-headers package,
# make and gcc to build v4l2loopback's module into the same cache. Prints one line per case and
# `N passed, M failed` last; exits non-zero on any failure or if the VM does not finish
# within VM_TIMEOUT_S.
#
# Environment: VM_TIMEOUT_S (default 420: boot and cases take about a minute under TCG
# emulation without KVM; a loaded 2-core machine may need several times that),
# VM_SKIP_BUILD=1 (use the existing release binaries), VM_KEEP=1 (keep the initramfs
# tree), VM_CASES=a,b (only these cases of scripts/vm/cases.sh), VM_CPUS (default 2),
# VM_MEM_MB (default 1024), VM_ACCEL=kvm (hardware virtualisation instead of TCG),
# TACTILE_FIRMWARE_ELF (the firmware the flashing case writes; default the release build of
# firmware/rp2040 if there is one, else a small test image).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

cache=target/vm-cache
work=target/vm-work
timeout_s=${VM_TIMEOUT_S:-420}
cpus=${VM_CPUS:-2}
mem=${VM_MEM_MB:-1024}
started=$(date +%s)
say() { printf 'vm-test: %s\n' "$*" >&2; }

# --- 1. host packages ------------------------------------------------------------------
need_pkgs=()
command -v qemu-system-x86_64 >/dev/null || need_pkgs+=(qemu-system-x86)
dpkg -s busybox-static >/dev/null 2>&1 || need_pkgs+=(busybox-static)
command -v v4l2-ctl >/dev/null || need_pkgs+=(v4l-utils)
# Installs the Debian packages named (with sudo where it is needed and present).
install_pkgs() {
    local sudo=
    if command -v sudo >/dev/null && [ "$(id -u)" -ne 0 ]; then sudo=sudo; fi
    say "installing $*"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "$@" \
        >/dev/null
}
if [ "${#need_pkgs[@]}" -gt 0 ]; then install_pkgs "${need_pkgs[@]}"; fi
busybox=/bin/busybox
ldd_out=$(LC_ALL=C ldd "$busybox" 2>&1 || true)
if ! grep -q 'not a dynamic' <<<"$ldd_out"; then
    say "$busybox is not the static busybox (install busybox-static)"
    exit 1
fi

# --- 2. the kernel (downloaded once) ---------------------------------------------------
mkdir -p "$cache"
if ! ls "$cache"/kernel/boot/vmlinuz-* >/dev/null 2>&1; then
    say "downloading Debian's kernel package into $cache"
    image=$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-[0-9]/ {print $2; exit}')
    if [ -z "$image" ]; then
        say "cannot resolve linux-image-amd64 (apt-get update?)"
        exit 1
    fi
    (cd "$cache" && apt-get download "$image" 2>/dev/null)
    rm -rf "$cache/kernel.tmp"
    dpkg-deb -x "$cache/$image"_*.deb "$cache/kernel.tmp"
    mv "$cache/kernel.tmp" "$cache/kernel"
fi
vmlinuz=$(ls "$cache"/kernel/boot/vmlinuz-* | head -n 1)
kver=${vmlinuz##*/vmlinuz-}
moddir="$cache/kernel/lib/modules/$kver"

# --- 2b. v4l2loopback, the out-of-tree video loopback a workstation uses (built once) --
# from Debian's v4l2loopback-dkms source against that kernel's headers (linux-headers-*,
# installed like the packages above; the module builds in seconds)
loopback_ko="$cache/v4l2loopback-$kver/v4l2loopback.ko"
if [ ! -f "$loopback_ko" ]; then
    need_pkgs=()
    [ -d "/usr/src/linux-headers-$kver" ] || need_pkgs+=("linux-headers-$kver")
    command -v make >/dev/null || need_pkgs+=(make)
    command -v gcc >/dev/null || need_pkgs+=(gcc)
    if [ "${#need_pkgs[@]}" -gt 0 ]; then install_pkgs "${need_pkgs[@]}"; fi
    rm -rf "$cache/v4l2loopback.tmp"
    mkdir -p "$cache/v4l2loopback.tmp"
    (cd "$cache/v4l2loopback.tmp" && apt-get download v4l2loopback-dkms 2>/dev/null)
    dpkg-deb -x "$cache"/v4l2loopback.tmp/v4l2loopback-dkms_*.deb "$cache/v4l2loopback.tmp/x"
    src=$(ls -d "$cache"/v4l2loopback.tmp/x/usr/src/v4l2loopback-* | head -n 1)
    make -s -C "/usr/src/linux-headers-$kver" M="$root/$src" modules >/dev/null
    mkdir -p "$(dirname "$loopback_ko")"
    cp "$src/v4l2loopback.ko" "$loopback_ko"
    rm -rf "$cache/v4l2loopback.tmp"
    say "built v4l2loopback ($(basename "$src")) for $kver"
fi

# --- 3. the release binaries -----------------------------------------------------------
if [ "${VM_SKIP_BUILD:-0}" != 1 ]; then
    build_start=$(date +%s)
    cargo build --release -p tactile -p hil-sim
    say "release build: $(($(date +%s) - build_start)) s"
fi
bins=(target/release/tactile target/release/hil-sim target/release/picoboot-gadget)
for b in "${bins[@]}"; do
    [ -x "$b" ] || { say "$b missing (cargo build --release -p tactile -p hil-sim)"; exit 1; }
done

# --- 4. the initramfs ------------------------------------------------------------------
rm -rf "$work"
tree="$work/root"
mkdir -p "$tree"/{bin,sbin,dev,proc,sys,tmp,run,etc,lib/modules,data,usr/bin}
cp "$busybox" "$tree/bin/busybox"
v4l2ctl=$(command -v v4l2-ctl)
for b in "${bins[@]}" "$v4l2ctl"; do cp "$b" "$tree/usr/bin/"; done
# without their debug information (a quarter of the size: a smaller, faster initramfs)
if command -v strip >/dev/null; then strip --strip-debug "$tree"/usr/bin/*; fi
# Shared libraries of the binaries (glibc and friends), at the paths the loader expects.
for lib in $(ldd "${bins[@]}" "$v4l2ctl" 2>/dev/null | awk '$2 == "=>" && $3 ~ /^\// {print $3} $1 ~ /^\// && NF > 1 {print $1}' | sort -u); do
    mkdir -p "$tree$(dirname "$lib")"
    cp -L "$lib" "$tree$lib"
done
cp -r fem-core/data/. "$tree/data/"
cp -r hil-sim/scenarios "$tree/data/scenarios"
# Images for the flashing cases: the firmware ELF if it has been built (TACTILE_FIRMWARE_ELF,
# or the release build of firmware/rp2040), and two small ELF files written here: 20000
# bytes of a repeated text at 0x10000000 (flashed when there is no firmware build, and cut
# short for a refused image), and the same at 0x20000000 (RAM: refused).
firmware_elf=${TACTILE_FIRMWARE_ELF:-firmware/rp2040/target/thumbv6m-none-eabi/release/tactile-rp2040}
if [ -f "$firmware_elf" ]; then cp "$firmware_elf" "$tree/data/firmware.elf"; fi
le32() { printf "$(printf '\\x%02x\\x%02x\\x%02x\\x%02x' $(($1 & 255)) $(($1 >> 8 & 255)) $(($1 >> 16 & 255)) $(($1 >> 24 & 255)))"; }
le16() { printf "$(printf '\\x%02x\\x%02x' $(($1 & 255)) $(($1 >> 8 & 255)))"; }
# ELF32 little-endian ARM executable with one PT_LOAD segment of $2 bytes at $1 (System V
# ABI: 52-byte header, 32-byte program header, the segment's bytes at offset 84).
test_elf() {
    printf '\x7fELF\x01\x01\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00'
    le16 2; le16 40; le32 1; le32 $(($1 + 1)); le32 52; le32 0; le32 0x05000200
    le16 52; le16 32; le16 1; le16 40; le16 0; le16 0
    le32 1; le32 84; le32 "$1"; le32 "$1"; le32 "$2"; le32 "$2"; le32 5; le32 4
    awk -v n="$2" 'BEGIN { while (length(s) < n) s = s "picoboot test image, page after page "
        printf "%s", substr(s, 1, n) }'
}
test_elf 0x10000000 20000 >"$tree/data/test-image.elf"
test_elf 0x20000000 20000 >"$tree/data/ram-image.elf"
cp scripts/vm/init.sh "$tree/init"
cp scripts/vm/cases.sh "$tree/cases.sh"
chmod +x "$tree/init" "$tree/cases.sh"

# Kernel modules with their dependencies (from each module's own `depends=` field: the
# package ships no modules.dep), in load order.
declare -A modpath=()
while IFS= read -r f; do
    n=${f##*/}
    n=${n%.ko}
    modpath[${n//-/_}]=$f
done < <(find "$moddir/kernel" -name '*.ko')
modpath[v4l2loopback]=$loopback_ko
declare -A loaded=()
order=()
add_module() {
    local name=${1//-/_} dep deps
    [ -n "${loaded[$name]:-}" ] && return 0
    local f=${modpath[$name]:-}
    if [ -z "$f" ]; then
        # built into the kernel
        grep -q "/${1}.ko\$\|/${name}.ko\$" "$moddir/modules.builtin" && return 0
        say "kernel module $1 not found"
        exit 1
    fi
    deps=$(tr '\0' '\n' <"$f" | sed -n 's/^depends=//p' | head -n 1)
    for dep in ${deps//,/ }; do add_module "$dep"; done
    loaded[$name]=1
    order+=("$name")
}
for m in configfs dummy_hcd libcomposite usb_f_acm usb_f_fs cdc_acm vivid v4l2loopback; do add_module "$m"; done
for m in "${order[@]}"; do
    cp "${modpath[$m]}" "$tree/lib/modules/$m.ko"
done
printf '%s\n' "${order[@]}" >"$tree/lib/modules/order"

(cd "$tree" && find . | LC_ALL=C sort | "$root/$tree/bin/busybox" cpio -o -H newc 2>/dev/null) \
    | gzip -1 >"$work/initramfs.gz"
say "initramfs: $(du -h "$work/initramfs.gz" | cut -f1), kernel $kver, modules: ${order[*]}"

# --- 5. boot ---------------------------------------------------------------------------
log="$work/console.log"
# TCG emulation by default (what the timeouts are sized for): a /dev/kvm that exists is no
# promise that it works (nested virtualisation without the MSRs qemu sets aborts at boot).
# VM_ACCEL=kvm where it does.
accel=(-accel tcg,thread=multi -cpu max)
if [ "${VM_ACCEL:-tcg}" = kvm ]; then accel=(-accel kvm -cpu host); fi
boot_start=$(date +%s)
set +e
timeout --foreground -k 10 "$timeout_s" qemu-system-x86_64 \
    -machine q35 "${accel[@]}" -smp "$cpus" -m "$mem" \
    -nographic -no-reboot -nodefaults -serial stdio -monitor none \
    -kernel "$vmlinuz" -initrd "$work/initramfs.gz" \
    -append "console=ttyS0 panic=-1 quiet loglevel=4 rdinit=/init${VM_CASES:+ vmtest.cases=$VM_CASES}" \
    </dev/null >"$log" 2>&1
qemu_rc=$?
set -e
boot_s=$(($(date +%s) - boot_start))
[ "${VM_KEEP:-0}" = 1 ] || rm -rf "$tree"

# --- 6. results ------------------------------------------------------------------------
tr -d '\r' <"$log" >"$log.txt"
passed=0
failed=0
while IFS= read -r line; do
    case "$line" in
    "VMTEST PASS "*) passed=$((passed + 1)); echo "ok    ${line#VMTEST PASS }" ;;
    "VMTEST FAIL "*) failed=$((failed + 1)); echo "FAIL  ${line#VMTEST FAIL }" ;;
    esac
done < <(grep -a '^VMTEST \(PASS\|FAIL\) ' "$log.txt")
if ! grep -a -q '^VMTEST END' "$log.txt"; then
    failed=$((failed + 1))
    if [ "$qemu_rc" -eq 124 ]; then
        echo "FAIL  vm: did not finish within ${timeout_s} s (VM_TIMEOUT_S)"
    else
        echo "FAIL  vm: ended before the last case (qemu exit $qemu_rc)"
    fi
    echo "----- last lines of the console ($log.txt) -----"
    tail -n 40 "$log.txt"
fi
if [ "$failed" -gt 0 ]; then
    echo "----- case output -----"
    grep -a '^  | ' "$log.txt" | tail -n 80 || true
fi
say "VM ${boot_s} s, total $(($(date +%s) - started)) s; console log: $log.txt"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
