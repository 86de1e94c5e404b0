//! `tactile devices [--json]`: serial ports and our USB devices / RP2040 boot ROMs.

use clap::Args;
use std::process::ExitCode;
use usb::discovery::{UsbRole, discover};

#[derive(Debug, Args)]
pub struct DevicesArgs {
    /// JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: DevicesArgs) -> ExitCode {
    let report = discover();
    if args.json {
        match serde_json::to_string_pretty(&report) {
            Ok(s) => println!("{s}"),
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
        return ExitCode::SUCCESS;
    }
    println!("serial ports:");
    if let Some(note) = &report.serial_note {
        println!("  (cannot list serial ports: {note})");
    } else if report.serial_ports.is_empty() {
        println!("  none");
    }
    for p in &report.serial_ports {
        let usb = match (p.vid, p.pid) {
            (Some(v), Some(d)) => format!(" usb {v:04x}:{d:04x}"),
            _ => String::new(),
        };
        println!(
            "  {}  {}{}{}{}{}",
            p.port,
            p.kind,
            usb,
            p.serial_number
                .as_ref()
                .map_or(String::new(), |s| format!(" serial {s}")),
            p.product
                .as_ref()
                .map_or(String::new(), |s| format!(" \"{s}\"")),
            if p.ours {
                "  <- tactile controller"
            } else {
                ""
            }
        );
    }
    println!("USB devices (1209:7ac7 controller, 2e8a:0003 RP2040 boot ROM):");
    if let Some(note) = &report.usb_note {
        println!("  {note}");
    } else if report.usb.is_empty() {
        println!("  none");
    }
    for u in &report.usb {
        let role = match u.role {
            UsbRole::Controller => "tactile controller",
            UsbRole::Rp2040Bootrom => "RP2040 boot ROM (BOOTSEL), ready to flash",
        };
        println!(
            "  bus {:03} addr {:03}  {:04x}:{:04x}  {}{}",
            u.bus,
            u.address,
            u.vid,
            u.pid,
            role,
            u.serial_number
                .as_ref()
                .map_or(String::new(), |s| format!(" serial {s}"))
        );
    }
    ExitCode::SUCCESS
}
