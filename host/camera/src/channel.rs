//! An in-memory frame source fed through a channel: how a simulator (hil-sim's camera
//! renderer) or any other producer thread delivers frames without a device or a file.
//!
//! ```
//! use camera::{channel_source, Frame, FrameSource, GrayImage};
//! let (tx, mut source) = channel_source(4);
//! let image = GrayImage::new(2, 1, vec![10, 20]).unwrap();
//! tx.send(Frame::from_gray(image, 0, 0)).unwrap();
//! drop(tx); // producer hangs up: the stream ends after the queued frames
//! assert_eq!(source.next_frame().unwrap().unwrap().data, vec![10, 20]);
//! assert!(source.next_frame().unwrap().is_none());
//! ```

use super::frame::Frame;
use super::source::{CameraError, FrameSource};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, sync_channel};
use std::time::Duration;

/// Receiving end; the stream ends (`Ok(None)`) when every sender is dropped.
#[derive(Debug)]
pub struct ChannelSource {
    rx: Receiver<Frame>,
    timeout: Option<Duration>,
}

/// A bounded channel (`capacity` frames; a producer faster than the consumer blocks, as a
/// camera's buffer queue would fill) and the source reading it.
pub fn channel_source(capacity: usize) -> (SyncSender<Frame>, ChannelSource) {
    let (tx, rx) = sync_channel(capacity);
    (tx, ChannelSource { rx, timeout: None })
}

impl ChannelSource {
    /// Makes `next_frame` fail with [`CameraError::Timeout`] when no frame arrives in time.
    pub fn with_timeout(mut self, timeout: Duration) -> Self {
        self.timeout = Some(timeout);
        self
    }
}

impl FrameSource for ChannelSource {
    fn next_frame(&mut self) -> Result<Option<Frame>, CameraError> {
        match self.timeout {
            None => Ok(self.rx.recv().ok()),
            Some(t) => match self.rx.recv_timeout(t) {
                Ok(f) => Ok(Some(f)),
                Err(RecvTimeoutError::Disconnected) => Ok(None),
                Err(RecvTimeoutError::Timeout) => Err(CameraError::Timeout {
                    timeout_ms: u64::try_from(t.as_millis()).unwrap_or(u64::MAX),
                }),
            },
        }
    }

    fn describe(&self) -> String {
        "in-memory channel".to_string()
    }
}
