//! PICOBOOT over rusb: finds the RP2040 boot ROM (2e8a:0003), claims its vendor-class
//! interface and bulk endpoints. Always through `rusb::Context::new()`: the global-context
//! functions panic where usbfs is absent.

use super::picoboot::{PicobootError, PicobootTransport};
use super::{RP2040_BOOTROM_PID, RP2040_BOOTROM_VID};
use rusb::UsbContext;
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_secs(5);

#[derive(Debug)]
pub struct RusbPicoboot {
    handle: rusb::DeviceHandle<rusb::Context>,
    interface: u8,
    ep_in: u8,
    ep_out: u8,
}

fn usb(e: rusb::Error) -> PicobootError {
    PicobootError::Usb(e.to_string())
}

impl RusbPicoboot {
    /// Opens the first RP2040 in BOOTSEL mode; `Ok(None)` if there is none.
    pub fn open_first() -> Result<Option<Self>, PicobootError> {
        let ctx = rusb::Context::new().map_err(|e| {
            PicobootError::Usb(format!(
                "no USB access ({e}): {}",
                crate::discovery::usb_access_hint()
            ))
        })?;
        for device in ctx.devices().map_err(usb)?.iter() {
            let Ok(desc) = device.device_descriptor() else {
                continue;
            };
            if desc.vendor_id() != RP2040_BOOTROM_VID || desc.product_id() != RP2040_BOOTROM_PID {
                continue;
            }
            let config = device.active_config_descriptor().map_err(usb)?;
            let mut found = None;
            for iface in config.interfaces() {
                for alt in iface.descriptors() {
                    if alt.class_code() != 0xFF {
                        continue;
                    }
                    let mut ep_in = None;
                    let mut ep_out = None;
                    for ep in alt.endpoint_descriptors() {
                        if ep.transfer_type() != rusb::TransferType::Bulk {
                            continue;
                        }
                        match ep.direction() {
                            rusb::Direction::In => ep_in = Some(ep.address()),
                            rusb::Direction::Out => ep_out = Some(ep.address()),
                        }
                    }
                    if let (Some(i), Some(o)) = (ep_in, ep_out) {
                        found = Some((alt.interface_number(), i, o));
                    }
                }
            }
            let Some((interface, ep_in, ep_out)) = found else {
                return Err(PicobootError::Usb(
                    "RP2040 boot ROM has no PICOBOOT interface (disabled by OTP/config?)"
                        .to_string(),
                ));
            };
            let handle = device.open().map_err(usb)?;
            // Not supported on every platform; claiming still works where a driver is absent.
            let _ = handle.set_auto_detach_kernel_driver(true);
            handle.claim_interface(interface).map_err(usb)?;
            return Ok(Some(Self {
                handle,
                interface,
                ep_in,
                ep_out,
            }));
        }
        Ok(None)
    }
}

impl PicobootTransport for RusbPicoboot {
    fn bulk_out(&mut self, data: &[u8]) -> Result<usize, PicobootError> {
        self.handle
            .write_bulk(self.ep_out, data, TIMEOUT)
            .map_err(usb)
    }

    fn bulk_in(&mut self, len: usize) -> Result<Vec<u8>, PicobootError> {
        // A zero-length acknowledgement still needs a buffer of one packet.
        let mut buf = vec![0u8; len.max(64)];
        let n = self
            .handle
            .read_bulk(self.ep_in, &mut buf, TIMEOUT)
            .map_err(usb)?;
        buf.truncate(n.min(len.max(n)));
        Ok(buf)
    }

    fn control_out(
        &mut self,
        request_type: u8,
        request: u8,
        data: &[u8],
    ) -> Result<(), PicobootError> {
        self.handle
            .write_control(
                request_type,
                request,
                0,
                u16::from(self.interface),
                data,
                TIMEOUT,
            )
            .map(drop)
            .map_err(usb)
    }

    fn control_in(
        &mut self,
        request_type: u8,
        request: u8,
        len: usize,
    ) -> Result<Vec<u8>, PicobootError> {
        let mut buf = vec![0u8; len];
        let n = self
            .handle
            .read_control(
                request_type,
                request,
                0,
                u16::from(self.interface),
                &mut buf,
                TIMEOUT,
            )
            .map_err(usb)?;
        buf.truncate(n);
        Ok(buf)
    }
}
