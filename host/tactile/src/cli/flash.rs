//! `tactile flash FIRMWARE [--uf2-out FILE]`: ELF (or UF2) -> UF2, or flashing over
//! PICOBOOT. The image is read and checked completely before any device is touched.

use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};
use usb::bootsel_request::request_bootsel;
use usb::discovery::list_serial_ports;
use usb::elf_image::load_segments;
use usb::picoboot::Picoboot;
use usb::rusb_transport::RusbPicoboot;
use usb::uf2::{FlashImage, UF2_MAGIC_START0, UF2_MAGIC_START1};

#[derive(Debug, Args)]
pub struct FlashArgs {
    /// The firmware: the ELF of the firmware/rp2040 build, or a UF2 file for the RP2040.
    pub firmware: PathBuf,
    /// Only write the UF2 file (copy it to the RPI-RP2 drive to flash).
    #[arg(long)]
    pub uf2_out: Option<PathBuf>,
    /// Serial port of a running controller to reboot into BOOTSEL (default: the first port
    /// with our VID:PID).
    #[arg(long)]
    pub port: Option<String>,
}

pub fn run(args: FlashArgs) -> ExitCode {
    let path = args.firmware.display().to_string();
    // The RP2040 addresses at most 16 MiB of flash; an ELF with full debug information is
    // larger than its image but not by this much.
    const MAX_FIRMWARE_FILE_BYTES: u64 = 256 << 20;
    let elf = match fem_core::input_file::read_limited(
        &args.firmware,
        MAX_FIRMWARE_FILE_BYTES,
        "a firmware image",
    ) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: {path}: {e}");
            return ExitCode::from(2);
        }
    };
    let is_uf2 = elf.len() >= 8
        && elf[0..4] == UF2_MAGIC_START0.to_le_bytes()
        && elf[4..8] == UF2_MAGIC_START1.to_le_bytes();
    let image = if is_uf2 {
        FlashImage::from_uf2(&elf).map_err(|e| e.to_string())
    } else {
        load_segments(&elf)
            .map_err(|e| e.to_string())
            .and_then(|s| FlashImage::from_segments(&s).map_err(|e| e.to_string()))
    };
    let image = match image {
        Ok(i) => i,
        Err(e) => {
            eprintln!("error: {path}: {e}");
            return ExitCode::from(2);
        }
    };
    if !image.boot2_valid() {
        eprintln!(
            "warning: {path}: no valid boot2 at 0x10000000 (CRC-32 at byte 252 does not match); \
             the boot ROM will not start this image"
        );
    }
    let bytes: usize = image.pages.len() * 256;
    if let Some(out) = &args.uf2_out {
        let uf2 = image.to_uf2();
        if let Err(e) = std::fs::write(out, &uf2) {
            eprintln!("error: {}: {e}", out.display());
            return ExitCode::FAILURE;
        }
        println!(
            "wrote {} ({} blocks, {} bytes of flash)",
            out.display(),
            uf2.len() / 512,
            bytes
        );
        return ExitCode::SUCCESS;
    }
    let device = match find_bootrom(args.port.as_deref()) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut session = Picoboot::new(device);
    let mut last_phase = String::new();
    let mut progress = |phase: &str, done: usize, total: usize| {
        if phase != last_phase || done == total {
            eprintln!("{phase}: {done}/{total} bytes");
            last_phase = phase.to_string();
        }
    };
    match session.flash_image(&image, &mut progress) {
        Ok(()) => {
            println!("flashed and verified {bytes} bytes; rebooting into the new firmware");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: flashing failed: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The boot ROM device, rebooting a running controller into BOOTSEL first if needed.
fn find_bootrom(port: Option<&str>) -> Result<RusbPicoboot, String> {
    if let Some(d) = RusbPicoboot::open_first().map_err(|e| e.to_string())? {
        return Ok(d);
    }
    let port = match port {
        Some(p) => p.to_string(),
        None => list_serial_ports()
            .unwrap_or_default()
            .into_iter()
            .find(|p| p.ours)
            .map(|p| p.port)
            .ok_or_else(|| {
                "no RP2040 in BOOTSEL mode and no tactile controller on a serial port; hold \
                 BOOTSEL while plugging the board in, or write a UF2 with --uf2-out"
                    .to_string()
            })?,
    };
    eprintln!("asking the controller on {port} to reboot into BOOTSEL");
    request_bootsel(&port, Duration::from_secs(2)).map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(250));
        if let Some(d) = RusbPicoboot::open_first().map_err(|e| e.to_string())? {
            return Ok(d);
        }
    }
    Err("the controller acknowledged but no RP2040 boot ROM appeared within 10 s".to_string())
}
