//! TEST FIXTURE ONLY: an analytic stand-in for the finite-element solver, used to test the
//! LUT machinery (build, shards, file format, interpolation) quickly and against a known
//! function. It is not physics and must never be used to build a shipped table or by the
//! `tactile` commands.
//!
//! The stand-in curve for (E2, p_air) over h_k = k * max_depth / steps:
//!   u_s(h) = h * E2 / (E2 + 300 kPa) * (1 + p_air / 100 kPa)        (stiffer -> more u_s)
//!   a(u_s) = C * (E2 / 100 kPa)^(-1/3) * (1 + p_air / 50 kPa) * sqrt(0.2 mm + u_s)
//!   P      = 0.01 N * E2/100 kPa * u_s^1.5 + 0.001 N * p_air/kPa,  V = 100 mm^3 - 10 u_s
//! so at fixed (p_air, u_s) the contact radius is exactly a Hertz-like C' * E2^(-1/3) and is
//! linear in p_air, which gives the interpolation tests a closed form to compare with.

#![allow(dead_code)]

use fem_core::{Curve, CurveParams, CurvePoint};

pub const C_MM: f64 = 1.5;

/// Solver description recorded in tables built with the stand-in.
pub const STANDIN: &str = "analytic stand-in (TEST FIXTURE, not physics)";

/// Closed-form a at (E2, p_air, u_s) of the stand-in.
pub fn standin_a_mm(modulus_kpa: f64, pressure_kpa: f64, u_s_mm: f64) -> f64 {
    C_MM * (modulus_kpa / 100.0).powf(-1.0 / 3.0)
        * (1.0 + pressure_kpa / 50.0)
        * (0.2 + u_s_mm).sqrt()
}

/// The stand-in "solver" (test fixture).
pub fn standin_solver(p: &CurveParams) -> Result<Curve, String> {
    if p.sample_modulus_kpa <= 0.0 {
        return Err("non-positive modulus".into());
    }
    let e = p.sample_modulus_kpa;
    let points = (0..=p.steps)
        .map(|k| {
            let h = p.max_depth_mm * k as f64 / p.steps as f64;
            let u = h * e / (e + 300.0) * (1.0 + p.pressure_kpa / 100.0);
            CurvePoint {
                h_mm: h,
                u_s_mm: u,
                a_mm: standin_a_mm(e, p.pressure_kpa, u),
                load_n: 0.01 * e / 100.0 * u.powf(1.5) + 0.001 * p.pressure_kpa,
                volume_mm3: 100.0 - 10.0 * u,
                contact_pressure: Vec::new(),
            }
        })
        .collect();
    Ok(Curve {
        params: p.clone(),
        rest_volume_mm3: 100.0,
        inflated_volume_mm3: 100.0 + p.pressure_kpa,
        inflation_apex_mm: 0.01 * p.pressure_kpa,
        points,
        solve_seconds: 0.0,
    })
}
