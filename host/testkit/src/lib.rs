//! What the tests, benchmarks and examples of the host crates simulate, kept out of the
//! shipped libraries: an in-process controller behind a serial transport
//! ([`loopback_device`]), camera frames with an exactly known contact radius
//! ([`synthetic_frame`]), a–u_s curves drawn from the tables with known noise
//! ([`synthetic_curves`]) and minimal firmware ELF files ([`elf_image`]). The whole
//! emulated bench is hil-sim.

pub mod elf_image;
pub mod loopback_device;
pub mod synthetic_curves;
pub mod synthetic_frame;

pub use synthetic_frame::{SeededRng, SyntheticDisc, SyntheticScene};
