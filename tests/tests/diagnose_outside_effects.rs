//! The simulation of effects outside the diagnosis's library (`simulate::Outside`): what
//! the camera and the shell see under them, checked against the same seed without them
//! (the noise draws are the same, so the difference is the effect alone).

use diagnosis::simulate::{Outside, SimSpec, simulate};

fn spec(outside: Option<Outside>) -> SimSpec {
    SimSpec {
        outside,
        seed: 11,
        ..SimSpec::default()
    }
}

#[test]
fn a_lens_distortion_grows_with_the_cube_of_the_radius() {
    let k = 0.002;
    let plain = simulate(&spec(None)).expect("simulation");
    let distorted =
        simulate(&spec(Some(Outside::LensDistortion { k_per_mm2: k }))).expect("simulation");
    assert_eq!(plain.len(), distorted.len());
    let mut largest: f64 = 0.0;
    for (p, d) in plain.iter().zip(&distorted) {
        assert_eq!(p.u_s_mm, d.u_s_mm);
        assert_eq!(p.load_n, d.load_n);
        // seen = a (1 + k a^2) + noise, plain = a + noise: the difference is k a^3, with a
        // read off the noisy plain radius (white 4 um + offsets: 3 k a^2 times ~10 um is
        // below 1e-3 mm at a = 4 mm)
        let expected = k * p.a_mm.powi(3);
        assert!(
            (d.a_mm - p.a_mm - expected).abs() < 1e-3,
            "a {}: {} vs {expected}",
            p.a_mm,
            d.a_mm - p.a_mm
        );
        largest = largest.max(d.a_mm - p.a_mm);
    }
    // the deepest radii (about 3.7 mm) grow by about 0.1 mm
    assert!(largest > 0.08, "largest growth {largest} mm");
}

#[test]
fn a_pressure_leak_softens_the_shell_as_the_indentation_goes_on() {
    let plain = simulate(&spec(None)).expect("simulation");
    let leaking =
        simulate(&spec(Some(Outside::PressureLeak { kpa_per_s: 0.5 }))).expect("simulation");
    assert_eq!(plain.len(), leaking.len());
    let load = |p: &diagnosis::data::Point| p.load_n.unwrap_or(f64::NAN);
    // the first frame after contact: the pressure has barely moved (1/30 s at 0.5 kPa/s)
    let first = (&plain[0], &leaking[0]);
    assert!((load(first.1) - load(first.0)).abs() < 1e-3 * load(first.0).abs().max(1e-3));
    // the last frame of each indentation, 0.9 kPa below the set point: a softer shell
    // carries less of the tube's travel, so the apex moves further and the load is lower
    for (p, l) in plain.iter().zip(&leaking) {
        if p.t_s.is_some_and(|t| t > 1.7) {
            assert!(l.u_s_mm > p.u_s_mm, "{p:?} vs {l:?}");
            assert!(load(l) < load(p), "{p:?} vs {l:?}");
        }
    }
}
