//! The camera calibration's lens-distortion check on hil-sim's rendered reference discs:
//! the renderer draws each disc at exactly its radius times the optics' scale (no
//! distortion), so the check must not report one. The discs are measured by the real
//! vision code, whose per-disc errors weight the fit.

// Test helpers outside #[test] functions may unwrap too (clippy.toml allows it only inside them).
#![allow(clippy::unwrap_used)]

use experiment::simulated::{demo_scenario, px_per_mm_from_reference_disc};

#[test]
fn rendered_discs_show_no_lens_distortion() {
    for seed in 1..=4 {
        let scenario = demo_scenario(200.0, 6.0, seed);
        let px = px_per_mm_from_reference_disc(&scenario, &[1.2, 2.0, 2.8, 3.4]).unwrap();
        let d = px.lens_distortion.unwrap();
        eprintln!(
            "seed {seed}: k = {:.2e} ± {:.1e} /mm², {:.3} px/mm",
            d.k_per_mm2, d.k_sigma_per_mm2, px.px_per_mm
        );
        assert!(!d.significant(), "seed {seed}: {d:?}");
        // a distortion that changes the deepest contact radius by 0.5 % would be seen:
        // its k is several standard errors
        assert!(
            0.005 / (3.4f64 * 3.4) > 3.0 * d.k_sigma_per_mm2,
            "seed {seed}: {d:?}"
        );
    }
}
