//! The byte pipe under the link: anything that can write bytes and read them with a timeout.
//! The real one is a serial port (USB CDC-ACM on the bench, a PTY for hil-sim); tests use
//! an in-process device (the test kit's `loopback_device`).

use std::io::{Read, Write};
use std::time::Duration;

/// Why the pipe failed. A timeout is not an error: [`Transport::read_timeout`] returns 0.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The device went away (USB unplugged, PTY closed, simulator stopped).
    #[error("{port}: device disconnected ({reason})")]
    Disconnected { port: String, reason: String },
    #[error("{port}: {source}")]
    Io {
        port: String,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot open serial port {port}: {reason}")]
    Open { port: String, reason: String },
}

/// A bidirectional byte pipe to the device.
pub trait Transport: Send {
    /// Writes every byte.
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), TransportError>;
    /// Reads what is available, waiting at most `timeout`; `Ok(0)` means nothing arrived.
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError>;
    /// The port's name, for messages.
    fn name(&self) -> String;
}

/// A serial port (`serialport`'s POSIX `TTYPort`; the baud rate is irrelevant for CDC-ACM
/// and PTYs but is set to 115200 for real UARTs).
#[derive(Debug)]
pub struct SerialTransport {
    port: serialport::TTYPort,
    name: String,
}

impl SerialTransport {
    /// Opens `path` (e.g. `/dev/ttyACM0` or a PTY's slave path).
    pub fn open(path: &str) -> Result<Self, TransportError> {
        let port = serialport::new(path, 115_200)
            .timeout(Duration::from_millis(10))
            .open_native()
            .map_err(|e| TransportError::Open {
                port: path.to_string(),
                reason: e.to_string(),
            })?;
        Ok(Self {
            port,
            name: path.to_string(),
        })
    }

    fn classify(&self, e: std::io::Error) -> TransportError {
        use std::io::ErrorKind as K;
        match e.kind() {
            K::BrokenPipe | K::ConnectionReset | K::ConnectionAborted | K::UnexpectedEof => {
                TransportError::Disconnected {
                    port: self.name.clone(),
                    reason: e.to_string(),
                }
            }
            // EIO is what a PTY master that has gone, or an unplugged CDC-ACM device, gives.
            _ if e.raw_os_error() == Some(5) || e.raw_os_error() == Some(19) => {
                TransportError::Disconnected {
                    port: self.name.clone(),
                    reason: e.to_string(),
                }
            }
            _ => TransportError::Io {
                port: self.name.clone(),
                source: e,
            },
        }
    }
}

impl Transport for SerialTransport {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        self.port
            .write_all(bytes)
            .and_then(|()| self.port.flush())
            .map_err(|e| self.classify(e))
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        use serialport::SerialPort;
        self.port
            .set_timeout(timeout.max(Duration::from_millis(1)))
            .map_err(|e| TransportError::Io {
                port: self.name.clone(),
                source: e.into(),
            })?;
        match self.port.read(buf) {
            Ok(0) => Err(TransportError::Disconnected {
                port: self.name.clone(),
                reason: "end of file".into(),
            }),
            Ok(n) => Ok(n),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(self.classify(e)),
        }
    }

    fn name(&self) -> String {
        self.name.clone()
    }
}
