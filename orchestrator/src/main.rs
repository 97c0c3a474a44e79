//! `orchestrator`: parses arguments, initialises logging, runs the command, and maps the outcome
//! to an exit code: 0 safe and complete, 1 safety violation / UNSAFE, 2 bad input, 3 runtime fault.

/// `println!` that never panics: a closed or full stdout (`plan | head -1`, `launch >
/// /dev/full`) must not stop a command before its files are complete. What cannot be printed is
/// dropped; the run's outcome still decides the exit code.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

mod cli;
mod commands;
mod errors;
mod export;
mod host;
mod launch;
mod loss;
mod member_priority;
mod progress;
mod realtime;
mod report;
mod team;
mod team_arm;
mod telemetry;
mod vehicle_reports;
mod viewer;

use clap::Parser;

/// Exit codes of every command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    Safe = 0,
    Unsafe = 1,
    BadInput = 2,
    Fault = 3,
}

/// Any error a command ends with, its source chain kept (see [`Failure::message`]).
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A failure with its exit code. The error stays typed, with its sources, until `main` prints it.
#[derive(Debug)]
pub struct Failure {
    pub exit: Exit,
    pub error: BoxError,
}

impl Failure {
    pub fn bad_input(error: impl Into<BoxError>) -> Self {
        Failure {
            exit: Exit::BadInput,
            error: error.into(),
        }
    }

    pub fn fault(error: impl Into<BoxError>) -> Self {
        Failure {
            exit: Exit::Fault,
            error: error.into(),
        }
    }

    /// The error and its sources, `"...: caused by ..."`. A source whose text the message
    /// already shows (most of our errors name their source in their own text) is not repeated.
    pub fn message(&self) -> String {
        let mut text = self.error.to_string();
        let mut source = self.error.source();
        while let Some(s) = source {
            let more = s.to_string();
            if !more.is_empty() && !text.contains(&more) {
                text.push_str(": caused by ");
                text.push_str(&more);
            }
            source = s.source();
        }
        text
    }
}

/// A run directory that cannot be used: a full disk is a runtime fault (exit 3), anything else
/// (a file in the way, permissions) bad input.
impl From<common::rundir::RunDirError> for Failure {
    fn from(e: common::rundir::RunDirError) -> Self {
        if e.is_disk_full() {
            Failure::fault(e)
        } else {
            Failure::bad_input(e)
        }
    }
}

fn main() {
    let _ = launch::PROCESS_START.set(std::time::Instant::now());
    let cli = match cli::Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() {
                Exit::BadInput as i32
            } else {
                0
            };
            let _ = e.print();
            std::process::exit(code);
        }
    };
    let default = if cli.quiet { "warn" } else { "info" };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
    let code = match commands::run(cli) {
        Ok(exit) => exit as i32,
        Err(f) => {
            use std::io::Write as _;
            let _ = writeln!(std::io::stderr(), "error: {}", f.message());
            f.exit as i32
        }
    };
    std::process::exit(code);
}
