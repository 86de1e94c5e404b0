//! The plant with real fem-core mechanics (slow: one coarse solve). Run in release:
//! `cargo test --release -p hil-sim --test fem_mechanics -- --ignored`.

#![allow(clippy::unwrap_used)] // tests may unwrap

use std::path::Path;

use hil_sim::device::SimDevice;
use hil_sim::scenario::Scenario;

#[test]
#[ignore = "runs a fem-core solve (about a minute in release)"]
fn gelatin_indentation_with_solved_mechanics_holds_pressure() {
    let text = r#"
        seed = 12
        [sample]
        modulus_kpa = 200.0
        [mechanics]
        source = "solve"
        pressures_kpa = [6.0]
        mesh_level = -1
        steps = 20
        [[programme]]
        at_s = 0.0
        request = { SetPressure = { setpoint_kpa = 6.0 } }
        [[programme]]
        at_s = 1.5
        indent_to_mm = 1.7
        speed_mm_per_s = 1.0
    "#;
    let mut dev =
        SimDevice::new(Scenario::parse(text, Path::new("gelatin.toml")).unwrap()).unwrap();
    dev.set_camera_enabled(false);
    dev.record_truth();
    dev.run_until(5.5);
    let truth = dev.take_truth();
    let last = truth.last().unwrap();
    // The paper's contact radii reach ~3.5 mm; at h = 1.7 mm on 200 kPa gelatin the apex
    // displacement is a fraction of h (the sample takes the rest: h = u_s + u_0).
    eprintln!("{:?}", last.contact);
    assert!((last.contact.h_mm - 1.7).abs() < 1e-3);
    assert!(last.contact.a_mm > 1.5 && last.contact.a_mm < 4.5);
    assert!(last.contact.u_s_mm > 0.0 && last.contact.u_s_mm < 1.7);
    let worst = truth
        .iter()
        .filter(|t| t.t_s >= 1.5)
        .map(|t| (t.pressure_kpa - 6.0).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.12, "{worst}");
}
