//! Verification of the element, materials and follower pressure on a pressurised thick
//! sphere (a = 4.6 mm, b = 5 mm: the sensor's wall), modelled as a hemisphere with symmetry
//! conditions on the equator plane.

// Test helpers outside #[test] functions unwrap solver results too.
#![allow(clippy::unwrap_used)]

use fem_core::element::Formulation;
use fem_core::material::{Material, MaterialLaw};
use fem_core::mesh::{Mesh, ShellDivisions, ShellGeometry, add_shell};
use fem_core::model::Model;

/// Inner and outer radial displacement (mm) at the equator after ramping the pressure.
fn inflate_sphere(
    law: MaterialLaw,
    nu: f64,
    pressure_kpa: f64,
    divisions: ShellDivisions,
    formulation: Formulation,
    ramp_steps: usize,
) -> (f64, f64) {
    inflate_sphere_with(
        Material::from_young_poisson(2300.0, nu, law),
        pressure_kpa,
        divisions,
        formulation,
        ramp_steps,
    )
}

fn inflate_sphere_with(
    material: Material,
    pressure_kpa: f64,
    divisions: ShellDivisions,
    formulation: Formulation,
    ramp_steps: usize,
) -> (f64, f64) {
    let mut mesh = Mesh::default();
    let shell = add_shell(&mut mesh, &SPHERE, &divisions, 0);
    let mut model = Model::new(mesh, vec![material], formulation);
    let mut fixed: Vec<usize> = shell.axis.iter().map(|&n| 2 * n).collect();
    fixed.extend(shell.equator.iter().map(|&n| 2 * n + 1));
    model.fix_all(fixed);
    model.pressure_surface = shell.inner_surface.clone();
    let mut u = vec![0.0; model.n_dofs()];
    for k in 1..=ramp_steps {
        let p = pressure_kpa * k as f64 / ramp_steps as f64;
        model.solve_equilibrium(&mut u, p).unwrap();
    }
    let inner = shell.equator[0];
    let outer = shell.equator[shell.equator.len() - 1];
    // the apex must move like the equator (spherical symmetry of the discrete solution)
    let apex = -u[2 * shell.inner_apex + 1];
    let eq = u[2 * inner];
    assert!(
        (apex - eq).abs() < 2e-3 * eq.abs(),
        "apex {apex} vs equator {eq}: spherical symmetry lost"
    );
    (u[2 * inner], u[2 * outer])
}

/// The sensor's wall as a hemisphere without skirt.
const SPHERE: ShellGeometry = ShellGeometry {
    inner_radius_mm: 4.6,
    outer_radius_mm: 5.0,
    skirt_length_mm: 0.0,
};

const COARSE: ShellDivisions = ShellDivisions {
    arc: 8,
    skirt: 0,
    thickness: 2,
};

#[test]
fn lame_thick_sphere_small_strain() {
    // Lamé: u(r) = p a^3 / (E (b^3 - a^3)) [ (1 - 2 nu) r + (1 + nu) b^3 / (2 r^2) ]
    // a = 4.6, b = 5, E = 2300 kPa, nu = 0.49, p = 15 kPa: 103.100 um and 87.772 um.
    let (ui, uo) = inflate_sphere(
        MaterialLaw::Linear,
        0.49,
        15.0,
        COARSE,
        Formulation::Mixed,
        1,
    );
    let (a, b, e, nu, p): (f64, f64, f64, f64, f64) = (4.6, 5.0, 2300.0, 0.49, 15.0);
    let lame = |r: f64| {
        p * a.powi(3) / (e * (b.powi(3) - a.powi(3)))
            * ((1.0 - 2.0 * nu) * r + (1.0 + nu) * b.powi(3) / (2.0 * r * r))
    };
    assert!((lame(a) * 1e3 - 103.100).abs() < 1e-3);
    assert!((lame(b) * 1e3 - 87.772).abs() < 1e-3);
    println!(
        "Lame: inner {:.4} um (exact 103.100), outer {:.4} um (exact 87.772)",
        ui * 1e3,
        uo * 1e3
    );
    // accepted error 0.5 %
    assert!((ui / lame(a) - 1.0).abs() < 5e-3, "inner {ui}");
    assert!((uo / lame(b) - 1.0).abs() < 5e-3, "outer {uo}");
}

#[test]
fn incompressible_neo_hookean_sphere_inflation() {
    // Exact incompressible neo-Hookean thick sphere (mu = E/3): inner-radius displacement
    // 42.134 um at 6 kPa, 111.570 um at 15 kPa, 505.189 um at 50 kPa, checked to
    // 1 % with nu = 0.4999 (bulk/shear ratio 1.7e3).
    for (p, exact_um, steps) in [(6.0, 42.134, 1), (15.0, 111.570, 2), (50.0, 505.189, 5)] {
        let (ui, _) = inflate_sphere(
            MaterialLaw::NeoHookean,
            0.4999,
            p,
            COARSE,
            Formulation::Mixed,
            steps,
        );
        println!(
            "neo-Hookean sphere p = {p} kPa: inner {:.3} um (exact {exact_um})",
            ui * 1e3
        );
        assert!((ui * 1e3 / exact_um - 1.0).abs() < 1e-2, "p = {p}: {ui}");
    }
}

#[test]
fn exact_incompressible_reference_values() {
    // Independent check of the quoted numbers: for an incompressible neo-Hookean sphere
    // p = mu int_{lambda_b}^{lambda_a} (lambda^-2 + lambda^-5) ... in the form
    // p = int_a^b (sigma_tt - sigma_rr) 2/r dr with r^3 = R^3 + (a^3 - A^3).
    let mu = 2300.0 / 3.0;
    let (ai, bo): (f64, f64) = (4.6, 5.0);
    let pressure_for = |du: f64| {
        let c = (ai + du).powi(3) - ai.powi(3);
        // integrate over the reference radius R with Simpson's rule
        let n = 2000;
        let h = (bo - ai) / n as f64;
        let f = |rr: f64| {
            let r = (rr.powi(3) + c).cbrt();
            let lam = r / rr; // hoop stretch; radial stretch 1/lam^2
            let diff = mu * (lam * lam - lam.powi(-4));
            // dr = (R/r)^2 dR
            diff * 2.0 / r * (rr / r).powi(2)
        };
        let mut s = f(ai) + f(bo);
        for k in 1..n {
            s += f(ai + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    };
    for (p, du_um) in [(6.0, 42.134), (15.0, 111.570), (50.0, 505.189)] {
        let got = pressure_for(du_um * 1e-3);
        assert!(
            (got / p - 1.0).abs() < 1e-4,
            "p({du_um} um) = {got}, expected {p}"
        );
    }
}

#[test]
fn clamped_shell_bending_does_not_lock_with_the_mixed_element() {
    // Bending-dominated: the sensor shell clamped on its skirt and inflated (the wall bends
    // near the clamp). Physically, going from nu = 0.49 to 0.4999 changes the apex
    // deflection by ~1 %; a locking element stiffens markedly. One element through the
    // wall, coarse along it, makes locking visible.
    use fem_core::problem::{Indentation, SolverSettings};
    let run = |nu: f64, formulation: Formulation| {
        let params = fem_core::CurveParams {
            shell_poisson: nu,
            material: MaterialLaw::Linear,
            ..Default::default()
        };
        let mut settings = SolverSettings::for_level(-2);
        settings.formulation = formulation;
        settings.mesh.shell = ShellDivisions {
            arc: 6,
            skirt: 2,
            thickness: 1,
        };
        let mut ind = Indentation::build(&params, &settings, None);
        let mut u = vec![0.0; ind.model.n_dofs()];
        ind.model.solve_equilibrium(&mut u, 6.0).unwrap();
        -u[2 * ind.shell.inner_apex + 1]
    };
    let mixed = (
        run(0.49, Formulation::Mixed),
        run(0.4999, Formulation::Mixed),
    );
    let displ = (
        run(0.49, Formulation::Displacement),
        run(0.4999, Formulation::Displacement),
    );
    let mixed_limit = run(0.499999, Formulation::Mixed);
    let displ_limit = run(0.499999, Formulation::Displacement);
    println!(
        "apex deflection (um) nu 0.49 / 0.4999 / 0.499999: mixed {:.3} / {:.3} / {:.3}, \
         displacement {:.3} / {:.3} / {:.3}",
        mixed.0 * 1e3,
        mixed.1 * 1e3,
        mixed_limit * 1e3,
        displ.0 * 1e3,
        displ.1 * 1e3,
        displ_limit * 1e3
    );
    // the physical effect of nu 0.49 -> 0.4999 is ~1 % (thick-sphere Lame estimate 0.99)
    let ratio_mixed = mixed.1 / mixed.0;
    assert!(
        (ratio_mixed - 0.99).abs() < 0.01,
        "mixed ratio {ratio_mixed}"
    );
    // no locking: a 100x larger bulk modulus changes the mixed answer by < 0.1 %
    assert!((mixed_limit / mixed.1 - 1.0).abs() < 1e-3);
    // control (shows the test detects locking): the pure-displacement Q9 keeps stiffening
    // (measured 0.961) and is stiffer than the mixed element at nu = 0.4999
    assert!(
        displ_limit / displ.1 < 0.98,
        "displacement element did not lock"
    );
    assert!(displ.1 < mixed.1 * 0.99);
}

/// Exact inflation pressure of an incompressible thick sphere (inner radius A = 4.6 mm,
/// outer B = 5 mm) of a two-term Yeoh material, `W = c1 (I1 - 3) + c2 (I1 - 3)^2` with
/// `c1 = mu/2`, `c2 = beta c1`, when the inner radius has grown by `du` (mm):
/// `p = int_a^b (sigma_tt - sigma_rr) 2/r dr`, with `sigma_tt - sigma_rr
/// = 2 dW/dI1 (l^2 - l^-4) = mu (1 + 2 beta (I1 - 3)) (l^2 - l^-4)`, hoop stretch
/// `l = r/R`, `I1 = 2 l^2 + l^-4`, `r^3 = R^3 + a^3 - A^3` (Ogden, "Non-linear elastic
/// deformations", sec. 5.3). Composite Simpson over the reference radius R.
fn yeoh_sphere_pressure_kpa(mu: f64, beta: f64, du: f64) -> f64 {
    let (ai, bo): (f64, f64) = (4.6, 5.0);
    let c = (ai + du).powi(3) - ai.powi(3);
    let n = 2000;
    let h = (bo - ai) / n as f64;
    let f = |rr: f64| {
        let r = (rr.powi(3) + c).cbrt();
        let lam = r / rr;
        let i1 = 2.0 * lam * lam + lam.powi(-4);
        let diff = mu * (1.0 + 2.0 * beta * (i1 - 3.0)) * (lam * lam - lam.powi(-4));
        diff * 2.0 / r * (rr / r).powi(2)
    };
    let mut s = f(ai) + f(bo);
    for k in 1..n {
        s += f(ai + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

/// Inner-radius growth (mm) of the exact Yeoh sphere at pressure `p_kpa` (bisection on the
/// monotone pressure–radius relation; stiffening rules out a limit point).
fn yeoh_sphere_inflation_mm(mu: f64, beta: f64, p_kpa: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 3.0);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if yeoh_sphere_pressure_kpa(mu, beta, mid) < p_kpa {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn strain_stiffening_sphere_inflation_matches_the_exact_incompressible_yeoh_solution() {
    // beta = 0 reproduces the neo-Hookean reference numbers above (checks the quadrature)
    let mu = 2300.0 / 3.0;
    let du0 = yeoh_sphere_inflation_mm(mu, 0.0, 50.0);
    assert!((du0 * 1e3 / 505.189 - 1.0).abs() < 1e-4, "{du0}");
    // The sensor wall at 50 kPa reaches I1 - 3 ~ 0.1, so beta = 5 stiffens it by ~2x.
    for (beta, p, steps) in [(5.0, 50.0, 5), (1.0, 30.0, 3)] {
        let exact = yeoh_sphere_inflation_mm(mu, beta, p);
        let neo = yeoh_sphere_inflation_mm(mu, 0.0, p);
        let mat = Material::from_young_poisson(2300.0, 0.4999, MaterialLaw::NeoHookean)
            .with_stiffening(beta);
        let (ui, _) = inflate_sphere_with(mat, p, COARSE, Formulation::Mixed, steps);
        println!(
            "Yeoh sphere beta = {beta}, p = {p} kPa: inner {:.3} um (exact {:.3}, neo-Hookean \
             {:.3})",
            ui * 1e3,
            exact * 1e3,
            neo * 1e3
        );
        // the stiffening effect must exceed 3x the tolerance below for the test to
        // discriminate (5.8 % at beta = 1, 38 % at beta = 5)
        assert!(neo / exact - 1.0 > 3e-2, "{neo} vs {exact}");
        // same 1 % as the neo-Hookean check (nu = 0.4999, coarse mesh)
        assert!(
            (ui / exact - 1.0).abs() < 1e-2,
            "beta {beta}: {ui} vs {exact}"
        );
    }
}

/// The sphere's mesh with eight elements through the wall over the middle of the arc and
/// two elsewhere, joined by hanging nodes (`Mesh::add_block_coarsened`).
fn coarsened_sphere(law: MaterialLaw, nu: f64) -> (Model, fem_core::mesh::ShellMesh) {
    use fem_core::mesh::{Coarsening, GridDirection, add_shell_coarsened};
    let divisions = ShellDivisions {
        arc: 8,
        skirt: 0,
        thickness: 8,
    };
    let arc_edges: Vec<f64> = (0..=8)
        .map(|k| std::f64::consts::FRAC_PI_2 * k as f64 / 8.0)
        .collect();
    let coarsening = Coarsening {
        direction: GridDirection::Second,
        fine: (0..8).map(|e| (3..5).contains(&e)).collect(),
        groups: vec![4, 4],
    };
    let mut mesh = Mesh::default();
    let shell = add_shell_coarsened(
        &mut mesh,
        &SPHERE,
        &divisions,
        &arc_edges,
        Some(&coarsening),
        0,
    );
    // 6 coarse columns of 2 x 4 elements, 2 fine columns of 8
    assert_eq!(mesh.elements.len(), 6 * 2 + 2 * 8);
    assert!(!mesh.hanging.is_empty());
    let material = Material::from_young_poisson(2300.0, nu, law);
    let mut model = Model::new(mesh, vec![material], Formulation::Mixed);
    let mut fixed: Vec<usize> = shell.axis.iter().map(|&n| 2 * n).collect();
    fixed.extend(shell.equator.iter().map(|&n| 2 * n + 1));
    model.fix_all(fixed);
    model.pressure_surface = shell.inner_surface.clone();
    (model, shell)
}

#[test]
fn hanging_nodes_keep_the_lame_sphere_spherical() {
    // The pressurised sphere's displacement is radial and the same at every polar angle;
    // a change of wall division along the arc must neither break that symmetry nor move
    // the solution away from Lamé's (same 0.5 % as the uniform mesh above). A
    // non-conforming junction or a wrong constraint shows as a kink at the fine columns.
    let (mut model, shell) = coarsened_sphere(MaterialLaw::Linear, 0.49);
    let mut u = vec![0.0; model.n_dofs()];
    model.solve_equilibrium(&mut u, 15.0).unwrap();
    let (a, b, e, nu, p): (f64, f64, f64, f64, f64) = (4.6, 5.0, 2300.0, 0.49, 15.0);
    let lame = |r: f64| {
        p * a.powi(3) / (e * (b.powi(3) - a.powi(3)))
            * ((1.0 - 2.0 * nu) * r + (1.0 + nu) * b.powi(3) / (2.0 * r * r))
    };
    let radial = |n: usize| {
        let x = model.mesh.nodes[n];
        (u[2 * n] * x[0] + u[2 * n + 1] * x[1]) / (x[0] * x[0] + x[1] * x[1]).sqrt()
    };
    for (surface, r) in [(&shell.inner_surface, a), (&shell.outer_surface, b)] {
        for &n in surface.iter() {
            let ur = radial(n);
            assert!(
                (ur / lame(r) - 1.0).abs() < 5e-3,
                "node {n}: {ur} vs {}",
                lame(r)
            );
        }
        // symmetry: 2e-3 as for the uniform mesh's apex against its equator
        let first = radial(surface[0]);
        for &n in surface.iter() {
            assert!(
                (radial(n) / first - 1.0).abs() < 2e-3,
                "node {n} breaks symmetry"
            );
        }
    }
    // every hanging node sits on its masters' quadratic: the field there is the
    // interpolation of theirs
    for h in &model.mesh.hanging {
        for c in 0..2 {
            let interpolated: f64 = h.masters.iter().map(|&(m, w)| w * u[2 * m + c]).sum();
            assert!((u[2 * h.node + c] - interpolated).abs() < 1e-15);
        }
    }
}

#[test]
fn tangent_with_hanging_nodes_matches_finite_differences() {
    // C^T K C and C^T r: the assembled tangent over the free dofs against central
    // differences of the condensed residual, moving each probed dof with its hanging
    // dependants (the state is off equilibrium, nonlinear material and follower pressure).
    let (model, _) = coarsened_sphere(MaterialLaw::NeoHookean, 0.45);
    let n_dofs = model.n_dofs();
    let mut u: Vec<f64> = (0..n_dofs)
        .map(|i| 5e-3 * ((i as f64) * 0.37).sin())
        .collect();
    model.apply_prescribed(&mut u);
    let p = 10.0;
    let asm = model.assemble(&u, p, true).unwrap();
    let free: Vec<usize> = (0..n_dofs).filter(|&d| model.is_free(d)).collect();
    let mut eq = vec![usize::MAX; n_dofs];
    for (k, &d) in free.iter().enumerate() {
        eq[d] = k;
    }
    let mut worst: f64 = 0.0;
    for &d in free.iter().step_by(7) {
        let h = 1e-7;
        let residual_at = |shift: f64| {
            let mut v = u.clone();
            v[d] += shift;
            model.apply_prescribed(&mut v);
            model.assemble(&v, p, false).unwrap().residual
        };
        let (rp, rm) = (residual_at(h), residual_at(-h));
        let j = eq[d];
        let mut column = vec![0.0; free.len()];
        for (r, c, v) in asm.tangent.entries() {
            if c == j {
                column[r] += v;
            }
            if r == j && r != c {
                column[c] += v;
            }
        }
        let scale = column.iter().fold(0.0, |m: f64, v| m.max(v.abs()));
        for (k, &dd) in free.iter().enumerate() {
            let fd = (rp[dd] - rm[dd]) / (2.0 * h);
            worst = worst.max((fd - column[k]).abs() / scale);
        }
    }
    // central differences with h = 1e-7 mm: truncation ~h^2 and round-off ~1e-16 / h of
    // the column's scale, well under 1e-6
    assert!(worst < 1e-6, "tangent vs finite differences: {worst:e}");
}
