//! `picoboot-gadget --ffs DIR [--flash-out FILE] [--flash-size BYTES]`: the RP2040 boot
//! ROM's USB face (BOOTSEL mode) on a Linux USB gadget, for testing `tactile flash` and
//! `tactile devices` against the kernel's USB stack and libusb.
//!
//! DIR is a mounted FunctionFS instance (`mount -t functionfs NAME DIR`) of an
//! `ffs.NAME` function in a configfs gadget with VID:PID 2E8A:0003. The program writes the
//! descriptors of one vendor interface (class 0xFF, one bulk OUT and one bulk IN endpoint)
//! and its string to `DIR/ep0`, after which the gadget can be bound to a UDC; then it serves
//! PICOBOOT with the boot ROM model of `usb::bootrom` on `DIR/ep1` (OUT) and `DIR/ep2` (IN),
//! and INTERFACE_RESET and GET_COMMAND_STATUS on `ep0`. Every command is logged on stderr.
//!
//! The flash (2 MiB by default) starts erased. On REBOOT the program acknowledges, writes
//! the flash to FILE (`--flash-out`), waits the delay and exits, which unbinds the gadget
//! (the chip leaves the bus as a real one does); on SIGTERM or SIGINT it writes FILE and
//! exits too.

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use hil_sim::functionfs::{self, Event, Setup};
use usb::bootrom::{BootRom, BootRomError, Expect, command_name};
use usb::picoboot::{
    CMD_EXCLUSIVE_ACCESS, CMD_FLASH_ERASE, CMD_READ, CMD_REBOOT, CMD_WRITE, REQ_GET_COMMAND_STATUS,
    REQ_INTERFACE_RESET, REQTYPE_IN, REQTYPE_OUT, status_name,
};

const USAGE: &str = "usage: picoboot-gadget --ffs DIR [--flash-out FILE] [--flash-size BYTES]

The RP2040 boot ROM's PICOBOOT interface (BOOTSEL mode) on a Linux USB gadget through
FunctionFS, with the boot ROM model of the usb crate behind it (NOR flash, alignment,
exclusive access and XIP exit enforced).

  --ffs DIR          a mounted FunctionFS instance (mount -t functionfs NAME DIR) of an
                     ffs.NAME function in a configfs gadget with VID:PID 2E8A:0003; bind
                     the gadget to a UDC once DIR/ep1 exists
  --flash-out FILE   write the flash contents (from 0x10000000) to FILE on REBOOT and on
                     SIGTERM/SIGINT
  --flash-size BYTES the flash size (default 2097152, 2 MiB); it starts erased (0xFF)
  -h, --help         this text

Every command is logged on stderr. On REBOOT the program writes FILE, waits the
command's delay and exits, which unbinds the gadget (the chip leaves the bus).";

const STATUS_UNKNOWN_ERROR: u32 = 8;

struct Args {
    ffs: PathBuf,
    flash_out: Option<PathBuf>,
    flash_size: usize,
}

fn parse_args() -> Result<Option<Args>, String> {
    let mut ffs = None;
    let mut flash_out = None;
    let mut flash_size = 2 * 1024 * 1024;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match a.as_str() {
            "--ffs" => ffs = Some(PathBuf::from(value("--ffs")?)),
            "--flash-out" => flash_out = Some(PathBuf::from(value("--flash-out")?)),
            "--flash-size" => {
                let v = value("--flash-size")?;
                flash_size = v
                    .parse()
                    .ok()
                    .filter(|&n: &usize| n > 0 && n <= 16 << 20 && n % 4096 == 0)
                    .ok_or(format!(
                        "--flash-size {v}: a multiple of 4096 up to 16 MiB expected"
                    ))?;
            }
            "-h" | "--help" => return Ok(None),
            other => return Err(format!("unknown argument `{other}` (try --help)")),
        }
    }
    let ffs = ffs.ok_or("--ffs DIR is required (try --help)")?;
    Ok(Some(Args {
        ffs,
        flash_out,
        flash_size,
    }))
}

fn log(msg: &str) {
    eprintln!("picoboot-gadget: {msg}");
}

fn lock(rom: &Mutex<BootRom>) -> MutexGuard<'_, BootRom> {
    rom.lock().unwrap_or_else(|e| e.into_inner())
}

/// Writes the flash to `path` (through a temporary file, so that a reader never sees half
/// of it).
fn save_flash(rom: &Mutex<BootRom>, path: &Path) {
    let flash = lock(rom).flash.clone();
    let tmp = path.with_extension("tmp");
    match std::fs::write(&tmp, &flash).and_then(|()| std::fs::rename(&tmp, path)) {
        Ok(()) => log(&format!(
            "wrote the flash ({} bytes) to {}",
            flash.len(),
            path.display()
        )),
        Err(e) => log(&format!("error: {}: {e}", path.display())),
    }
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(Some(a)) => a,
        Ok(None) => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    match serve(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// An endpoint file, open for both directions: a transfer in the endpoint's wrong direction
/// halts it (FunctionFS's way of stalling).
fn open_endpoint(path: &Path) -> Result<File, String> {
    OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// Stalls an endpoint: FunctionFS halts it and fails the transfer with EBADMSG.
fn halt(result: std::io::Result<usize>) -> String {
    match result {
        Err(e) if e.raw_os_error() == Some(libc::EBADMSG) => "endpoint stalled".to_string(),
        Err(e) => format!("stalling the endpoint failed: {e}"),
        Ok(_) => "the endpoint did not stall".to_string(),
    }
}

fn serve(args: &Args) -> Result<(), String> {
    let ep0_path = args.ffs.join("ep0");
    let mut ep0 = OpenOptions::new()
        .read(true)
        .write(true)
        .open(&ep0_path)
        .map_err(|e| format!("{}: {e} (is FunctionFS mounted there?)", ep0_path.display()))?;
    ep0.write_all(&functionfs::vendor_bulk_descriptors())
        .map_err(|e| format!("{}: writing the descriptors: {e}", ep0_path.display()))?;
    ep0.write_all(&functionfs::strings(&["RP2040 PICOBOOT"]))
        .map_err(|e| format!("{}: writing the strings: {e}", ep0_path.display()))?;
    let ep_out = open_endpoint(&args.ffs.join("ep1"))?;
    let ep_in = open_endpoint(&args.ffs.join("ep2"))?;
    log(&format!(
        "ready on {} (flash {} bytes, erased)",
        args.ffs.display(),
        args.flash_size
    ));

    let rom = Arc::new(Mutex::new(BootRom::new(vec![0xFF; args.flash_size])));

    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .map_err(|e| format!("signal handler: {e}"))?;
    }
    {
        let rom = Arc::clone(&rom);
        let flash_out = args.flash_out.clone();
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(50));
            }
            log("stopped by a signal");
            if let Some(path) = &flash_out {
                save_flash(&rom, path);
            }
            std::process::exit(0);
        });
    }
    {
        let rom = Arc::clone(&rom);
        let flash_out = args.flash_out.clone();
        std::thread::spawn(move || bulk_loop(&rom, ep_out, ep_in, flash_out.as_deref()));
    }
    control_loop(&rom, &mut ep0)
}

/// Events and control requests on `ep0`.
fn control_loop(rom: &Mutex<BootRom>, ep0: &mut File) -> Result<(), String> {
    let mut buf = [0u8; functionfs::EVENT_SIZE * 4];
    loop {
        let n = match ep0.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(format!("reading ep0 events: {e}")),
        };
        for event in functionfs::parse_events(&buf[..n]) {
            match event {
                Event::Setup(setup) => control_request(rom, ep0, setup),
                Event::Enable => log("enabled (the host configured the device)"),
                Event::Disable => {
                    log("disabled");
                    lock(rom).phase = usb::bootrom::Phase::Command;
                }
                Event::Bind => log("bound to the UDC"),
                Event::Unbind => log("unbound from the UDC"),
                Event::Suspend | Event::Resume | Event::Unknown(_) => {}
            }
        }
    }
}

fn control_request(rom: &Mutex<BootRom>, ep0: &mut File, setup: Setup) {
    let result = match (setup.request_type, setup.request) {
        (REQTYPE_OUT, REQ_INTERFACE_RESET) => {
            lock(rom).interface_reset();
            log("INTERFACE_RESET");
            // a read completes the status stage of a request without data
            ep0.read(&mut []).map(drop)
        }
        (REQTYPE_IN, REQ_GET_COMMAND_STATUS) => {
            let status = lock(rom).command_status();
            log(&format!(
                "GET_COMMAND_STATUS: status {}",
                u32::from_le_bytes([status[4], status[5], status[6], status[7]])
            ));
            let n = usize::from(setup.length).min(status.len());
            ep0.write(&status[..n]).map(drop)
        }
        _ => {
            log(&format!(
                "unsupported control request type 0x{:02x} request 0x{:02x}: stalled",
                setup.request_type, setup.request
            ));
            // the wrong direction stalls the control endpoint
            let _ = if setup.is_in() {
                ep0.read(&mut [0u8; 1])
            } else {
                ep0.write(&[0u8; 1])
            };
            Ok(())
        }
    };
    if let Err(e) = result {
        log(&format!("ep0: {e}"));
    }
}

/// Commands and their data on the bulk endpoints.
fn bulk_loop(rom: &Mutex<BootRom>, mut ep_out: File, mut ep_in: File, flash_out: Option<&Path>) {
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        let expect = lock(rom).expect();
        let result = match expect {
            Expect::Out(n) => {
                // exactly what is due (a full-size last packet ends no transfer); a
                // zero-length acknowledgement still needs room for a packet
                let len = if n == 0 { 512 } else { n.min(buf.len()) };
                match ep_out.read(&mut buf[..len]) {
                    Ok(got) => {
                        let mut r = lock(rom);
                        let is_command = r.phase == usb::bootrom::Phase::Command;
                        let res = r.bulk_out(&buf[..got]);
                        if is_command && res.is_ok() {
                            log(&describe(&buf[..got]));
                        }
                        res.map(drop)
                    }
                    Err(e) => {
                        io_error("ep1 (bulk OUT)", &e);
                        continue;
                    }
                }
            }
            Expect::In => {
                let data = lock(rom).bulk_in();
                match data {
                    Ok(data) => {
                        // `write`, not `write_all`: a zero-length acknowledgement is one
                        // write of nothing
                        match ep_in.write(&data) {
                            Ok(n) if n == data.len() => {}
                            Ok(n) => {
                                log(&format!("ep2 (bulk IN): {n} of {} bytes sent", data.len()))
                            }
                            Err(e) => {
                                io_error("ep2 (bulk IN)", &e);
                                continue;
                            }
                        }
                        let r = lock(rom);
                        if data.is_empty()
                            && r.phase == usb::bootrom::Phase::Command
                            && let Some(reboot) = r.rebooted
                        {
                            drop(r);
                            log(&format!(
                                "rebooting: pc 0x{:08x}, sp 0x{:08x}, after {} ms",
                                reboot.pc, reboot.sp, reboot.delay_ms
                            ));
                            if let Some(path) = flash_out {
                                save_flash(rom, path);
                            }
                            std::thread::sleep(Duration::from_millis(u64::from(
                                reboot.delay_ms.min(10_000),
                            )));
                            std::process::exit(0);
                        }
                        Ok(())
                    }
                    Err(e) => Err(e),
                }
            }
        };
        if let Err(e) = result {
            let mut r = lock(rom);
            let cmd = r.last_cmd;
            if let BootRomError::Protocol(_) = e {
                r.status = STATUS_UNKNOWN_ERROR;
                r.phase = usb::bootrom::Phase::Command;
            }
            let status = r.status;
            drop(r);
            // The endpoint the host uses next stalls: WRITE's data phase on OUT, else the
            // IN endpoint (data or acknowledgement). The wrong direction halts it.
            let stalled = halt(if cmd == CMD_WRITE {
                ep_out.write(&[0u8; 1])
            } else {
                ep_in.read(&mut [0u8; 1])
            });
            let why = match e {
                BootRomError::Status(_) => String::new(),
                BootRomError::Protocol(v) => format!(" ({v})"),
            };
            log(&format!(
                "command 0x{cmd:02x} {} failed{why}: status {status} ({}), {stalled}",
                command_name(cmd),
                status_name(status)
            ));
        }
    }
}

fn io_error(what: &str, e: &std::io::Error) {
    // ESHUTDOWN and the like while the host resets or the gadget is unbound: wait for the
    // endpoint to come back
    log(&format!("{what}: {e}"));
    std::thread::sleep(Duration::from_millis(200));
}

/// A command packet as a log line: `WRITE 0x10000000 +4096`.
fn describe(p: &[u8]) -> String {
    let le = |o: usize| u32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]]);
    let id = p[8];
    let name = command_name(id);
    match id {
        CMD_FLASH_ERASE | CMD_READ | CMD_WRITE => format!("{name} 0x{:08x} +{}", le(16), le(20)),
        CMD_EXCLUSIVE_ACCESS => format!("{name} mode {}", p[16]),
        CMD_REBOOT => format!(
            "{name} pc 0x{:08x} sp 0x{:08x} delay {} ms",
            le(16),
            le(20),
            le(24)
        ),
        _ => name.to_string(),
    }
}
