//! The host clock that frame timestamps are expressed in: microseconds of the monotonic clock
//! (`CLOCK_MONOTONIC` on Linux, i.e. [`std::time::Instant`]) since a process-wide epoch
//! fixed at the first call. V4L2 drivers stamp buffers with the same monotonic clock, so a
//! driver timestamp maps to host time by a fixed offset (see [`monotonic_to_host_us`]).

use std::sync::OnceLock;
use std::time::Instant;

fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

/// Microseconds since the process epoch.
pub fn now_us() -> u64 {
    u64::try_from(epoch().elapsed().as_micros()).unwrap_or(u64::MAX)
}

/// Maps a timestamp on another clock to host microseconds given one simultaneous pair of
/// readings (`other_now_us` on that clock taken at `host_now_us`):
/// `host = t + (host_now - other_now)`, saturating at 0 for times before the epoch.
pub fn map_clock_us(t_other_us: i128, other_now_us: i128, host_now_us: u64) -> u64 {
    let host = t_other_us - other_now_us + i128::from(host_now_us);
    u64::try_from(host.max(0)).unwrap_or(u64::MAX)
}

/// Maps a `CLOCK_MONOTONIC` timestamp (seconds, microseconds, as in a V4L2 buffer's
/// `timeval`) to host microseconds, reading both clocks now. `monotonic_now_us` is the
/// current `CLOCK_MONOTONIC` reading, passed in so that the mapping is testable.
pub fn monotonic_to_host_us(sec: i64, usec: i64, monotonic_now_us: i128, host_now_us: u64) -> u64 {
    let t = i128::from(sec) * 1_000_000 + i128::from(usec);
    map_clock_us(t, monotonic_now_us, host_now_us)
}
