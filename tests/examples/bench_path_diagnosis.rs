//! Hidden effects through the whole bench path, diagnosed from the records.
//!
//! For every effect of the diagnosis's library at its two test sizes
//! (`diagnosis::simulate::sizes`) and for no effect, over several seeds: the hidden-effect
//! truth of the diagnosis's studies (`diagnosis::simulate::truth_scenario`: the sample's
//! mechanics solved by fem-core at its true parameters, hil-sim's effect code) runs as a
//! hil-sim bench — the controller logic, the serial link, rendered camera frames, the
//! calibrations, the vision and the pairing of `tactile demo` — at 6 and 15 kPa with 5
//! indentations each; the two record folders are read as `tactile diagnose` reads them
//! (`experiment::record_meta::record_curve_at_set_pressure`) and diagnosed with the shipped
//! tables. Prints one line per case and a summary: how often each effect is named (first, or
//! later in the forward selection) and how often clean data names something, then the
//! rates over all effects with one-sided 95 % exact binomial bounds. A proximity
//! offset and a manometer offset present from the start are removed by the bench's own
//! calibrations (the rigid sweep, the vent-open zero), so for them `none` is the expected
//! verdict; they run a second time with a stale calibration (`+stale`: the offsets appeared
//! after the bench was calibrated), where the manometer's offset reaches the measurement
//! and should be named; a constant proximity offset is still removed, by each
//! indentation's own zero of u_s before contact. A case whose truth cannot be solved is
//! listed as not run.
//!
//!     cargo run --release -p system-tests --example bench_path_diagnosis -- OUTDIR \
//!         [--seeds N] [--null-seeds N] [--effects NAME,...] [--clear-only] [--jobs N]
//!
//! Each case's two records are kept in OUTDIR (`case-EFFECT-SIZE-SEED/record-P`) and reused
//! by later runs, so an interrupted study carries on where it stopped; the diagnosis is
//! always recomputed from them (so a change of the diagnosis is measured on the same bench
//! data in ~15 s per case). The truths are solved first, one at a time, and kept in
//! `OUTDIR/truth-cache`, keyed by their parameters and solver settings, so the seeds of one
//! effect and size solve their sample once. Delete OUTDIR after changing the bench path
//! (hil-sim, the calibrations, vision, pairing). A bench run is paced by its emulated link
//! in real time (about 35 s for a case's two records, a fifth of a core), so `--jobs N` runs
//! N cases at once (their diagnoses one at a time); the records of one seed differ from run
//! to run by the sample timing, as a real bench's do. Too many jobs starve the hosts: a
//! host that sends nothing for 1 s faults its controller, and the case is listed as not
//! run (a later run retries it).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, mpsc};
use std::time::Instant;

use diagnosis::candidates::EffectKind;
use diagnosis::simulate::{Hidden, SimSpec, sizes, truth_modulus_kpa, truth_scenario};
use diagnosis::stats::binomial_bounds;
use diagnosis::{DiagnoseOptions, diagnose};
use experiment::record_meta::record_curve_at_set_pressure;
use experiment::simulated::{DemoOptions, run_demo_with};
use hil_sim::scenario::{MechanicsSource, Scenario};

const PRESSURES_KPA: [f64; 2] = [6.0, 15.0];
const REPEATS: u32 = 5;

/// One case's outcome.
#[derive(Debug, Clone)]
struct CaseResult {
    effect: String,
    size: f64,
    seed: u64,
    true_modulus_kpa: f64,
    verdict: String,
    /// Effects of the forward selection's final model, in order.
    named: Vec<String>,
    /// The first named effect's parameter (radius fit) and its joint fit, when named.
    parameter: Option<f64>,
    joint_parameter: Option<f64>,
    /// The host's fit of both records together (the diagnosis's baseline) and the forward
    /// selection's final model.
    modulus_baseline_kpa: f64,
    modulus_after_kpa: Option<f64>,
    seconds: f64,
    /// Whether the hidden effect is at its clear (larger) test size.
    clear: bool,
}

struct Args {
    out: PathBuf,
    seeds: u64,
    null_seeds: u64,
    effects: Vec<EffectKind>,
    clear_only: bool,
    /// Cases run at once (the bench is paced by its emulated link, not by the CPU).
    jobs: usize,
}

fn parse_args() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let mut args = Args {
        out: PathBuf::new(),
        seeds: 2,
        null_seeds: 4,
        effects: EffectKind::ALL.to_vec(),
        clear_only: false,
        jobs: 1,
    };
    let number = |flag: &str, v: Option<String>| -> Result<u64, String> {
        v.ok_or_else(|| format!("{flag} needs a number"))?
            .parse()
            .map_err(|e| format!("{flag}: {e}"))
    };
    let mut out = None;
    while let Some(a) = it.next() {
        match a.as_str() {
            "--seeds" => args.seeds = number("--seeds", it.next())?,
            "--null-seeds" => args.null_seeds = number("--null-seeds", it.next())?,
            "--clear-only" => args.clear_only = true,
            "--jobs" => {
                args.jobs = usize::try_from(number("--jobs", it.next())?)
                    .map_err(|e| format!("--jobs: {e}"))?
                    .max(1)
            }
            "--effects" => {
                let list = it.next().ok_or("--effects needs a list of names")?;
                args.effects = list
                    .split(',')
                    .map(|n| {
                        EffectKind::ALL
                            .into_iter()
                            .find(|k| k.name() == n.trim())
                            .ok_or_else(|| {
                                format!(
                                    "--effects: unknown effect {n:?} (known: {})",
                                    EffectKind::ALL.map(EffectKind::name).join(", ")
                                )
                            })
                    })
                    .collect::<Result<_, _>>()?;
            }
            _ if a.starts_with('-') => return Err(format!("unknown option {a}")),
            _ => out = Some(PathBuf::from(a)),
        }
    }
    args.out = out.ok_or("usage: bench_path_diagnosis OUTDIR [--seeds N] [--null-seeds N] [--effects NAME,...] [--clear-only] [--jobs N]")?;
    Ok(args)
}

/// The true modulus and the hil-sim scenario of a case (its truth solved by fem-core).
fn case_scenario(hidden: Option<Hidden>, stale: bool, seed: u64) -> (f64, Scenario) {
    let modulus = truth_modulus_kpa(hidden.map(|h| h.kind));
    let spec = SimSpec {
        modulus_kpa: modulus,
        hidden,
        seed,
        ..SimSpec::default()
    };
    let mut scenario = truth_scenario(&spec);
    scenario.effects.offsets_after_calibration = stale;
    // The truth of a manometer offset assumes the controller regulates the offset reading
    // (the sample then sits at p - p0, as with a stale calibration); the bench's vent-open
    // zero removes the offset first, so the sample sits at the set point: solve there too.
    if let (Some(h), MechanicsSource::Solve { pressures_kpa, .. }) =
        (hidden, &mut scenario.mechanics)
        && h.kind == EffectKind::PressureOffset
        && !stale
    {
        pressures_kpa.extend(PRESSURES_KPA);
        pressures_kpa.sort_by(f64::total_cmp);
    }
    (modulus, scenario)
}

/// Runs one case: two bench runs, their records diagnosed.
fn run_case(
    hidden: Option<Hidden>,
    stale: bool,
    seed: u64,
    dir: &Path,
    truth_cache: &Path,
) -> Result<CaseResult, String> {
    let started = Instant::now();
    let (modulus, mut scenario) = case_scenario(hidden, stale, seed);
    let mut curves = Vec::new();
    let mut truth_written = false;
    for p in PRESSURES_KPA {
        let record = dir.join(format!("record-{p}"));
        // a complete record of an earlier run is reused
        if let Ok(curve) = record_curve_at_set_pressure(&record) {
            curves.push((record.display().to_string(), curve));
            continue;
        }
        let _ = std::fs::remove_dir_all(&record);
        if !truth_written {
            // the truth's curves (the converged sample as it is, its friction included:
            // `truth_curves`) run as a `curves` mechanics source
            scenario.mechanics = write_truth_curves(&scenario, &dir.join("truth"), truth_cache)?;
            truth_written = true;
        }
        let options = DemoOptions {
            modulus_kpa: modulus,
            pressure_kpa: p,
            seed,
            scenario: None,
            out: Some(record.clone()),
            lut: None,
            repeats: REPEATS,
            progress: false,
            u_s_equals_h: false,
            firmware: None,
            finer_truth: false,
        };
        run_demo_with(scenario.clone(), &options)
            .map_err(|e| format!("bench run at {p} kPa: {e}"))?;
        let curve = record_curve_at_set_pressure(&record).map_err(|e| e.to_string())?;
        curves.push((record.display().to_string(), curve));
    }
    let points = diagnosis::data::points_from_curves(&curves).map_err(|e| e.to_string())?;
    let (base, effects) = diagnosis::tables::shipped_tables().map_err(|e| e.to_string())?;
    let options = DiagnoseOptions {
        confidence_reruns: 0,
        seed,
        ..DiagnoseOptions::default()
    };
    // one diagnosis at a time (each uses every core), beside the other cases' benches
    static DIAGNOSING: Mutex<()> = Mutex::new(());
    let d = {
        let _one = DIAGNOSING.lock().unwrap_or_else(|e| e.into_inner());
        diagnose(&base, &effects, points, &options).map_err(|e| e.to_string())?
    };
    // the effect's own parameter (the map also holds derived values such as the thickness)
    let first_value = |v: &serde_json::Value| {
        v.as_object()?
            .values()
            .find_map(|p| p.get("value").and_then(serde_json::Value::as_f64))
    };
    Ok(CaseResult {
        effect: hidden.map_or("none".into(), |h| label(h.kind, stale)),
        size: hidden.map_or(0.0, |h| h.size),
        seed,
        true_modulus_kpa: modulus,
        verdict: d.verdict.as_str().to_string(),
        named: d.effects.iter().map(|e| e.effect.clone()).collect(),
        parameter: first_value(&d.parameters),
        joint_parameter: d.joint_fit.as_ref().map(|j| j.value),
        modulus_baseline_kpa: d.baseline.modulus_kpa,
        modulus_after_kpa: (!d.effects.is_empty()).then_some(d.forward.modulus_after_kpa),
        seconds: started.elapsed().as_secs_f64(),
        clear: hidden.is_some_and(|h| h.size == sizes(h.kind)[1]),
    })
}

/// The instrument offsets the bench's own calibrations remove when present from the start;
/// they also run with a stale calibration (`EffectsConfig::offsets_after_calibration`).
fn removed_by_calibration(kind: EffectKind) -> bool {
    matches!(
        kind,
        EffectKind::DisplacementOffset | EffectKind::PressureOffset
    )
}

/// A case's effect column: the effect's name, `+stale` with a stale calibration.
fn label(kind: EffectKind, stale: bool) -> String {
    if stale {
        format!("{}+stale", kind.name())
    } else {
        kind.name().to_string()
    }
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let mut cases: Vec<(Option<Hidden>, bool, u64)> =
        (1..=args.null_seeds).map(|s| (None, false, s)).collect();
    for &kind in &args.effects {
        let [small, clear] = sizes(kind);
        let wanted = if args.clear_only {
            vec![clear]
        } else {
            vec![clear, small]
        };
        let stale: &[bool] = if removed_by_calibration(kind) {
            &[false, true]
        } else {
            &[false]
        };
        for &stale in stale {
            for &size in &wanted {
                for seed in 1..=args.seeds {
                    cases.push((Some(Hidden { kind, size }), stale, 100 + seed));
                }
            }
        }
    }
    println!(
        "effect               size     seed  verdict       named (forward)                          parameter (joint)      E2 before -> after [true]   s"
    );
    let truth_cache = args.out.join("truth-cache");
    let case_dir = |&(hidden, stale, seed): &(Option<Hidden>, bool, u64)| {
        let name = hidden.map_or("none".to_string(), |h| {
            format!("{}-{}", label(h.kind, stale), h.size)
        });
        (args.out.join(format!("case-{name}-{seed}")), name)
    };
    // The truths first, one at a time with every core (into the cache): a solve running
    // beside the benches would starve their hosts, whose link to the emulated controller
    // keeps real time (a host that sends nothing for 1 s faults the controller).
    let truth_errors: Vec<Option<String>> = cases
        .iter()
        .map(|case| {
            let (dir, _) = case_dir(case);
            let recorded = PRESSURES_KPA
                .iter()
                .all(|p| record_curve_at_set_pressure(&dir.join(format!("record-{p}"))).is_ok());
            if recorded {
                return None;
            }
            let (_, scenario) = case_scenario(case.0, case.1, case.2);
            diagnosis::simulate::truth_curves_cached(&scenario, &truth_cache)
                .err()
                .map(|e| e.to_string())
        })
        .collect();
    let next = AtomicUsize::new(0);
    let (sender, finished) = mpsc::channel();
    let mut results = Vec::new();
    let mut failed = 0;
    std::thread::scope(|scope| {
        for _ in 0..args.jobs {
            let sender = sender.clone();
            let (cases, next, truth_cache) = (&cases, &next, &truth_cache);
            let (truth_errors, case_dir) = (&truth_errors, &case_dir);
            scope.spawn(move || {
                loop {
                    let k = next.fetch_add(1, Ordering::SeqCst);
                    let Some(&(hidden, stale, seed)) = cases.get(k) else {
                        break;
                    };
                    let (dir, name) = case_dir(&cases[k]);
                    let _ = std::fs::create_dir_all(&dir);
                    let result = match &truth_errors[k] {
                        Some(e) => Err(format!("truth: {e}")),
                        None => run_case(hidden, stale, seed, &dir, truth_cache),
                    };
                    if sender.send((k, name, seed, result)).is_err() {
                        break;
                    }
                }
            });
        }
        drop(sender);
        // lines in the order of the cases, whichever worker finishes first
        let mut pending = std::collections::BTreeMap::new();
        let mut printed = 0;
        for (k, name, seed, result) in finished {
            pending.insert(k, (name, seed, result));
            while let Some((name, seed, result)) = pending.remove(&printed) {
                printed += 1;
                match result {
                    Ok(r) => {
                        print_case(&r);
                        results.push(r);
                    }
                    Err(e) => {
                        failed += 1;
                        println!("{name} seed {seed}: not run: {e}");
                    }
                }
            }
        }
    });
    summary(&results);
    if failed > 0 {
        println!("  {failed} case(s) not run (above)");
    }
    ExitCode::SUCCESS
}

fn print_case(r: &CaseResult) {
    println!(
        "{:<20} {:<8} {:<5} {:<13} {:<40} {:<22} {:>6.1} -> {:>6} [{:.0}] {:>5.0}",
        r.effect,
        r.size,
        r.seed,
        r.verdict,
        if r.named.is_empty() {
            "-".to_string()
        } else {
            r.named.join(", ")
        },
        match (r.parameter, r.joint_parameter) {
            (Some(p), Some(j)) => format!("{p:.4} ({j:.4})"),
            (Some(p), None) => format!("{p:.4}"),
            _ => "-".into(),
        },
        r.modulus_baseline_kpa,
        r.modulus_after_kpa
            .map_or("-".to_string(), |m| format!("{m:.1}")),
        r.true_modulus_kpa,
        r.seconds
    );
}

/// Per effect and size: named first / named at all; clean data: anything named.
fn summary(results: &[CaseResult]) {
    println!("summary:");
    let nulls: Vec<&CaseResult> = results.iter().filter(|r| r.effect == "none").collect();
    if !nulls.is_empty() {
        let fp: Vec<String> = nulls
            .iter()
            .filter(|r| !r.named.is_empty())
            .map(|r| format!("{} (seed {})", r.named.join("+"), r.seed))
            .collect();
        println!(
            "  none: something named in {} of {} (target <= 5 %){}",
            fp.len(),
            nulls.len(),
            if fp.is_empty() {
                String::new()
            } else {
                format!(": {}", fp.join(", "))
            }
        );
    }
    let mut keys: Vec<(String, f64)> = results
        .iter()
        .filter(|r| r.effect != "none")
        .map(|r| (r.effect.clone(), r.size))
        .collect();
    keys.dedup();
    for (effect, size) in keys {
        let of: Vec<&CaseResult> = results
            .iter()
            .filter(|r| r.effect == effect && r.size == size)
            .collect();
        let name = effect.trim_end_matches("+stale").to_string();
        let first = of.iter().filter(|r| r.named.first() == Some(&name)).count();
        let any = of.iter().filter(|r| r.named.contains(&name)).count();
        // the bench's own calibrations remove these two instrument offsets: the rigid
        // sweep sees the proximity offset, the vent-open zero the manometer's
        let calibrated_out = match effect.as_str() {
            "displacement_offset+stale" => {
                " (a stale calibration, but each indentation zeroes u_s before contact: none expected)"
            }
            "pressure_offset+stale" => " (a stale calibration: the offset reaches the measurement)",
            "displacement_offset" => {
                " (removed by the rigid-sample proximity calibration: none expected)"
            }
            "pressure_offset" => " (removed by the manometer's vent-open zero: none expected)",
            _ => "",
        };
        let worst_e2 = of
            .iter()
            .map(|r| {
                100.0
                    * (r.modulus_after_kpa.unwrap_or(r.modulus_baseline_kpa) / r.true_modulus_kpa
                        - 1.0)
            })
            .fold(0.0, |m: f64, v| if v.abs() > m.abs() { v } else { m });
        println!(
            "  {effect} at {size}: named first in {first} of {n}, named at all in {any} of {n}; E2 of the final model off by up to {worst_e2:+.1} %{calibrated_out}",
            n = of.len()
        );
    }
    rates(results);
}

/// The cases that should give `none`: clean data is separate; these are the instrument
/// offsets the bench's calibrations or each indentation's zero of u_s remove.
fn none_expected(effect: &str) -> bool {
    matches!(
        effect,
        "displacement_offset" | "displacement_offset+stale" | "pressure_offset"
    )
}

/// The study's rates with one-sided 95 % exact binomial bounds
/// (`diagnosis::stats::binomial_bounds`): an effect that reaches the measurement at its
/// clear size named (target >= 95 %), clean data naming something (target <= 5 %).
fn rates(results: &[CaseResult]) {
    let count = |of: &[&CaseResult], hit: &dyn Fn(&CaseResult) -> bool| {
        (of.iter().filter(|r| hit(r)).count(), of.len())
    };
    let clear: Vec<&CaseResult> = results
        .iter()
        .filter(|r| r.clear && r.effect != "none" && !none_expected(&r.effect))
        .collect();
    let nulls: Vec<&CaseResult> = results.iter().filter(|r| r.effect == "none").collect();
    let calibrated: Vec<&CaseResult> = results
        .iter()
        .filter(|r| none_expected(&r.effect))
        .collect();
    let named_itself = |r: &CaseResult| {
        r.named
            .contains(&r.effect.trim_end_matches("+stale").to_string())
    };
    println!("rates (one-sided 95 % exact binomial bounds):");
    let named_something = |r: &CaseResult| !r.named.is_empty();
    // (what is counted, (hits, cases), whether the rate's lower bound is the one that
    // matters, the target)
    let lines = [
        (
            "an effect at its clear size named",
            count(&clear, &named_itself),
            true,
            "; target >= 95 %",
        ),
        (
            "clean data naming something",
            count(&nulls, &named_something),
            false,
            "; target <= 5 %",
        ),
        (
            "offsets the bench removes naming something",
            count(&calibrated, &named_something),
            false,
            "",
        ),
    ];
    for (label, (k, n), lower, target) in lines {
        if n == 0 {
            continue;
        }
        let (lo, hi) = binomial_bounds(k, n, 0.05);
        let bound = if lower {
            format!(">= {:.1} %", 100.0 * lo)
        } else {
            format!("<= {:.1} %", 100.0 * hi)
        };
        println!("  {label}: {k} of {n} (rate {bound}{target})");
    }
}

/// Solves the truth of `scenario` (`diagnosis::simulate::truth_curves`, kept in the study's
/// `truth_cache`: the seeds of one effect and size share their sample), writes each curve
/// as JSON into `dir` and returns the `curves` mechanics source that reads them.
fn write_truth_curves(
    scenario: &Scenario,
    dir: &Path,
    truth_cache: &Path,
) -> Result<MechanicsSource, String> {
    let curves = diagnosis::simulate::truth_curves_cached(scenario, truth_cache)
        .map_err(|e| e.to_string())?;
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut files = Vec::new();
    for (k, c) in curves.iter().enumerate() {
        let path = dir.join(format!("curve-{k}.json"));
        let json = serde_json::to_string(c).map_err(|e| e.to_string())?;
        std::fs::write(&path, json).map_err(|e| format!("{}: {e}", path.display()))?;
        files.push(path);
    }
    Ok(MechanicsSource::Curves { files })
}
