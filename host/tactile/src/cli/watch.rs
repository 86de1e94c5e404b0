//! `tactile watch`: the live dashboard (see `daemon::terminal_view`).

use std::process::ExitCode;
use std::sync::mpsc;
use std::time::Duration;

use clap::Args;
use daemon::terminal_view::{DashboardState, render};
use ratatui::crossterm::event::{self, Event as TermEvent, KeyCode, KeyModifiers};

use super::status::DaemonAddr;

#[derive(Debug, Args)]
pub struct WatchArgs {
    #[command(flatten)]
    daemon: DaemonAddr,
}

pub fn run(args: WatchArgs) -> ExitCode {
    use std::io::IsTerminal as _;
    if !(std::io::stdout().is_terminal() && std::io::stdin().is_terminal()) {
        eprintln!(
            "error: tactile watch draws a live view and needs a terminal; without one, read the live feed (GET /v1/events, see docs/daemon-api.md) or poll `tactile status`"
        );
        return ExitCode::from(2);
    }
    let client = match args.daemon.client() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut state = match client.status() {
        Ok(s) => DashboardState::from_status(&s),
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let events = match client.events() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let (tx, rx) = mpsc::channel();
    let reader = std::thread::Builder::new()
        .name("watch-feed".into())
        .spawn(move || {
            for e in events {
                if tx.send(e).is_err() {
                    return;
                }
            }
        });
    if reader.is_err() {
        eprintln!("error: cannot start the feed reader");
        return ExitCode::FAILURE;
    }
    let mut terminal = match ratatui::try_init() {
        Ok(t) => t,
        Err(e) => {
            ratatui::restore();
            eprintln!("error: tactile watch cannot use this terminal ({e})");
            return ExitCode::from(2);
        }
    };
    let mut closed = false;
    let result = loop {
        for e in rx.try_iter() {
            match e {
                Ok(ev) => state.apply(&ev),
                Err(e) => state.message = format!("live feed: {e}"),
            }
        }
        if !closed && matches!(rx.try_recv(), Err(mpsc::TryRecvError::Disconnected)) {
            closed = true;
            state.message = "the daemon closed the live feed".into();
        }
        if let Err(e) = terminal.draw(|f| render(&state, f, f.area())) {
            break Err(e.to_string());
        }
        match event::poll(Duration::from_millis(100)) {
            Ok(true) => {
                if let Ok(TermEvent::Key(k)) = event::read() {
                    let ctrl_c =
                        k.code == KeyCode::Char('c') && k.modifiers.contains(KeyModifiers::CONTROL);
                    if matches!(k.code, KeyCode::Char('q') | KeyCode::Esc) || ctrl_c {
                        break Ok(());
                    }
                }
            }
            Ok(false) => {}
            Err(e) => break Err(e.to_string()),
        }
    };
    ratatui::restore();
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
