#!/usr/bin/env bash
# Friction with a camera scale through hil-sim's truth (docs/diagnosis.md, Method, step 7):
# for each seed, simulated data (`tactile diagnose --simulate friction=MU,radius_scale=S`,
# true E2 170 kPa, 5 replicates at 6 and 15 kPa) diagnosed, one line each: the verdict, the
# final model's effects and modulus, whether the forward search's look-ahead decided it, and
# when the radius and the load disagree the candidates that fitted to both channels would
# explain them (with their fitted parameter, their joint chi^2 and the tube travel's chi^2
# and p-value under them).
#
#   scripts/diagnosis_pair_study.sh [OUT_DIR] [SEED...]     (default target/pair-study, 41..50)
#
# The simulated curves are kept in OUT_DIR and reused (delete it after changing the
# simulator). mu cycles through 0.2, 0.3, 0.4 and the scale through 2 and 3 % with the seed.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/pair-study}
shift || true
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(41 42 43 44 45 46 47 48 49 50)
cargo build -q --release -p tactile
mus=(0.2 0.3 0.4)
scales=(0.02 0.03)
for s in "${seeds[@]}"; do
    mu=${mus[$((s % 3))]}
    scale=${scales[$((s % 2))]}
    case="friction=$mu,radius_scale=$scale"
    dir="$out/$case-$s"
    [ -f "$dir/simulated.csv" ] || target/release/tactile diagnose --simulate "$case" --seed "$s" --out "$dir" --truth-cache "$out/truth" >/dev/null 2>&1
    report=$(target/release/tactile diagnose "$dir/simulated.csv" --reruns 0 --seed "$s" 2>&1)
    verdict=$(echo "$report" | grep -m1 '^verdict:' | sed 's/^verdict: //' || true)
    model=$(echo "$report" | grep -m1 '^  final model:' | sed 's/^  final model: //; s/ ([^()]*)//g' || true)
    e2=$(echo "$report" | grep -m1 'kPa (.*) after, ' | sed 's/^ *E2 = \([0-9.]*\) kPa.*/\1/' || true)
    look=$(echo "$report" | grep -m1 '^  look-ahead:' | sed -E 's/.*: (kept|not kept)( \(.*\))?$/look-ahead \1/' || true)
    both=$(echo "$report" | grep -m1 'explains both within their noise:' | sed 's/.*explains both within their noise: //; s/); /)\n/g' | sed -E 's/^(.*) \(([a-z_]+) = ([-0-9.]+).* joint chi2 ([0-9.]+) on [0-9]+ values, p = [0-9.]+(; tube travel under it: chi2 ([0-9.]+) on [0-9]+ values, p ([=<]) ([0-9.]+))?.*/\1 \3 (chi2 \4; travel chi2 \6 (p \7 \8))/; s/; travel chi2  \(p  \)\)/)/' | paste -sd, - | sed 's/,/, /g' || true)
    echo "$case seed $s: $verdict | ${model:-nothing added} | E2 ${e2:--} kPa (true 170)${look:+ | $look}${both:+ | both channels: $both}"
done
