#!/usr/bin/env bash
# Size budget of the RP2040 firmware: flash <= 96 KiB, static RAM <= 16 KiB.
#
# Reads the ELF's section headers with od (coreutils only; no llvm-size or python needed):
# - flash = every allocated section placed in flash (0x10000000..0x11000000: boot2, vector
#   table, code, read-only data) + the initial image of every allocated PROGBITS section in
#   RAM (.data is copied from flash at boot);
# - static RAM = every allocated section in RAM (0x20000000..0x20042000: .data, .bss,
#   .uninit); the stack is the rest of RAM and is not static.
#
# Usage: scripts/check-firmware-size.sh [ELF]   (default: the release build of
# firmware/rp2040 in $CARGO_TARGET_DIR or firmware/rp2040/target). Exit 1 when over budget,
# 2 on a missing or malformed ELF. FLASH_BUDGET_KIB / RAM_BUDGET_KIB override the budgets
# (to see the check fail).
set -euo pipefail
cd "$(dirname "$0")/.."

FLASH_BUDGET=$((${FLASH_BUDGET_KIB:-96} * 1024))
RAM_BUDGET=$((${RAM_BUDGET_KIB:-16} * 1024))

elf="${1:-}"
if [ -z "$elf" ]; then
    target_dir="${CARGO_TARGET_DIR:-target}"
    case "$target_dir" in
        /*) ;;
        *) target_dir="firmware/rp2040/$target_dir" ;;
    esac
    elf="$target_dir/thumbv6m-none-eabi/release/tactile-rp2040"
fi
if [ ! -f "$elf" ]; then
    echo "check-firmware-size: $elf not found (build it: cd firmware/rp2040 && cargo build --release)" >&2
    exit 2
fi

# u32/u16 little-endian at a byte offset.
u32() { od -An -t u4 -j "$2" -N 4 --endian=little "$1" | tr -d ' '; }
u16() { od -An -t u2 -j "$2" -N 2 --endian=little "$1" | tr -d ' '; }

if [ "$(od -An -t x1 -N 6 "$elf" | tr -d ' ')" != "7f454c460101" ]; then
    echo "check-firmware-size: $elf is not a 32-bit little-endian ELF" >&2
    exit 2
fi
shoff=$(u32 "$elf" 32)
shentsize=$(u16 "$elf" 46)
shnum=$(u16 "$elf" 48)

SHT_NOBITS=8
SHF_ALLOC=2
flash=0
ram=0
for ((i = 0; i < shnum; i++)); do
    base=$((shoff + i * shentsize))
    # sh_name, sh_type, sh_flags, sh_addr, sh_offset, sh_size
    read -r _ type flags addr _ size < <(od -An -v -w24 -t u4 -j "$base" -N 24 --endian=little "$elf")
    if (( (flags & SHF_ALLOC) == 0 || size == 0 )); then
        continue
    fi
    if (( addr >= 0x10000000 && addr < 0x11000000 )); then
        flash=$((flash + size))
    elif (( addr >= 0x20000000 && addr < 0x20042000 )); then
        ram=$((ram + size))
        if (( type != SHT_NOBITS )); then
            flash=$((flash + size))
        fi
    fi
done

kib() { printf '%d.%d' $(($1 / 1024)) $(($1 * 10 / 1024 % 10)); }
echo "firmware size ($elf):"
echo "  flash      $flash bytes ($(kib "$flash") KiB of $((FLASH_BUDGET / 1024)) KiB)"
echo "  static RAM $ram bytes ($(kib "$ram") KiB of $((RAM_BUDGET / 1024)) KiB)"
status=0
if (( flash > FLASH_BUDGET )); then
    echo "check-firmware-size: flash $flash bytes exceeds the budget of $FLASH_BUDGET" >&2
    status=1
fi
if (( ram > RAM_BUDGET )); then
    echo "check-firmware-size: static RAM $ram bytes exceeds the budget of $RAM_BUDGET" >&2
    status=1
fi
exit $status
