//! Device discovery for `tactile devices`: serial ports (with USB VID/PID/serial where the
//! port is a USB CDC device; `serialport` reads them from sysfs without libudev) and USB
//! devices that are ours or an RP2040 in BOOTSEL mode, via `rusb::Context::new()`.

use super::{RP2040_BOOTROM_PID, RP2040_BOOTROM_VID, TACTILE_USB_PID, TACTILE_USB_VID};
use rusb::UsbContext;

#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct SerialPortEntry {
    pub port: String,
    /// "usb", "pci", "bluetooth" or "unknown".
    pub kind: String,
    pub vid: Option<u16>,
    pub pid: Option<u16>,
    pub serial_number: Option<String>,
    pub product: Option<String>,
    /// True when VID:PID is our controller's.
    pub ours: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum UsbRole {
    /// Our controller running its firmware (1209:7AC7).
    Controller,
    /// An RP2040 boot ROM in BOOTSEL mode (2e8a:0003), ready for flashing.
    Rp2040Bootrom,
}

#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct UsbEntry {
    pub bus: u8,
    pub address: u8,
    pub vid: u16,
    pub pid: u16,
    pub role: UsbRole,
    /// Read when the device can be opened (permissions allowing).
    pub serial_number: Option<String>,
}

#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct DeviceReport {
    pub serial_ports: Vec<SerialPortEntry>,
    pub usb: Vec<UsbEntry>,
    /// Why USB devices could not be listed (no usbfs, permissions), if so.
    pub usb_note: Option<String>,
    pub serial_note: Option<String>,
}

/// Classifies a VID:PID.
pub fn usb_role(vid: u16, pid: u16) -> Option<UsbRole> {
    match (vid, pid) {
        (TACTILE_USB_VID, TACTILE_USB_PID) => Some(UsbRole::Controller),
        (RP2040_BOOTROM_VID, RP2040_BOOTROM_PID) => Some(UsbRole::Rp2040Bootrom),
        _ => None,
    }
}

/// The operating system's serial-port enumeration failed.
#[derive(Debug, thiserror::Error)]
#[error("listing serial ports: {0}")]
pub struct SerialListError(#[from] serialport::Error);

pub fn list_serial_ports() -> Result<Vec<SerialPortEntry>, SerialListError> {
    let ports = serialport::available_ports()?;
    Ok(ports
        .into_iter()
        .map(|p| match p.port_type {
            serialport::SerialPortType::UsbPort(u) => SerialPortEntry {
                port: p.port_name,
                kind: "usb".to_string(),
                vid: Some(u.vid),
                pid: Some(u.pid),
                serial_number: u.serial_number,
                product: u.product,
                ours: usb_role(u.vid, u.pid) == Some(UsbRole::Controller),
            },
            other => SerialPortEntry {
                port: p.port_name,
                kind: match other {
                    serialport::SerialPortType::PciPort => "pci",
                    serialport::SerialPortType::BluetoothPort => "bluetooth",
                    _ => "unknown",
                }
                .to_string(),
                vid: None,
                pid: None,
                serial_number: None,
                product: None,
                ours: false,
            },
        })
        .collect())
}

/// What to check when libusb cannot start: it needs the usbfs device nodes.
pub fn usb_access_hint() -> &'static str {
    if !std::path::Path::new("/dev/bus/usb").exists() {
        "/dev/bus/usb does not exist (no usbfs: inside a container, pass the USB devices through, e.g. --device /dev/bus/usb)"
    } else {
        "/dev/bus/usb is there but could not be used: check its permissions (a udev rule for VID 1209 and 2E8A, or the plugdev group)"
    }
}

/// Our devices and RP2040 boot ROMs on the USB; `Err` with a note when USB is not
/// accessible (no usbfs in a container, no permissions).
pub fn list_usb_devices() -> Result<Vec<UsbEntry>, String> {
    let ctx =
        rusb::Context::new().map_err(|e| format!("no USB access ({e}): {}", usb_access_hint()))?;
    let devices = ctx
        .devices()
        .map_err(|e| format!("no USB access: cannot list devices: {e}"))?;
    let mut out = Vec::new();
    for device in devices.iter() {
        let Ok(desc) = device.device_descriptor() else {
            continue;
        };
        let Some(role) = usb_role(desc.vendor_id(), desc.product_id()) else {
            continue;
        };
        let serial_number = device
            .open()
            .ok()
            .and_then(|h| h.read_serial_number_string_ascii(&desc).ok());
        out.push(UsbEntry {
            bus: device.bus_number(),
            address: device.address(),
            vid: desc.vendor_id(),
            pid: desc.product_id(),
            role,
            serial_number,
        });
    }
    Ok(out)
}

pub fn discover() -> DeviceReport {
    let (serial_ports, serial_note) = match list_serial_ports() {
        Ok(p) => (p, None),
        Err(e) => (Vec::new(), Some(e.to_string())),
    };
    let (usb, usb_note) = match list_usb_devices() {
        Ok(u) => (u, None),
        Err(e) => (Vec::new(), Some(e)),
    };
    DeviceReport {
        serial_ports,
        usb,
        usb_note,
        serial_note,
    }
}
