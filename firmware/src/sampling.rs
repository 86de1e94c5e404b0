//! Sampling: oversampling of the 12-bit ADC, averaging between streamed samples, and the
//! HX711 load cell as its conversions arrive (with tare).
//!
//! Oversampling: the sum of N = 16 conversions of a 12-bit ADC is a 16-bit count; with at
//! least ~1 LSB of noise (the RP2040 ADC has more) the sum resolves the input below one
//! 12-bit step and averages white noise down by sqrt(16) = 4.

use crate::device_constants::OVERSAMPLE_COUNT;

/// Sums [`OVERSAMPLE_COUNT`] 12-bit conversions into one 16-bit reading. The board layer
/// pushes conversions as they come (e.g. from the ADC FIFO) and takes one reading per tick.
#[derive(Debug, Clone, Copy, Default)]
pub struct Oversampler {
    sum: u32,
    count: u32,
}

impl Oversampler {
    pub const fn new() -> Self {
        Self { sum: 0, count: 0 }
    }

    /// Adds one 12-bit conversion (bits above 12 are ignored: the RP2040 sets bit 15 on a
    /// conversion error, which must not leak into the sum).
    pub fn push(&mut self, raw_12bit: u16) {
        self.sum = self.sum.saturating_add(u32::from(raw_12bit & 0x0fff));
        self.count = self.count.saturating_add(1);
    }

    /// Conversions accumulated so far.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The 16-bit reading: the sum scaled to exactly [`OVERSAMPLE_COUNT`] conversions (so a
    /// short or long burst still reads on the same scale), then restarts. `None` when no
    /// conversion was pushed.
    pub fn take(&mut self) -> Option<u16> {
        if self.count == 0 {
            return None;
        }
        let scaled = (u64::from(self.sum) * u64::from(OVERSAMPLE_COUNT)
            + u64::from(self.count / 2))
            / u64::from(self.count);
        *self = Self::new();
        Some(scaled.min(u64::from(u16::MAX)) as u16)
    }
}

/// Boxcar average of the per-tick readings between two streamed samples: when the stream
/// runs slower than the tick rate, each sample is the mean of the ticks it stands for
/// (an anti-aliasing filter), not a single decimated reading.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReadingAverager {
    sum: u64,
    count: u32,
}

impl ReadingAverager {
    pub const fn new() -> Self {
        Self { sum: 0, count: 0 }
    }

    pub fn add(&mut self, counts: u16) {
        self.sum += u64::from(counts);
        self.count = self.count.saturating_add(1);
    }

    /// Rounded mean since the last take, then restarts; `None` when empty.
    pub fn take(&mut self) -> Option<u16> {
        if self.count == 0 {
            return None;
        }
        let n = u64::from(self.count);
        let mean = (self.sum + n / 2) / n;
        *self = Self::new();
        // The mean of u16 values is a u16.
        Some(mean as u16)
    }
}

/// How many recent conversions a tare averages.
pub const TARE_AVERAGE_COUNT: usize = 8;

/// The load cell channel: the latest HX711 conversion, whether it is new, the tare offset,
/// and the time of the last conversion (for the load-cell timeout).
#[derive(Debug, Clone, Copy, Default)]
pub struct LoadCell {
    latest_counts: Option<i32>,
    recent: [i32; TARE_AVERAGE_COUNT],
    recent_len: usize,
    recent_next: usize,
    tare_counts: i32,
    fresh: bool,
    last_conversion_us: Option<u64>,
}

impl LoadCell {
    pub const fn new() -> Self {
        Self {
            latest_counts: None,
            recent: [0; TARE_AVERAGE_COUNT],
            recent_len: 0,
            recent_next: 0,
            tare_counts: 0,
            fresh: false,
            last_conversion_us: None,
        }
    }

    /// Records a new conversion (signed 24-bit counts).
    pub fn record(&mut self, counts: i32, now_us: u64) {
        self.latest_counts = Some(counts);
        self.recent[self.recent_next] = counts;
        self.recent_next = (self.recent_next + 1) % TARE_AVERAGE_COUNT;
        self.recent_len = (self.recent_len + 1).min(TARE_AVERAGE_COUNT);
        self.fresh = true;
        self.last_conversion_us = Some(now_us);
    }

    /// Latest conversion minus the tare, `None` before the first conversion.
    pub fn tared_counts(&self) -> Option<i32> {
        self.latest_counts
            .map(|counts| counts.saturating_sub(self.tare_counts))
    }

    /// True once per conversion: returns whether a conversion arrived since the last call.
    pub fn take_fresh(&mut self) -> bool {
        core::mem::take(&mut self.fresh)
    }

    /// Takes the mean of the last (up to [`TARE_AVERAGE_COUNT`]) conversions as zero.
    /// Returns false (and changes nothing) before the first conversion.
    pub fn tare(&mut self) -> bool {
        if self.recent_len == 0 {
            return false;
        }
        let sum: i64 = self.recent[..self.recent_len]
            .iter()
            .map(|&c| i64::from(c))
            .sum();
        let n = self.recent_len as i64;
        // Round half away from zero; the mean of i32 values fits in i32.
        let mean = if sum >= 0 {
            (sum + n / 2) / n
        } else {
            (sum - n / 2) / n
        };
        self.tare_counts = mean as i32;
        true
    }

    pub fn tare_counts(&self) -> i32 {
        self.tare_counts
    }

    /// Microseconds since the last conversion, `None` before the first one.
    pub fn silent_for_us(&self, now_us: u64) -> Option<u64> {
        self.last_conversion_us
            .map(|last| now_us.saturating_sub(last))
    }
}

/// Decodes the 24 bits clocked out of an HX711 (MSB first) as two's complement.
pub fn hx711_counts_from_bits(raw_24bit: u32) -> i32 {
    // Shift the sign bit into bit 31, then arithmetic-shift back.
    ((raw_24bit << 8) as i32) >> 8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_conversions_make_a_16_bit_reading() {
        let mut o = Oversampler::new();
        assert_eq!(o.take(), None);
        for _ in 0..16 {
            o.push(4095);
        }
        assert_eq!(o.take(), Some(65520));
        // A value between two 12-bit codes is resolved by the sum (dither).
        for i in 0..16 {
            o.push(if i % 4 == 0 { 2049 } else { 2048 });
        }
        assert_eq!(o.take(), Some(2048 * 16 + 4));
        // A burst of 8 is scaled to the same 16-conversion scale.
        for _ in 0..8 {
            o.push(1000);
        }
        assert_eq!(o.take(), Some(16_000));
        // The RP2040 error bit (15) is masked off.
        o.push(0x8000 | 100);
        assert_eq!(o.take(), Some(1600));
    }

    #[test]
    fn averager_rounds_the_mean() {
        let mut a = ReadingAverager::new();
        assert_eq!(a.take(), None);
        a.add(10);
        a.add(11);
        assert_eq!(a.take(), Some(11));
        a.add(7);
        assert_eq!(a.take(), Some(7));
    }

    #[test]
    fn hx711_twos_complement() {
        assert_eq!(hx711_counts_from_bits(0x00_0001), 1);
        assert_eq!(hx711_counts_from_bits(0x7f_ffff), 8_388_607);
        assert_eq!(hx711_counts_from_bits(0x80_0000), -8_388_608);
        assert_eq!(hx711_counts_from_bits(0xff_ffff), -1);
    }

    #[test]
    fn tare_averages_recent_conversions_and_fresh_is_one_shot() {
        let mut l = LoadCell::new();
        assert!(!l.tare());
        assert_eq!(l.tared_counts(), None);
        for (i, c) in [100, 102, 98, 100, -50_000].iter().enumerate() {
            l.record(*c, i as u64 * 12_500);
        }
        assert!(l.take_fresh());
        assert!(!l.take_fresh());
        // Ring of 8: five values so far, mean (100+102+98+100-50000)/5 = -9920.
        assert!(l.tare());
        assert_eq!(l.tare_counts(), -9920);
        assert_eq!(l.tared_counts(), Some(-50_000 + 9920));
        assert_eq!(l.silent_for_us(60_000), Some(10_000));
    }
}
