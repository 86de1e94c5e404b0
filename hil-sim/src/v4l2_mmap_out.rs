//! Memory-mapped V4L2 video *output* streaming (`VIDIOC_REQBUFS`, `QUERYBUF`, `QBUF`,
//! `DQBUF`, `STREAMON`) on a device whose format is already set.
//!
//! Why this exists: `write()` on a videobuf2 output queue loses the frame's payload size on
//! the kernels this runs on (Debian 12's 6.1: vivid refuses every written frame with
//! "payload is too small ... 0 < size"), and the `linuxvideo` crate's output stream requests
//! capture buffers and never starts streaming. So the five ioctls and the buffer mappings
//! are done here, against the structure layouts of `<linux/videodev2.h>` on 64-bit Linux.
//! This module is the only place in the host workspace that needs `unsafe`: each block
//! states what it relies on.
#![allow(unsafe_code)]

use std::io;
use std::os::fd::{AsRawFd, RawFd};

/// `V4L2_BUF_TYPE_VIDEO_OUTPUT`.
const BUF_TYPE_VIDEO_OUTPUT: u32 = 2;
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

/// An output queue streaming from memory-mapped driver buffers. The file descriptor must
/// stay open for its lifetime (the owner keeps the device).
#[derive(Debug)]
pub struct MmapOutput {
    fd: RawFd,
    buffers: Vec<Mapped>,
    /// Buffers never queued yet, used before any is dequeued.
    fresh: std::ops::Range<usize>,
    streaming: bool,
}

// SAFETY: the mappings are owned by this value alone (no aliases are handed out beyond a
// call), so moving it to another thread is sound.
unsafe impl Send for MmapOutput {}

impl MmapOutput {
    /// Requests `count` buffers on `device` (format already negotiated) and maps them.
    pub fn new(device: &impl AsRawFd, count: u32) -> io::Result<Self> {
        let fd = device.as_raw_fd();
        let mut req = RequestBuffers {
            count,
            type_: BUF_TYPE_VIDEO_OUTPUT,
            memory: MEMORY_MMAP,
            ..RequestBuffers::default()
        };
        ioctl(fd, VIDIOC_REQBUFS, &mut req)?;
        if req.count == 0 {
            return Err(io::Error::other("the driver granted no output buffers"));
        }
        let mut out = Self {
            fd,
            buffers: Vec::new(),
            fresh: 0..req.count as usize,
            streaming: false,
        };
        for index in 0..req.count {
            let mut buf = Buffer {
                index,
                type_: BUF_TYPE_VIDEO_OUTPUT,
                memory: MEMORY_MMAP,
                ..Buffer::default()
            };
            ioctl(fd, VIDIOC_QUERYBUF, &mut buf)?;
            let len = buf.length as usize;
            // SAFETY: maps `len` bytes of the driver's buffer at the offset QUERYBUF gave
            // for it; a failure is checked below, a success is unmapped in `Drop`.
            let ptr = unsafe {
                libc::mmap(
                    std::ptr::null_mut(),
                    len,
                    libc::PROT_READ | libc::PROT_WRITE,
                    libc::MAP_SHARED,
                    fd,
                    libc::off_t::from(buf.m_offset),
                )
            };
            if ptr == libc::MAP_FAILED {
                return Err(io::Error::last_os_error());
            }
            out.buffers.push(Mapped {
                ptr: ptr.cast::<u8>(),
                len,
            });
        }
        Ok(out)
    }

    /// Queues one frame of `bytes` (at most a buffer's length); blocks until the driver
    /// returns a buffer when all are queued. Starts streaming with the first frame.
    pub fn queue(&mut self, bytes: &[u8]) -> io::Result<()> {
        let index = match self.fresh.next() {
            Some(i) => i,
            None => {
                let mut buf = Buffer {
                    type_: BUF_TYPE_VIDEO_OUTPUT,
                    memory: MEMORY_MMAP,
                    ..Buffer::default()
                };
                ioctl(self.fd, VIDIOC_DQBUF, &mut buf)?;
                buf.index as usize
            }
        };
        let mapped = self
            .buffers
            .get(index)
            .ok_or_else(|| io::Error::other(format!("the driver returned buffer {index}")))?;
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
        let mut buf = Buffer {
            index: index as u32,
            type_: BUF_TYPE_VIDEO_OUTPUT,
            memory: MEMORY_MMAP,
            bytesused: bytes.len() as u32,
            field: FIELD_NONE,
            ..Buffer::default()
        };
        ioctl(self.fd, VIDIOC_QBUF, &mut buf)?;
        if !self.streaming {
            let mut kind = BUF_TYPE_VIDEO_OUTPUT as libc::c_int;
            ioctl(self.fd, VIDIOC_STREAMON, &mut kind)?;
            self.streaming = true;
        }
        Ok(())
    }
}

impl Drop for MmapOutput {
    fn drop(&mut self) {
        if self.streaming {
            let mut kind = BUF_TYPE_VIDEO_OUTPUT as libc::c_int;
            let _ = ioctl(self.fd, VIDIOC_STREAMOFF, &mut kind);
        }
        for m in &self.buffers {
            // SAFETY: unmaps exactly what `new` mapped; no slice into it outlives `queue`.
            unsafe {
                libc::munmap(m.ptr.cast::<libc::c_void>(), m.len);
            }
        }
    }
}
