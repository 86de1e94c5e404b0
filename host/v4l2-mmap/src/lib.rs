//! Memory-mapped V4L2 streaming (`VIDIOC_REQBUFS`, `QUERYBUF`, `QBUF`, `DQBUF`,
//! `STREAMON`, `STREAMOFF`) on a device whose format is already negotiated, for both
//! directions:
//!
//! - [`MmapCapture`]: frames from a camera with what the driver says about each one: its
//!   `CLOCK_MONOTONIC` timestamp (for UVC the start of the frame's arrival, or the
//!   camera's own clock translated by the driver), its sequence number (gaps are frames the
//!   driver dropped) and its error flag. The `linuxvideo` crate's stream hands out the
//!   bytes only, so a frame could only be stamped when the program got round to dequeuing
//!   it: late by however many frames were waiting.
//! - [`MmapOutput`]: frames to a video output (vivid's loop, v4l2loopback). `write()` on a
//!   videobuf2 output queue loses the frame's payload size on the kernels this runs on
//!   (Debian 12's 6.1: vivid refuses every written frame with "payload is too small ... 0 <
//!   size"), and `linuxvideo`'s output stream requests capture buffers and never starts
//!   streaming.
//!
//! The structure layouts are those of `<linux/videodev2.h>` on 64-bit Linux. This crate is
//! the only place in the host workspace that needs `unsafe`: each block states what it
//! relies on.
#![allow(unsafe_code)]

use std::io;
use std::os::fd::{AsRawFd, RawFd};

/// `V4L2_BUF_TYPE_VIDEO_CAPTURE`.
const BUF_TYPE_VIDEO_CAPTURE: u32 = 1;
/// `V4L2_BUF_TYPE_VIDEO_OUTPUT`.
const BUF_TYPE_VIDEO_OUTPUT: u32 = 2;
/// `V4L2_BUF_FLAG_ERROR`: the driver filled the buffer but its data may be corrupt.
const BUF_FLAG_ERROR: u32 = 0x0040;
/// `V4L2_BUF_FLAG_TIMESTAMP_MASK` and its `MONOTONIC` value.
const BUF_FLAG_TIMESTAMP_MASK: u32 = 0xe000;
const BUF_FLAG_TIMESTAMP_MONOTONIC: u32 = 0x2000;
/// `V4L2_MEMORY_MMAP`.
const MEMORY_MMAP: u32 = 1;
/// `V4L2_FIELD_NONE` (progressive frames).
const FIELD_NONE: u32 = 1;

/// `struct v4l2_requestbuffers` (20 bytes).
#[repr(C)]
#[derive(Debug, Default)]
struct RequestBuffers {
    count: u32,
    type_: u32,
    memory: u32,
    capabilities: u32,
    flags: u8,
    reserved: [u8; 3],
}

/// `struct v4l2_timecode` (16 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy)]
struct Timecode {
    type_: u32,
    flags: u32,
    frames: u8,
    seconds: u8,
    minutes: u8,
    hours: u8,
    userbits: [u8; 4],
}

/// `struct v4l2_buffer` on 64-bit Linux (88 bytes); the `m` union is read as the mmap
/// offset (its first 4 bytes) and kept 8 bytes wide for the pointer members.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy)]
struct Buffer {
    index: u32,
    type_: u32,
    bytesused: u32,
    flags: u32,
    field: u32,
    /// `struct timeval` (64-bit seconds and microseconds), after 4 bytes of padding.
    padding: u32,
    timestamp_s: i64,
    timestamp_us: i64,
    timecode: Timecode,
    sequence: u32,
    memory: u32,
    m_offset: u32,
    m_high: u32,
    length: u32,
    reserved2: u32,
    request_fd: i32,
}

const _: () = assert!(size_of::<RequestBuffers>() == 20);
const _: () = assert!(size_of::<Buffer>() == 88);

/// `_IOC(dir, 'V', nr, size)`.
const fn ioc(dir: u64, nr: u64, size: usize) -> u64 {
    (dir << 30) | ((size as u64) << 16) | ((b'V' as u64) << 8) | nr
}
const READ_WRITE: u64 = 3;
const WRITE: u64 = 1;
const VIDIOC_REQBUFS: u64 = ioc(READ_WRITE, 8, size_of::<RequestBuffers>());
const VIDIOC_QUERYBUF: u64 = ioc(READ_WRITE, 9, size_of::<Buffer>());
const VIDIOC_QBUF: u64 = ioc(READ_WRITE, 15, size_of::<Buffer>());
const VIDIOC_DQBUF: u64 = ioc(READ_WRITE, 17, size_of::<Buffer>());
const VIDIOC_STREAMON: u64 = ioc(WRITE, 18, size_of::<libc::c_int>());
const VIDIOC_STREAMOFF: u64 = ioc(WRITE, 19, size_of::<libc::c_int>());

/// `ioctl(fd, request, arg)`, retried on EINTR.
fn ioctl<T>(fd: RawFd, request: u64, arg: &mut T) -> io::Result<()> {
    loop {
        // SAFETY: `arg` is a live, exclusively borrowed value of the structure type that
        // `request` encodes (the size is part of the request number), so the kernel reads
        // and writes only inside it.
        let r = unsafe { libc::ioctl(fd, request as libc::Ioctl, arg as *mut T) };
        if r >= 0 {
            return Ok(());
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

/// One driver buffer mapped into this process.
#[derive(Debug)]
struct Mapped {
    ptr: *mut u8,
    len: usize,
}

/// The buffers of one queue (capture or output), mapped; streaming stopped and the
/// mappings released on drop. The file descriptor must stay open for its lifetime (the
/// owner keeps the device).
#[derive(Debug)]
struct MmapQueue {
    fd: RawFd,
    type_: u32,
    buffers: Vec<Mapped>,
    streaming: bool,
}

// SAFETY: the mappings are owned by this value alone (no aliases are handed out beyond a
// call), so moving it to another thread is sound.
unsafe impl Send for MmapQueue {}

impl MmapQueue {
    /// Requests `count` buffers of `type_` on `fd` and maps them.
    fn new(fd: RawFd, type_: u32, count: u32, prot: libc::c_int) -> io::Result<Self> {
        let mut req = RequestBuffers {
            count,
            type_,
            memory: MEMORY_MMAP,
            ..RequestBuffers::default()
        };
        ioctl(fd, VIDIOC_REQBUFS, &mut req)?;
        if req.count == 0 {
            return Err(io::Error::other("the driver granted no buffers"));
        }
        let mut queue = Self {
            fd,
            type_,
            buffers: Vec::new(),
            streaming: false,
        };
        for index in 0..req.count {
            let mut buf = queue.buffer(index);
            ioctl(fd, VIDIOC_QUERYBUF, &mut buf)?;
            let len = buf.length as usize;
            // SAFETY: maps `len` bytes of the driver's buffer at the offset QUERYBUF gave
            // for it; a failure is checked below, a success is unmapped in `Drop`.
            let ptr = unsafe {
                libc::mmap(
                    std::ptr::null_mut(),
                    len,
                    prot,
                    libc::MAP_SHARED,
                    fd,
                    libc::off_t::from(buf.m_offset),
                )
            };
            if ptr == libc::MAP_FAILED {
                return Err(io::Error::last_os_error());
            }
            queue.buffers.push(Mapped {
                ptr: ptr.cast::<u8>(),
                len,
            });
        }
        Ok(queue)
    }

    fn buffer(&self, index: u32) -> Buffer {
        Buffer {
            index,
            type_: self.type_,
            memory: MEMORY_MMAP,
            ..Buffer::default()
        }
    }

    fn enqueue(&self, mut buf: Buffer) -> io::Result<()> {
        ioctl(self.fd, VIDIOC_QBUF, &mut buf)
    }

    /// The next buffer the driver is done with (blocks unless the device is non-blocking).
    fn dequeue(&self) -> io::Result<(Buffer, &Mapped)> {
        let mut buf = self.buffer(0);
        ioctl(self.fd, VIDIOC_DQBUF, &mut buf)?;
        let mapped = self
            .buffers
            .get(buf.index as usize)
            .ok_or_else(|| io::Error::other(format!("the driver returned buffer {}", buf.index)))?;
        Ok((buf, mapped))
    }

    fn stream_on(&mut self) -> io::Result<()> {
        let mut kind = self.type_ as libc::c_int;
        ioctl(self.fd, VIDIOC_STREAMON, &mut kind)?;
        self.streaming = true;
        Ok(())
    }
}

impl Drop for MmapQueue {
    fn drop(&mut self) {
        if self.streaming {
            let mut kind = self.type_ as libc::c_int;
            let _ = ioctl(self.fd, VIDIOC_STREAMOFF, &mut kind);
        }
        for m in &self.buffers {
            // SAFETY: unmaps exactly what `new` mapped; no slice into it outlives a call.
            unsafe {
                libc::munmap(m.ptr.cast::<libc::c_void>(), m.len);
            }
        }
    }
}

/// What the driver says about a captured frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameInfo {
    /// The driver's frame counter (a gap is frames it dropped).
    pub sequence: u32,
    /// The driver's timestamp on `CLOCK_MONOTONIC` in microseconds, if the driver stamps
    /// on that clock (`V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC`); `None` for other clocks.
    pub monotonic_us: Option<i128>,
    /// The driver flagged the data as possibly corrupt (`V4L2_BUF_FLAG_ERROR`).
    pub error: bool,
}

/// A capture queue streaming into memory-mapped driver buffers.
#[derive(Debug)]
pub struct MmapCapture {
    queue: MmapQueue,
}

impl MmapCapture {
    /// Requests `count` buffers on `device` (format already negotiated), maps them, queues
    /// them all and starts streaming.
    pub fn start(device: &impl AsRawFd, count: u32) -> io::Result<Self> {
        let mut queue = MmapQueue::new(
            device.as_raw_fd(),
            BUF_TYPE_VIDEO_CAPTURE,
            count,
            libc::PROT_READ,
        )?;
        for index in 0..queue.buffers.len() as u32 {
            queue.enqueue(queue.buffer(index))?;
        }
        queue.stream_on()?;
        Ok(Self { queue })
    }

    /// Waits for the next frame and hands its bytes (`bytesused` of them) and what the
    /// driver says about it to `read`, then gives the buffer back to the driver.
    pub fn next<T>(&mut self, read: impl FnOnce(&[u8], FrameInfo) -> T) -> io::Result<T> {
        let (buf, mapped) = self.queue.dequeue()?;
        let used = (buf.bytesused as usize).min(mapped.len);
        let monotonic = buf.flags & BUF_FLAG_TIMESTAMP_MASK == BUF_FLAG_TIMESTAMP_MONOTONIC;
        let info = FrameInfo {
            sequence: buf.sequence,
            monotonic_us: monotonic
                .then(|| i128::from(buf.timestamp_s) * 1_000_000 + i128::from(buf.timestamp_us)),
            error: buf.flags & BUF_FLAG_ERROR != 0,
        };
        // SAFETY: the buffer is dequeued (the driver does not write it until QBUF, below,
        // after `read` returned) and mapped with `mapped.len >= used` readable bytes.
        let data = unsafe { std::slice::from_raw_parts(mapped.ptr, used) };
        let out = read(data, info);
        self.queue.enqueue(self.queue.buffer(buf.index))?;
        Ok(out)
    }
}

/// An output queue streaming from memory-mapped driver buffers.
#[derive(Debug)]
pub struct MmapOutput {
    queue: MmapQueue,
    /// Buffers never queued yet, used before any is dequeued.
    fresh: std::ops::Range<usize>,
}

impl MmapOutput {
    /// Requests `count` buffers on `device` (format already negotiated) and maps them.
    pub fn new(device: &impl AsRawFd, count: u32) -> io::Result<Self> {
        let queue = MmapQueue::new(
            device.as_raw_fd(),
            BUF_TYPE_VIDEO_OUTPUT,
            count,
            libc::PROT_READ | libc::PROT_WRITE,
        )?;
        let fresh = 0..queue.buffers.len();
        Ok(Self { queue, fresh })
    }

    /// Queues one frame of `bytes` (at most a buffer's length); blocks until the driver
    /// returns a buffer when all are queued. Starts streaming with the first frame.
    pub fn queue(&mut self, bytes: &[u8]) -> io::Result<()> {
        let (index, mapped) = match self.fresh.next() {
            Some(i) => (i as u32, &self.queue.buffers[i]),
            None => {
                let (buf, mapped) = self.queue.dequeue()?;
                (buf.index, mapped)
            }
        };
        if bytes.len() > mapped.len {
            return Err(io::Error::other(format!(
                "frame of {} bytes, buffer of {}",
                bytes.len(),
                mapped.len
            )));
        }
        // SAFETY: the buffer is dequeued (the driver does not touch it until QBUF) and
        // mapped with `mapped.len >= bytes.len()` writable bytes.
        let dst = unsafe { std::slice::from_raw_parts_mut(mapped.ptr, bytes.len()) };
        dst.copy_from_slice(bytes);
        let mut buf = self.queue.buffer(index);
        buf.bytesused = bytes.len() as u32;
        buf.field = FIELD_NONE;
        self.queue.enqueue(buf)?;
        if !self.queue.streaming {
            self.queue.stream_on()?;
        }
        Ok(())
    }
}

/// The current `CLOCK_MONOTONIC` reading in microseconds (the clock of the drivers'
/// buffer timestamps; `std::time::Instant` reads it too but does not expose its value).
pub fn monotonic_now_us() -> i128 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a live timespec the call writes; CLOCK_MONOTONIC always exists.
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    i128::from(ts.tv_sec) * 1_000_000 + i128::from(ts.tv_nsec) / 1000
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_clock_moves_with_instant() {
        // Both read CLOCK_MONOTONIC: 20 ms of sleep is 20 ms on both, give or take the
        // scheduling between the reads (bounded above by a generous 1 s on a busy machine).
        let (m0, i0) = (monotonic_now_us(), std::time::Instant::now());
        std::thread::sleep(std::time::Duration::from_millis(20));
        let (m1, i1) = (monotonic_now_us(), std::time::Instant::now());
        let dm = m1 - m0;
        let di = i1.duration_since(i0).as_micros() as i128;
        assert!((20_000..1_000_000).contains(&dm), "{dm} us");
        assert!(
            (dm - di).abs() < 1_000,
            "monotonic {dm} us, Instant {di} us"
        );
    }
}
