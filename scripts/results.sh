#!/usr/bin/env bash
# Regenerates the measured blocks of docs/results.md: every section of that page has a
# block between `<!-- results: NAME -->` and `<!-- /results -->` that holds what its
# commands print (their own summary lines, without cargo's and libtest's bookkeeping). The
# prose around the blocks says what is measured and how to read it; the numbers are in the
# blocks only, so rerunning this script brings the whole page up to date.
#
#   scripts/results.sh --list          # the sections and their commands
#   scripts/results.sh                 # every section (release builds; about an hour on 2 cores)
#   scripts/results.sh NAME...         # only these sections
#
# A section whose command fails keeps its previous block and is reported; the script then
# exits non-zero. Timings in the blocks depend on the machine and its load: compare ratios.
set -uo pipefail
cd "$(dirname "$0")/.."
# A `should_panic` test prints the panic it expects: without a backtrace that is its
# "thread ... panicked at" line and the message after it, both dropped below.
export RUST_BACKTRACE=0

page=docs/results.md

# name@@lines kept (an extended regular expression; empty: every line)@@command (run by
# bash from the repository root). Order = order of the page.
sections=(
    "demo@@@@for ep in 25:6 60:6 120:6 200:6 350:15 600:15 1000:15; do echo \"true E2 \${ep%:*} kPa at \${ep#*:} kPa:\"; cargo run -q --release -p tactile -- demo --modulus \${ep%:*} --pressure \${ep#*:} --seed 3 2>&1 | grep -E '^(E2 =|simulated sample|error)' | sed 's/^/    /'; done"
    "demo-seeds@@^(E2 kPa|[0-9]|all:)@@cargo build -q --release -p tactile && TRUTH=converged scripts/demo_study.sh target/demo-study"
    "demo-midpoints@@^(E2 kPa|[0-9]|all:)@@cargo build -q --release -p tactile && TRUTH=converged MODULI=\"26 56 121 178 261 383 562 825\" SEEDS=\"21 22 23 24\" scripts/demo_study.sh target/demo-midpoints"
    "demo-finer-truth@@^(E2 kPa|[0-9]|all:)@@cargo build -q --release -p tactile && TRUTH=finer MODULI=\"20 26 45 56 90 121 150 178 250 261 383 400 562 700 825 1000\" SEEDS=\"21 22\" scripts/demo_study.sh target/demo-finer-truth"
    "bench-measure@@@@cargo test -q -p tactile --release --test cli_calibrate -- --nocapture && cargo test -q --release -p system-tests --test measure_sim_bench -- --ignored --nocapture"
    "fit@@@@cargo test -q -p fit --release --test fit_lut -- --nocapture"
    "vision@@@@cargo run -q --release -p tactile --example vision_timing && cargo test -q --release -p vision --test unseen_frames -- --ignored --nocapture && cargo test -q --release -p system-tests --test vision_near_mirror -- --ignored --nocapture"
    "pressure@@@@cargo test -q -p controller --release --test pressure_regulation -- --nocapture --test-threads=1 && cargo run -q --release -p hil-sim --example pressure_steps"
    "emulated-bench@@@@cargo test -q -p hil-sim --release --test device_behaviour -- --nocapture --test-threads=1 && cargo test -q -p hil-sim --release --test clock_alignment -- --nocapture"
    "daemon@@@@cargo test -q --release -p system-tests --test daemon_experiments -- --nocapture --test-threads=1"
    "fem-verification@@@@cargo test -q -p fem-core --release -- --include-ignored --nocapture --test-threads=1"
    "convergence@@@@RAYON_NUM_THREADS=1 cargo run -q --release -p fem-core --example convergence_study -- 1e7 6 1,2,4,8 0"
    "fem-error-by-level@@@@RAYON_NUM_THREADS=1 cargo run -q --release -p fem-core --example discretisation_error"
    "edge-band@@^(E2|edge band|production - band)@@for c in '1e7 6' '200 6' '37 6' '1000 15'; do RAYON_NUM_THREADS=1 cargo run -q --release -p fem-core --example edge_band_curve -- \$c 1.7 34; done"
    "converged-truth@@@@scripts/converged_truth_fit.sh"
    "interpolation@@^(fem-core|p_air)@@for t in default-production-mesh default; do cargo run -q --release -p fem-core --example interpolation_error -- fem-core/data/\$t.lut 6,15; done"
    "interpolation-all-pressures@@@@cargo run -q --release -p fem-core --example interpolation_against_table -- fem-core/data/default.lut fem-core/data/sim-samples-converged.lut && cargo run -q --release -p fem-core --example interpolation_against_table -- fem-core/data/default.lut fem-core/data/sim-samples.lut"
    "band-against-finer@@@@scripts/band_against_finer.sh"
    "pressure-interpolation@@^(fem-core|p_air)@@cargo run -q --release -p fem-core --example interpolation_error -- fem-core/data/default-production-mesh.lut 3,8,12.5,17.5,25 nodes"
    "pressure-interpolation-converged@@^(fem-core|p_air|  load)@@mkdir -p target/pressure-truth; for s in mid:8,12.5,17.5,25 quarter:7,9,11.25,13.75,16.25,18.75,22.5,27.5; do t=target/pressure-truth/\${s%%:*}.lut; [ -f \$t ] || cargo run -q --release -p tactile -- lut build --grid default --edge-band --pressure \${s#*:} --out \$t 2>/dev/null; cargo run -q --release -p fem-core --example interpolation_error -- fem-core/data/default.lut --truth \$t; done"
    "pressure-term@@^(the shipped|p_air|summary)@@cargo run -q --release -p fit --example pressure_interpolation_term"
    "snap-through@@^(E2|snap|solve time)@@for e in 681.3 1000; do echo \"E2 = \$e kPa, p_air = 0:\"; RAYON_NUM_THREADS=1 cargo run -q --release -p fem-core --example curve -- \$e 0 0 40 2; done"
    "fem-speed@@^(stage|curve solve)@@RAYON_NUM_THREADS=1 cargo run -q --release -p fem-core --example solver_trace -- 200 6 0"
    "fem-band-work@@^instructions@@cargo build -q --release -p fem-core --example solver_trace && FEM_EDGE_BAND=1 FEM_TRACE_QUIET=1 valgrind --tool=callgrind --callgrind-out-file=/dev/null target/release/examples/solver_trace 200 6 0 0 8 0.4 2>&1 | sed -n 's/^==[0-9]*== Collected : \\([0-9]*\\)/instructions (callgrind) of the band curve at 200 kPa \\/ 6 kPa, 8 steps to 0.4 mm: \\1/p'"
    "fem-kernels@@(ns/iter|equations)@@cargo bench -q -p fem-core --bench solver -- --output-format bencher 2>&1 | sed -E 's/^test ([^ ]+) +[.]{3} bench: +/\\1: /'"
    "fem-anderson@@^(E2|rigid|[0-9]|factorisations)@@cargo build -q --release -p fem-core --example anderson_band && RAYON_NUM_THREADS=1 target/release/examples/anderson_band && RAYON_NUM_THREADS=1 target/release/examples/anderson_band 200:6 0.25"
    "fem-contact@@^(setting|stage 2|contact set|curve solve)@@cargo build -q --release -p fem-core --example solver_trace && for s in \"as set:\" \"FEM_PENETRATION_SCALE=10\" \"FEM_PENETRATION_SCALE=100\" \"FEM_AUGMENTATIONS=0\" \"FEM_PENALTY=60\" \"FEM_PENALTY=200\" \"FEM_CHORD=0\" \"FEM_CONTACT_CURVATURE=1\" \"FEM_FINER_BAND=1\" \"FEM_FINER_BAND=1 FEM_ANDERSON=5\"; do echo \"setting: \$s\"; env \$(echo \"\$s\" | grep -o \"FEM_[A-Z_]*=[0-9]*\") FEM_EDGE_BAND=1 FEM_TRACE_QUIET=1 RAYON_NUM_THREADS=1 target/release/examples/solver_trace 200 6 0 0 40 2 | sed -E \"s/, assembly [0-9.]+ s, linear [0-9.]+ s//\"; done"
    "friction-band@@^(band|level|friction) @@cargo run -q --release -p fem-core --example friction_band -- 190 6 0.25"
    "fem-felupe@@^(p_air|  )@@scripts/fem_crosscheck_felupe.sh --pressures 0,6,15 --levels 40,80,160,320 && scripts/fem_crosscheck_felupe.sh --pressures 6 --levels 640"
    "diagnosis@@^(false positives|travel check|channel|E2|overall|correlation)@@cargo test -q --release -p system-tests --test diagnose_null -- --ignored --nocapture --test-threads=1 && NULL_MODULUS_KPA=25 cargo test -q --release -p system-tests --test diagnose_null -- --ignored --nocapture --test-threads=1; DIAG_CONVERGED=1 cargo test -q --release -p system-tests --test diagnose_table_error -- --ignored --nocapture --test-threads=1 loo_calibration pressure_continuation_error && DIAG_CONVERGED=1 LOO_CHANNEL=travel cargo test -q --release -p system-tests --test diagnose_table_error -- --ignored --nocapture --test-threads=1 loo_calibration"
    "diagnosis-finer-truth@@@@TRUTH=finer MODULI=\"20 25 60 100 170 400 1000\" scripts/diagnose_null_study.sh target/null-finer-truth"
    "effect-tables@@^(Thickness|Friction|Stiffening)@@cargo test -q --release -p system-tests --test diagnose_effect_deltas -- --ignored --nocapture --test-threads=1"
    "diagnosis-bench-path@@@@cargo run -q --release -p system-tests --example bench_path_diagnosis -- target/bench-path-study --seeds 2 --null-seeds 6 --jobs 3"
    "diagnosis-bench-rates@@^(summary|rates|  )@@cargo run -q --release -p system-tests --example bench_path_diagnosis -- target/bench-path-study --seeds 9 --null-seeds 60 --clear-only --jobs 3"
    "diagnosis-outside@@@@cargo build -q --release -p tactile && for c in lens_distortion=0.001 lens_distortion=0.002 lens_distortion=0.004 pressure_leak=0.3 pressure_leak=0.6 radius_scale=0.03 finite_thickness=1.5; do for s in 1 2 3; do d=target/outside-study/\$c-\$s; [ -f \$d/simulated.csv ] || target/release/tactile diagnose --simulate \$c --seed \$s --out \$d 2>/dev/null; r=\$(target/release/tactile diagnose \$d/simulated.csv --reruns 0 2>&1); echo \"\$c seed \$s: \$(echo \"\$r\" | grep -m1 '^verdict:' | sed 's/^verdict: //') | \$(echo \"\$r\" | grep -m1 'radius and load under' | sed 's/^ *radius and load under //; s/ kPa from the radius (+-[0-9.]* %), / from the radius, /; s/ from the load given the radius (+-[0-9.]* %)\\(, the .* own +-[0-9.]* %\\)\\{0,1\\}: / from the load given the radius: /; s/; (the load alone.*every parameter shared: PG = \\([0-9.]*\\), 99 % of [0-9]* draws under the model below \\([0-9.]*\\), p \\([^;]*\\); with the tables. errors allowed: PG_t = \\([0-9.]*\\), 99 % below \\([0-9.]*\\), p \\(.*\\))\$/; PG \\1 (99 % of the draws below \\2), p \\3; allowing table errors PG_t \\4 (below \\5), p \\6/')\$(echo \"\$r\" | sed -n 's/.*baseline fits the radius but not the load (load chi2\/value \\([0-9.]*\\).*/the baseline fits the radius, not the load: chi2\/value \\1/p' | head -n 1)\$(echo \"\$r\" | sed -n 's/^ *pressure offset over the travel: \\([0-9.-]*\\) +- [0-9.]* kPa above u_s .* kPa, \\([0-9.-]*\\) +- [0-9.]* kPa below (both channels; allowance [0-9.]*): z = \\([^,]*\\), p \\(.*\\)\$/; manometer offset from the deep half \\1 kPa, the shallow \\2: z \\3, p \\4/p')\"; done; done"
    "diagnosis-pairs@@@@scripts/diagnosis_pair_study.sh"
    "model-file@@^(plain fit|true )@@cargo test -q --release -p tactile --test diagnose_cli an_applied_diagnosis -- --nocapture && cargo test -q --release -p system-tests --test daemon_model -- --nocapture"
    "firmware-size@@@@(cd firmware/rp2040 && cargo build -q --release) && scripts/check-firmware-size.sh"
)

name_of() { printf '%s' "${1%%@@*}"; }
keep_of() { local rest="${1#*@@}"; printf '%s' "${rest%%@@*}"; }
command_of() { local rest="${1#*@@}"; printf '%s' "${rest#*@@}"; }

if [ "${1:-}" = "--list" ]; then
    for s in "${sections[@]}"; do
        printf '%-18s %s\n' "$(name_of "$s")" "$(command_of "$s")"
    done
    exit 0
fi

wanted=("$@")
for w in "${wanted[@]}"; do
    found=0
    for s in "${sections[@]}"; do [ "$(name_of "$s")" = "$w" ] && found=1; done
    if [ "$found" -eq 0 ]; then
        echo "unknown section '$w' (scripts/results.sh --list shows them)" >&2
        exit 2
    fi
done

# Lines that are cargo's or the test harness's, not a measurement.
noise='^(running [0-9]+ tests?|test result:|test [^ ]+ \.\.\. |[.]+$|[.]*(ok|ignored)$|successes:|failures:|---- |$|[[:space:]]+(Compiling|Finished|Running|Doc-tests|Blocking|Downloaded|Updating)|warning:|note: |test .* has been running for over|all doctests ran in )'

failed=()
for s in "${sections[@]}"; do
    name=$(name_of "$s")
    if [ "${#wanted[@]}" -gt 0 ] && ! printf '%s\n' "${wanted[@]}" | grep -qx "$name"; then
        continue
    fi
    if ! grep -q "^<!-- results: $name -->$" "$page"; then
        echo "$page has no block for '$name'" >&2
        failed+=("$name")
        continue
    fi
    cmd=$(command_of "$s")
    printf '==> %s: %s\n' "$name" "$cmd" >&2
    out=$(mktemp)
    start=$(date +%s)
    if bash -c "$cmd" >"$out" 2>&1; then
        secs=$(( $(date +%s) - start ))
        body=$(mktemp)
        {
            echo '```text'
            # -q prints a dot per passed test, glued to the next printed line.
            keep=$(keep_of "$s")
            sed -E 's/^\.+//' "$out" |
                awk 'expected { expected = 0; next } /^thread .* panicked at / { expected = 1; next } { print }' |
                grep -Ev "$noise" | grep -E "${keep:-.}" |
                sed -E 's/[[:space:]]+$//'
            echo '```'
        } >"$body"
        # Replace the block's content, keep everything else of the page.
        awk -v name="$name" -v body="$body" '
            $0 == "<!-- results: " name " -->" { print; while ((getline line < body) > 0) print line; skip = 1; next }
            skip && $0 == "<!-- /results -->" { skip = 0 }
            !skip { print }
        ' "$page" >"$page.new" && mv "$page.new" "$page"
        rm -f "$body"
        printf '    %s: %d s\n' "$name" "$secs" >&2
    else
        echo "    $name FAILED (block kept); its output:" >&2
        tail -n 30 "$out" >&2
        failed+=("$name")
    fi
    rm -f "$out"
done

if [ "${#failed[@]}" -gt 0 ]; then
    echo "failed: ${failed[*]}" >&2
    exit 1
fi
echo "docs/results.md regenerated" >&2
