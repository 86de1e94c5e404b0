//! Camera frames and the sources that produce them: a V4L2 (UVC) camera, recordings (a
//! directory of PNG/PGM frames, a raw MJPEG stream file) and in-memory producers such as
//! hil-sim's renderer (through [`ChannelSource`]).

pub mod channel;
pub mod frame;
pub mod frame_dir;
pub mod image_file;
pub mod jpeg_encode;
pub mod mjpeg_file;
pub mod source;
pub mod v4l2;

pub use channel::{ChannelSource, channel_source};
pub use frame::{Frame, FrameError, PixelFormat};
pub use frame_dir::FrameDirSource;
pub use image_file::{read_gray_image, write_pgm, write_png};
pub use jpeg_encode::encode_gray_jpeg;
pub use mjpeg_file::MjpegFileSource;
pub use source::{CameraError, FrameSource};
pub use v4l2::{V4l2Config, V4l2Source};
pub use vision::GrayImage;
