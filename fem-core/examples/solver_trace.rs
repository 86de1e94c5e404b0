//! Trace the Newton work of one curve: per stage-2 step attempt the residual histories of
//! its Newton solves (first solve, then one per contact augmentation), each residual
//! followed by the contact set's change at that assembly (`3e-2(+1-2)`: one slave point
//! came into contact, two left it; `fem_core::contact_set`), and the totals, with how many
//! assemblies of the converged solves came before the set's last change.
//! `cargo run -p fem-core --release --example solver_trace -- [modulus_kpa] [pressure_kpa]
//! [mesh_level] [friction] [steps] [depth_mm]`; `FEM_CHORD=0` disables the chord iterations (full Newton
//! only), `FEM_CHORD=N,Q` allows N of them per solve with contraction Q; `FEM_EDGE_BAND=1`
//! solves with the band of fine elements at the contact edge (`FEM_FINER_BAND=1`: one
//! refinement finer), `FEM_CONTACT_CURVATURE=0|1`
//! leaves out or includes the master surface's curvature in the contact tangent;
//! `FEM_ANDERSON=N` mixes the chord iterations by Anderson acceleration of depth N
//! (`Simulation::with_anderson_acceleration`, its depth replaced; `FEM_CHORD` after it);
//! the contact's settings: `FEM_PENALTY=F` replaces the penalty factor,
//! `FEM_AUGMENTATIONS=N` the Uzawa augmentations per step and `FEM_PENETRATION_SCALE=S`
//! multiplies the penetration tolerance that ends them.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse::<f64>())
        .collect::<Result<_, _>>()?;
    let get = |i: usize, d: f64| args.get(i).copied().unwrap_or(d);
    let params = fem_core::CurveParams {
        sample_modulus_kpa: get(0, 200.0),
        pressure_kpa: get(1, 6.0),
        mesh_level: get(2, 0.0) as i32,
        friction: get(3, 0.0),
        steps: get(4, 40.0) as usize,
        max_depth_mm: get(5, 2.0),
        ..Default::default()
    };
    let mut sim = fem_core::Simulation::new(&params);
    if std::env::var_os("FEM_FINER_BAND").is_some() {
        sim = sim.with_finer_edge_band();
    } else if std::env::var_os("FEM_EDGE_BAND").is_some() {
        sim = sim.with_edge_band();
    }
    if let Ok(depth) = std::env::var("FEM_ANDERSON") {
        sim = sim.with_anderson_acceleration();
        sim.nonlinear_solver.anderson_depth = depth.parse()?;
    }
    if let Ok(f) = std::env::var("FEM_PENALTY") {
        sim.discretisation.penalty_factor = f.parse()?;
    }
    if let Ok(n) = std::env::var("FEM_AUGMENTATIONS") {
        sim.nonlinear_solver.augmentations = n.parse()?;
    }
    if let Ok(s) = std::env::var("FEM_PENETRATION_SCALE") {
        sim.nonlinear_solver.penetration_tolerance_mm *= s.parse::<f64>()?;
    }
    if let Ok(v) = std::env::var("FEM_CONTACT_CURVATURE") {
        sim.linear_solver.contact_curvature_tangent = v != "0";
    }
    if let Ok(c) = std::env::var("FEM_CHORD") {
        let mut parts = c.split(',');
        if let Some(k) = parts.next().and_then(|v| v.parse().ok()) {
            sim.linear_solver.chord_iterations = k;
        }
        if let Some(q) = parts.next().and_then(|v| v.parse().ok()) {
            sim.linear_solver.chord_contraction = q;
        }
    }
    let started = std::time::Instant::now();
    let solution = sim.solve()?;
    if let fem_core::StopReason::Stopped { error, .. } = &solution.stop {
        println!("stopped: {error}");
    }
    let (curve, ind) = (solution.curve, solution.indentation);
    let seconds = started.elapsed().as_secs_f64();
    let verbose = std::env::var_os("FEM_TRACE_QUIET").is_none();
    let mut per_step = std::collections::BTreeMap::<String, usize>::new();
    let mut settling = Settling::default();
    for a in &ind.attempts {
        let its: Vec<usize> = a.solves.iter().map(|h| h.len()).collect();
        *per_step.entry(format!("{:.4}", a.h_mm)).or_default() += its.iter().sum::<usize>();
        for (solve, changes) in a.solves.iter().zip(&a.contact_changes) {
            settling.add(solve, changes, a.converged);
        }
        if verbose {
            // each residual, and after it how the contact set changed at that assembly
            // (+points that entered / -points that left)
            let hist: Vec<String> = a
                .solves
                .iter()
                .zip(&a.contact_changes)
                .map(|(h, changes)| {
                    h.iter()
                        .zip(changes)
                        .map(|(r, c)| {
                            if c.changed() {
                                format!("{r:.0e}(+{}-{})", c.entered, c.left)
                            } else {
                                format!("{r:.0e}")
                            }
                        })
                        .collect::<Vec<_>>()
                        .join(" ")
                })
                .collect();
            println!(
                "h {:.4} {} assemblies {:?}: {}",
                a.h_mm,
                if a.converged { "ok  " } else { "FAIL" },
                its,
                hist.join(" | ")
            );
        }
    }
    let s1 = &ind.stage1_stats;
    // every mesh of stage 2 (the band's moves rebuild the model)
    let work = ind.stage2_work();
    let s2 = &work.stats;
    let failed = ind.attempts.iter().filter(|a| !a.converged).count();
    println!(
        "stage 1: {} solves, {} assemblies, {} factorisations, {} residual-only assemblies",
        s1.newton_solves, s1.assemblies, s1.factorizations, s1.residual_assemblies
    );
    println!(
        "stage 2 ({} meshes): {} attempts ({} failed) for {} steps, {} Newton solves ({} failed), {} \
         assemblies, {} factorisations, {} residual-only assemblies ({:.1} full and {:.1} \
         residual-only assemblies per step), assembly {:.3} s, linear \
         {:.3} s, fallbacks (LDLT, LU) {:?}",
        ind.band_moves + 1,
        ind.attempts.len(),
        failed,
        curve.points.len() - 1,
        s2.newton_solves,
        s2.failed_solves,
        s2.assemblies,
        s2.factorizations,
        s2.residual_assemblies,
        s2.assemblies as f64 / (curve.points.len() - 1) as f64,
        s2.residual_assemblies as f64 / (curve.points.len() - 1) as f64,
        work.assembly_seconds,
        work.solve_seconds,
        work.fallbacks
    );
    println!(
        "band: {} moves, {} failed transfers, {} restarts from the start on the moved mesh",
        ind.band_moves, ind.band_move_failures, ind.band_restarts
    );
    settling.print();
    println!("curve solve {seconds:.3} s");
    if std::env::var_os("FEM_TRACE_POINTS").is_some() {
        for p in &curve.points {
            println!(
                "point {:.4} {:.12e} {:.12e} {:.12e}",
                p.h_mm, p.u_s_mm, p.a_mm, p.load_n
            );
        }
    }
    Ok(())
}

/// Where the Newton work of the converged step attempts goes: the assemblies of each
/// solve up to the last one at which the contact set changed (the set settling), and
/// those after it (the contact set fixed).
#[derive(Default)]
struct Settling {
    solves: usize,
    assemblies: usize,
    settling: usize,
    changes: usize,
    points_changed: usize,
    farthest_mm: Vec<f64>,
    tail: Vec<f64>,
}

impl Settling {
    fn add(
        &mut self,
        residuals: &[f64],
        changes: &[fem_core::contact_set::ContactSetChange],
        ok: bool,
    ) {
        if !ok {
            return;
        }
        self.solves += 1;
        self.assemblies += residuals.len();
        // the first entry compares with the solve before (the step's predictor or the
        // multipliers' update); the settling is what changes from the second on
        let last = changes
            .iter()
            .enumerate()
            .skip(1)
            .rfind(|(_, c)| c.changed())
            .map_or(1, |(i, _)| i + 1);
        self.settling += last;
        for c in changes.iter().skip(1).filter(|c| c.changed()) {
            self.changes += 1;
            self.points_changed += c.entered + c.left;
            self.farthest_mm.push(c.farthest_from_edge_mm);
        }
        // the residual at which the set last changed: Newton's quadratic tail starts there
        if let Some(&r) = residuals.get(last - 1) {
            self.tail.push(r);
        }
    }

    fn print(&mut self) {
        let quantile = |v: &mut Vec<f64>, q: f64| {
            v.sort_by(f64::total_cmp);
            v.get(((v.len() as f64 - 1.0) * q).round() as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        let median_tail = quantile(&mut self.tail, 0.5);
        let (p50, p95, max) = (
            quantile(&mut self.farthest_mm, 0.5),
            quantile(&mut self.farthest_mm, 0.95),
            quantile(&mut self.farthest_mm, 1.0),
        );
        println!(
            "contact set in the {} converged solves: {} of {} assemblies up to the last change \
             of the set ({} assemblies changed it, {} points in all; farthest from the edge: \
             median {:.1} um, 95 % {:.1} um, largest {:.1} um); median residual at the last \
             change {:.0e}",
            self.solves,
            self.settling,
            self.assemblies,
            self.changes,
            self.points_changed,
            1e3 * p50,
            1e3 * p95,
            1e3 * max,
            median_tail
        );
    }
}
