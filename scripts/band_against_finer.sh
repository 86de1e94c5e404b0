#!/usr/bin/env bash
# The converged band (the shipped tables' settings) against solves one refinement finer
# (`tactile lut build --edge-band --finer`: half the band's element size, sixteen elements
# through the shell's wall): both built on a small grid across the tables' range, then
# compared curve by curve at equal tube travel (fem-core's `band_against_finer` example).
#
#   scripts/band_against_finer.sh [OUTDIR]    # default target/band-against-finer
#
# The tables are kept in OUTDIR and reused (the finer one takes about 7 min on two cores).
# MODULI and PRESSURES (comma-separated, kPa) choose the grid.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/band-against-finer}
moduli=${MODULI:-20,100,400,1000}
pressures=${PRESSURES:-6,15}
cargo build -q --release -p tactile
mkdir -p "$out"
for table in converged finer; do
    f="$out/$table-$moduli-$pressures.lut"
    [ -s "$f" ] && continue
    flags=(--edge-band)
    [ "$table" = finer ] && flags+=(--finer)
    target/release/tactile lut build --grid default --modulus "$moduli" --pressure "$pressures" \
        "${flags[@]}" --out "$f" 2>"$out/$table-$moduli-$pressures.log"
done
cargo run -q --release -p fem-core --example band_against_finer -- \
    "$out/converged-$moduli-$pressures.lut" "$out/finer-$moduli-$pressures.lut"
