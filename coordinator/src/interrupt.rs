//! SIGINT and SIGTERM. The first signal asks the run to stop at the end of the window under
//! way (after a last checkpoint when the scene checkpoints, so that `cosim resume` continues
//! from there bitwise); a second one stops the run at once; a third ends the process.
//! The nodes run in their own process group, so a Ctrl-C in the terminal reaches only the
//! coordinator, which stops them cleanly.

use std::sync::OnceLock;

use tokio::sync::watch;

/// `(signals received so far, the last signal's number)`.
type Signals = (u32, i32);

static SIGNALS: OnceLock<watch::Receiver<Signals>> = OnceLock::new();

/// The run was stopped by a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("interrupted by {}", signal_name(*.signal))]
pub struct Interrupted {
    pub signal: i32,
}

impl Interrupted {
    /// The conventional exit code: 128 + the signal's number (130 for SIGINT, 143 for SIGTERM).
    pub fn exit_code(&self) -> u8 {
        (128 + self.signal).clamp(0, 255) as u8
    }
}

pub fn signal_name(signal: i32) -> &'static str {
    match signal {
        libc::SIGINT => "SIGINT (Ctrl-C)",
        libc::SIGTERM => "SIGTERM",
        _ => "a signal",
    }
}

/// Listens for SIGINT and SIGTERM from now on (call once, inside the runtime). Until this is
/// called (library use, tests) runs are never interrupted.
pub fn install() -> std::io::Result<()> {
    use tokio::signal::unix::{signal, SignalKind};
    if SIGNALS.get().is_some() {
        return Ok(());
    }
    let (tx, rx) = watch::channel((0u32, 0i32));
    for (kind, number) in [
        (SignalKind::interrupt(), libc::SIGINT),
        (SignalKind::terminate(), libc::SIGTERM),
    ] {
        let mut stream = signal(kind)?;
        let tx = tx.clone();
        tokio::spawn(async move {
            while stream.recv().await.is_some() {
                let mut count = 0;
                tx.send_modify(|s| {
                    s.0 += 1;
                    s.1 = number;
                    count = s.0;
                });
                if count >= 3 {
                    eprintln!("{}: third signal, exiting now", signal_name(number));
                    std::process::exit(128 + number);
                }
            }
        });
    }
    let _ = SIGNALS.set(rx);
    Ok(())
}

/// A view of the signals received, for one run.
#[derive(Debug, Clone)]
pub struct Watch {
    rx: Option<watch::Receiver<Signals>>,
    seen: u32,
}

impl Watch {
    pub fn new() -> Self {
        let rx = SIGNALS.get().cloned();
        let seen = rx.as_ref().map_or(0, |r| r.borrow().0);
        Watch { rx, seen }
    }

    /// A signal that arrived since the last call, if any.
    pub fn poll(&mut self) -> Option<i32> {
        let rx = self.rx.as_ref()?;
        let (count, sig) = *rx.borrow();
        (count > self.seen).then(|| {
            self.seen = count;
            sig
        })
    }
}

impl Default for Watch {
    fn default() -> Self {
        Self::new()
    }
}
