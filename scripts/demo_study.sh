#!/usr/bin/env bash
# The demo's accuracy over many seeds and moduli: `tactile demo` (production table for the
# fit, a fem-core solve with the converged contact radius at the exact modulus as the
# sample, the whole bench path)
# at every modulus x seed, 6 kPa below 300 kPa and 15 kPa above. Prints one line per run
# and a summary per modulus and overall: median and largest |error|, how often the 95 %
# interval covers the true modulus, and the median error of the production table's own
# estimate before the fit's correction to the converged contact radius.
#
#   scripts/demo_study.sh OUTDIR            # runs what OUTDIR does not hold yet (25-120 s each)
#   MODULI="20 200" SEEDS="1 2" scripts/demo_study.sh OUTDIR
#   TACTILE=path/to/tactile scripts/demo_study.sh OUTDIR   # default: target/release/tactile
#
# Each run's JSON report stays in OUTDIR (out-E-SEED.json, its record in rec-E-SEED), so an
# interrupted study carries on where it stopped.
set -uo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/demo_study.sh OUTDIR}
tactile=${TACTILE:-target/release/tactile}
moduli=${MODULI:-20 45 90 150 250 400 700 1000}
seeds=${SEEDS:-11 12 13 14}
[ -x "$tactile" ] || { echo "demo_study: $tactile missing (cargo build --release -p tactile)" >&2; exit 1; }
mkdir -p "$out"

for seed in $seeds; do
    for e in $moduli; do
        p=6
        [ "$e" -ge 300 ] && p=15
        f="$out/out-$e-$seed.json"
        [ -s "$f" ] && continue
        "$tactile" demo --modulus "$e" --pressure "$p" --seed "$seed" --out "$out/rec-$e-$seed" \
            --json >"$f" 2>"$out/err-$e-$seed.txt" || {
            echo "demo_study: E2 $e seed $seed failed: $(tail -n 1 "$out/err-$e-$seed.txt")" >&2
            rm -f "$f"
        }
    done
done

# One line per run: E2 p seed estimate low high error% covered uncorrected-error%
for e in $moduli; do
    for seed in $seeds; do
        f="$out/out-$e-$seed.json"
        [ -s "$f" ] || continue
        p=6
        [ "$e" -ge 300 ] && p=15
        # the estimate before the correction (fit.json; the estimate itself if none was made)
        production=$(sed -n 's/.*"modulus_production_kpa": *\([-0-9.e]*\).*/\1/p' \
            "$out/rec-$e-$seed/fit.json" 2>/dev/null | head -n 1)
        sed -n 's/^{"modulus_kpa":\([-0-9.e]*\),"ci95_kpa":\[\([-0-9.e]*\),\([-0-9.e]*\)\].*/\1 \2 \3/p' "$f" |
            awk -v e="$e" -v p="$p" -v s="$seed" -v prod="$production" '{
                err = 100 * ($1 / e - 1); cov = ($2 <= e && e <= $3) ? "yes" : "no"
                uerr = 100 * ((prod == "" ? $1 : prod) / e - 1)
                printf "%s %s %s %.2f %.2f %.2f %+.2f %s %+.2f\n", e, p, s, $1, $2, $3, err, cov, uerr }'
    done
done >"$out/runs.txt"

awk '
    function abs(x) { return x < 0 ? -x : x }
    function median(a, n,    i, j, t) {
        for (i = 2; i <= n; i++) { t = a[i]; for (j = i - 1; j >= 1 && a[j] > t; j--) a[j + 1] = a[j]; a[j + 1] = t }
        return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
    }
    {
        e = $1; n[e]++; k = n[e]; errs[e, k] = abs($7); if (abs($7) > worst[e]) worst[e] = abs($7)
        if ($8 == "yes") cov[e]++
        uncorr[e, k] = $9
        all++; alle[all] = abs($7); if (abs($7) > allworst) allworst = abs($7); if ($8 == "yes") allcov++
        if (!(e in seen)) { seen[e] = 1; order[++m] = e; pr[e] = $2 }
        runs[e] = runs[e] sprintf(" %+.2f%s", $7, $8 == "yes" ? "" : "*")
    }
    END {
        printf "%-9s %-6s %-7s %-10s %-10s %-9s %-12s %s\n", "E2 kPa", "p kPa", "seeds", "median |e|", "worst |e|", "covered", "uncorrected", "errors (%, * = interval misses)"
        for (i = 1; i <= m; i++) {
            e = order[i]; delete t
            for (k = 1; k <= n[e]; k++) t[k] = errs[e, k]
            med = median(t, n[e]); delete t
            for (k = 1; k <= n[e]; k++) t[k] = uncorr[e, k]
            printf "%-9s %-6s %-7d %-10s %-10s %-9s %-12s%s\n", e, pr[e], n[e], sprintf("%.2f %%", med), sprintf("%.2f %%", worst[e]), cov[e] + 0 "/" n[e], sprintf("%+.2f %%", median(t, n[e])), runs[e]
        }
        printf "all: %d runs, median |error| %.2f %%, worst %.2f %%, interval covers the truth in %d of %d (%.0f %%)\n", all, median(alle, all), allworst, allcov, all, 100 * allcov / all
    }' "$out/runs.txt"
