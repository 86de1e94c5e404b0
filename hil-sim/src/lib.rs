//! hil-sim: the emulated bench.
