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
mod command_error;
mod commands;
mod export_args;
mod export_cmd;
mod launch_args;
mod launch_failure;
mod notices;
mod print_certificate;
mod print_origin;
mod progress;
mod replay;
mod replay_realtime;
mod run_summary;
mod steer_cmd;

use cdm_exit::Exit;
use clap::Parser;

fn main() {
    let _ = cdm_launch::launch::PROCESS_START.set(std::time::Instant::now());
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
    // zenoh's TLS link warns on every connection that it skips name verification: we check
    // peers by the team's authority and their certificate's common name instead (cdm-zenoh).
    // The DDS stack of `--ros2 dds` logs every discovery step at info and, with
    // ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, fails to leave a multicast group it never needed
    // on loopback as it closes: its errors only (RUST_LOG shows the rest).
    const QUIETER: &str =
        "zenoh_link_tls::utils=error,rustdds=error,rustdds::network::udp_listener=off,ros2_client=error";
    let default = if cli.quiet {
        format!("warn,{QUIETER}")
    } else {
        format!("info,{QUIETER}")
    };
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
