#!/usr/bin/env bash
# The demo's accuracy over many seeds and moduli: `tactile demo` (the shipped converged
# table for the fit, a fem-core solve at the exact modulus one refinement finer than the
# table as the sample, the whole bench path) at every modulus x seed, 6 kPa below
# 300 kPa and 15 kPa above. Prints one line per run and a summary per modulus and overall:
# median and largest |error|, how often the 95 % interval covers the true modulus, and the
# median half-width of the interval with the share of it that is the converged table's own
# error term (`discretisation_residual_ln`, in % of E2).
#
#   scripts/demo_study.sh OUTDIR            # runs what OUTDIR does not hold yet (50-200 s each)
#   MODULI="20 200" SEEDS="1 2" scripts/demo_study.sh OUTDIR
#   TACTILE=path/to/tactile scripts/demo_study.sh OUTDIR   # default: target/release/tactile
#   TRUTH=converged scripts/demo_study.sh OUTDIR   # the sample at the fit table's own
#                                                  # settings (default: one refinement finer,
#                                                  # `tactile demo --truth finer`)
#
# Each run's JSON report stays in OUTDIR (out-E-SEED.json, its record in rec-E-SEED), so an
# interrupted study carries on where it stopped; the record of a run that failed is moved
# to OUTDIR/failed and the run made again.
set -uo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/demo_study.sh OUTDIR}
tactile=${TACTILE:-target/release/tactile}
moduli=${MODULI:-20 45 90 150 250 400 700 1000}
seeds=${SEEDS:-11 12 13 14}
truth=${TRUTH:-finer}
case "$truth" in
    converged | finer) ;;
    *) echo "demo_study: TRUTH must be converged or finer, got ${truth}" >&2; exit 2 ;;
esac
[ -x "$tactile" ] || { echo "demo_study: $tactile missing (cargo build --release -p tactile)" >&2; exit 1; }
mkdir -p "$out"

for seed in $seeds; do
    for e in $moduli; do
        p=6
        [ "$e" -ge 300 ] && p=15
        f="$out/out-$e-$seed.json"
        [ -s "$f" ] && continue
        # a run that failed or was interrupted left its record: keep it aside, run again
        if [ -e "$out/rec-$e-$seed" ]; then
            mkdir -p "$out/failed"
            mv "$out/rec-$e-$seed" "$out/failed/rec-$e-$seed-$(date +%s)"
        fi
        "$tactile" demo --modulus "$e" --pressure "$p" --seed "$seed" --out "$out/rec-$e-$seed" \
            --truth "$truth" --json >"$f" 2>"$out/err-$e-$seed.txt" || {
            echo "demo_study: E2 $e seed $seed failed: $(tail -n 1 "$out/err-$e-$seed.txt")" >&2
            rm -f "$f"
        }
    done
done

# One line per run: E2 p seed estimate low high error% covered half-width% model-term%
for e in $moduli; do
    for seed in $seeds; do
        f="$out/out-$e-$seed.json"
        [ -s "$f" ] || continue
        p=6
        [ "$e" -ge 300 ] && p=15
        # the converged table's own error term in ln E2 (fit.json; 0 if none was added)
        term=$(sed -n 's/.*"discretisation_residual_ln": *\([-0-9.e]*\).*/\1/p' \
            "$out/rec-$e-$seed/fit.json" 2>/dev/null | head -n 1)
        sed -n 's/^{"modulus_kpa":\([-0-9.e]*\),"ci95_kpa":\[\([-0-9.e]*\),\([-0-9.e]*\)\].*/\1 \2 \3/p' "$f" |
            awk -v e="$e" -v p="$p" -v s="$seed" -v term="$term" '{
                err = 100 * ($1 / e - 1); cov = ($2 <= e && e <= $3) ? "yes" : "no"
                half = 50 * log($3 / $2); t = 100 * (term == "" ? 0 : term)
                printf "%s %s %s %.2f %.2f %.2f %+.2f %s %.2f %.2f\n", e, p, s, $1, $2, $3, err, cov, half, t }'
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
        halfw[e, k] = $9; termw[e, k] = $10
        all++; alle[all] = abs($7); if (abs($7) > allworst) allworst = abs($7); if ($8 == "yes") allcov++
        if (!(e in seen)) { seen[e] = 1; order[++m] = e; pr[e] = $2 }
        runs[e] = runs[e] sprintf(" %+.2f%s", $7, $8 == "yes" ? "" : "*")
    }
    END {
        printf "%-9s %-6s %-7s %-10s %-10s %-9s %-17s %s\n", "E2 kPa", "p kPa", "seeds", "median |e|", "worst |e|", "covered", "half-width/term", "errors (%, * = interval misses)"
        for (i = 1; i <= m; i++) {
            e = order[i]; delete t
            for (k = 1; k <= n[e]; k++) t[k] = errs[e, k]
            med = median(t, n[e]); delete t
            for (k = 1; k <= n[e]; k++) t[k] = halfw[e, k]
            hw = median(t, n[e]); delete t
            for (k = 1; k <= n[e]; k++) t[k] = termw[e, k]
            printf "%-9s %-6s %-7d %-10s %-10s %-9s %-17s%s\n", e, pr[e], n[e], sprintf("%.2f %%", med), sprintf("%.2f %%", worst[e]), cov[e] + 0 "/" n[e], sprintf("%.2f / %.2f %%", hw, median(t, n[e])), runs[e]
        }
        printf "all: %d runs, median |error| %.2f %%, worst %.2f %%, interval covers the truth in %d of %d (%.0f %%)\n", all, median(alle, all), allworst, allcov, all, 100 * allcov / all
    }' "$out/runs.txt"
