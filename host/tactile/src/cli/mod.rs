//! Subcommand implementations; `main.rs` only dispatches.

pub mod calibrate;
pub mod daemon;
pub mod dashboard;
pub mod demo;
pub mod devices;
pub mod diagnose;
pub mod fem;
pub mod fit;
pub mod flash;
pub mod lut;
pub mod measure;
pub mod radius;
pub mod run;
pub mod status;
pub mod stop;
pub mod watch;

/// Prints a measurement's result the way `demo` and `measure` both report it: the modulus
/// with its interval and residual, the record directory, and the notes.
fn print_modulus_summary(
    modulus_kpa: f64,
    ci95_kpa: [f64; 2],
    rms_residual_mm: f64,
    record_dir: &str,
    notes: &[String],
) {
    println!(
        "E2 = {modulus_kpa:.1} kPa (95 % CI {:.1} .. {:.1} kPa), residual RMS {rms_residual_mm:.4} mm",
        ci95_kpa[0], ci95_kpa[1]
    );
    println!("record: {record_dir}");
    for note in notes {
        println!("note: {note}");
    }
}
