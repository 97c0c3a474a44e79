//! Test-only helpers shared by the integration tests of cdm-scenario and cdm-iox (a dev-dependency
//! only: nothing ships with it).

use std::sync::mpsc;
use std::thread;
use std::time::Duration;

/// Ends the whole test process if a test outlives its deadline (a hang must not block CI).
pub struct Watchdog(Option<mpsc::Sender<()>>);

impl Watchdog {
    /// Arm a watchdog for `test`; dropping it disarms it.
    pub fn new(test: &'static str, deadline: Duration) -> Self {
        let (tx, rx) = mpsc::channel::<()>();
        thread::spawn(move || {
            if let Err(mpsc::RecvTimeoutError::Timeout) = rx.recv_timeout(deadline) {
                eprintln!("watchdog: test {test} exceeded its {deadline:?} deadline; aborting");
                std::process::exit(3);
            }
        });
        Self(Some(tx))
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        if let Some(tx) = self.0.take() {
            let _ = tx.send(());
        }
    }
}
