#!/usr/bin/env bash
# Fits curves solved with the converged contact radius (tactile fem curve --edge-band) with
# the shipped production-mesh table (default-production-mesh.lut: the default grid without
# the edge band), next to curves solved on the production mesh itself: the modulus error
# the production mesh's discretisation makes on a sample that has no mesh,
# with the fit's correction to the converged contact radius and without it (the table's
# own estimate), and each converged curve fitted directly with the shipped converged table
# (default.lut, the table the host fits with). A production-mesh curve is over-corrected by
# design: the correction assumes a sample without a mesh. A curve solved one refinement finer
# than the converged table (--edge-band --finer: 12.5 um band elements, sixteen through the
# wall) is fitted with default.lut: what the table's own discretisation does to a modulus.
#
#   scripts/converged_truth_fit.sh [OUT_DIR]      # default target/converged-truth
#
# Each converged curve takes 6-20 s on one core, a finer one about four times that (release build).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/converged-truth}
mkdir -p "$out"
cargo build -q --release -p tactile
tactile=target/release/tactile
lut=fem-core/data/default-production-mesh.lut
converged_lut=fem-core/data/default.lut
for case in 37:6 153:6 412:15 600:15; do
    e=${case%:*}
    p=${case#*:}
    printf 'true E2 %s kPa at %s kPa:\n' "$e" "$p"
    for mesh in converged finer production; do
        csv="$out/${mesh}_${e}_${p}.csv"
        flag=()
        [ "$mesh" = converged ] && flag=(--edge-band)
        [ "$mesh" = finer ] && flag=(--edge-band --finer)
        "$tactile" fem curve --modulus "$e" --pressure "$p" "${flag[@]}" --out "$csv" 2>/dev/null
        tables=("$lut")
        [ "$mesh" = converged ] && tables+=("$converged_lut")
        [ "$mesh" = finer ] && tables=("$converged_lut")
        for table in "${tables[@]}"; do
            fitted=$("$tactile" fit "$csv" --lut "$table" --json)
            label="$mesh curve"
            [ "$table" = "$converged_lut" ] && label="$mesh curve, shipped default.lut"
            python3 - "$label" "$e" "$fitted" <<'PY'
import json, sys
label, truth, fit = sys.argv[1], float(sys.argv[2]), json.loads(sys.argv[3])
e = fit["modulus_kpa"]
lo, hi = fit["ci95_kpa"]
covered = "covers" if lo <= truth <= hi else "misses"
own = fit["fit"].get("modulus_production_kpa") or e
print(f"    {label}: E2 = {e:7.1f} kPa ({100 * (e / truth - 1):+.2f} %), "
      f"95 % interval {lo:.1f} .. {hi:.1f} kPa ({covered} the truth); "
      f"table's own {own:.1f} kPa ({100 * (own / truth - 1):+.2f} %)")
PY
        done
    done
done
