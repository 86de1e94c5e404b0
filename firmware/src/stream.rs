//! Sample streaming: samples at a host-chosen rate (1..=2000 Hz) with a host-chosen channel
//! set, packed into [`SampleBlock`]s of up to [`MAX_SAMPLES_PER_BLOCK`] samples.
//!
//! - Timing: sample k is due at `start + ceil(k * 1e6 / rate)` µs and is taken at the first
//!   tick at or after that instant, so the long-run rate is exact and the jitter is below one
//!   tick; ticks that were missed are skipped, not replayed. The controller must be ticked
//!   at least as fast as the stream rate (it is ticked at 2 kHz).
//! - Each sample's ADC channels are the mean of the ticks since the previous sample (see
//!   [`ReadingAverager`]); the load is the latest conversion (minus the tare) with
//!   `LOAD_FRESH` set when a new one arrived since the previous sample, and `None` before
//!   the first conversion even when the channel is selected (no load cell fitted).
//! - A block is closed when it holds [`MAX_SAMPLES_PER_BLOCK`] samples or its first sample
//!   is [`MAX_BLOCK_LATENCY_US`] old (so slow streams still arrive promptly), and on
//!   `StopStream`. `block_seq` starts at 0 with each `StartStream` and increments for every
//!   block closed, including blocks dropped because the outgoing queue was full: the host
//!   sees the gap, and the next sample carries `OVERRUN`.

use heapless::Deque;
use protocol::{ChannelSet, MAX_SAMPLES_PER_BLOCK, Sample, SampleBlock, StatusFlags};

use crate::sampling::ReadingAverager;

/// Longest a sample waits in a partly filled block.
pub const MAX_BLOCK_LATENCY_US: u64 = 20_000;
/// Closed blocks waiting for the link (32 ms of data at 2 kHz).
pub const OUTGOING_BLOCKS: usize = 8;

/// What the controller measured and decided on one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickSample {
    pub proximity_counts: u16,
    pub manometer_counts: u16,
    /// Latest load conversion minus tare (`None` before the first conversion).
    pub load_counts: Option<i32>,
    /// A new conversion arrived this tick.
    pub load_fresh: bool,
    pub pump_duty_per_10k: u16,
    pub stage_steps: i32,
    pub status: StatusFlags,
}

/// The sample stream.
#[derive(Debug)]
pub struct Streamer {
    active: bool,
    rate_hz: u32,
    channels: ChannelSet,
    start_us: u64,
    next_index: u64,
    next_due_us: u64,
    proximity: ReadingAverager,
    manometer: ReadingAverager,
    load_fresh: bool,
    block: SampleBlock,
    block_started_us: u64,
    block_seq: u32,
    queue: Deque<SampleBlock, OUTGOING_BLOCKS>,
    overruns: u32,
    overrun_pending: bool,
}

impl Default for Streamer {
    fn default() -> Self {
        Self::new()
    }
}

impl Streamer {
    pub const fn new() -> Self {
        Self {
            active: false,
            rate_hz: 0,
            channels: ChannelSet(0),
            start_us: 0,
            next_index: 0,
            next_due_us: 0,
            proximity: ReadingAverager::new(),
            manometer: ReadingAverager::new(),
            load_fresh: false,
            block: SampleBlock {
                block_seq: 0,
                samples: heapless::Vec::new(),
            },
            block_started_us: 0,
            block_seq: 0,
            queue: Deque::new(),
            overruns: 0,
            overrun_pending: false,
        }
    }

    pub fn is_active(&self) -> bool {
        self.active
    }

    pub fn rate_hz(&self) -> u32 {
        self.rate_hz
    }

    pub fn channels(&self) -> ChannelSet {
        self.channels
    }

    /// Blocks dropped because the outgoing queue was full, since boot.
    pub fn overruns(&self) -> u32 {
        self.overruns
    }

    /// Starts (or restarts) the stream; the caller has validated rate and channels. A block
    /// in progress from a previous stream is closed first.
    pub fn start(&mut self, rate_hz: u16, channels: ChannelSet, now_us: u64) {
        self.close_block();
        self.active = true;
        self.rate_hz = u32::from(rate_hz.max(1));
        self.channels = channels;
        self.start_us = now_us;
        self.next_index = 0;
        self.next_due_us = now_us;
        self.proximity = ReadingAverager::new();
        self.manometer = ReadingAverager::new();
        self.load_fresh = false;
        self.block_seq = 0;
    }

    /// Stops the stream, closing the block in progress.
    pub fn stop(&mut self) {
        self.close_block();
        self.active = false;
    }

    /// Feeds one tick; takes a sample when one is due.
    pub fn on_tick(&mut self, now_us: u64, tick: &TickSample) {
        if !self.active {
            return;
        }
        self.proximity.add(tick.proximity_counts);
        self.manometer.add(tick.manometer_counts);
        self.load_fresh |= tick.load_fresh;
        if !self.block.samples.is_empty()
            && now_us.saturating_sub(self.block_started_us) >= MAX_BLOCK_LATENCY_US
        {
            self.close_block();
        }
        if now_us >= self.next_due_us {
            self.take_sample(now_us, tick);
            // Next due instant after `now_us` on the exact grid start + k/rate.
            let elapsed = now_us.saturating_sub(self.start_us);
            let rate = u64::from(self.rate_hz);
            self.next_index = (self.next_index + 1).max(elapsed * rate / 1_000_000 + 1);
            self.next_due_us = self.start_us + (self.next_index * 1_000_000).div_ceil(rate);
        }
    }

    fn take_sample(&mut self, now_us: u64, tick: &TickSample) {
        let c = self.channels;
        let proximity = self.proximity.take();
        let manometer = self.manometer.take();
        let mut status = tick.status;
        if core::mem::take(&mut self.load_fresh) {
            status.0 |= StatusFlags::LOAD_FRESH;
        }
        if core::mem::take(&mut self.overrun_pending) {
            status.0 |= StatusFlags::OVERRUN;
        }
        let sample = Sample {
            device_time_us: now_us,
            proximity_counts: proximity.filter(|_| c.contains(ChannelSet::PROXIMITY)),
            manometer_counts: manometer.filter(|_| c.contains(ChannelSet::MANOMETER)),
            load_counts: tick.load_counts.filter(|_| c.contains(ChannelSet::LOAD)),
            pump_duty_per_10k: Some(tick.pump_duty_per_10k)
                .filter(|_| c.contains(ChannelSet::PUMP_DUTY)),
            stage_steps: Some(tick.stage_steps).filter(|_| c.contains(ChannelSet::STAGE)),
            status,
        };
        if self.block.samples.is_empty() {
            self.block_started_us = now_us;
        }
        // The block is closed as soon as it is full, so there is always room here.
        let _ = self.block.samples.push(sample);
        if self.block.samples.len() == MAX_SAMPLES_PER_BLOCK {
            self.close_block();
        }
    }

    fn close_block(&mut self) {
        if self.block.samples.is_empty() {
            return;
        }
        let mut block = core::mem::take(&mut self.block);
        block.block_seq = self.block_seq;
        self.block_seq = self.block_seq.wrapping_add(1);
        if self.queue.push_back(block).is_err() {
            self.overruns = self.overruns.saturating_add(1);
            self.overrun_pending = true;
        }
    }

    /// The oldest closed block, if any.
    pub fn pop(&mut self) -> Option<SampleBlock> {
        self.queue.pop_front()
    }

    /// Closed blocks waiting.
    pub fn queued(&self) -> usize {
        self.queue.len()
    }
}
