//! The commands behind the CLI.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use cdm_certificates::airspace_suggest::suggest;
use cdm_certificates::certificate::{deviation_at, Certificate};
use cdm_certificates::certify::certify;
use cdm_certificates::command_certificate::{apply_commands, CommandRecord};
use cdm_certificates::delay::deviation_at_delay;
use cdm_certificates::losscert::{certify_losses, LossCertificate};
use cdm_certificates::vehicle_certificate::{suggest_times, VehicleCertificate};
use cdm_engine::loss::LossSchedule;
use cdm_model::link::MAX_DELAY_MS;
use cdm_model::outcome::Verdict;
use cdm_records::audit::AuditReport;
use cdm_records::run_record::{RunMode, RunRecord};
use cdm_records::rundir::RunDir;
use cdm_scenario::{Checks, Scenario};
use cdm_simulate::{simulate, SimulateOptions};

use cdm_iox::TeamName;
use cdm_member_cli::timeout;

use crate::cli::{Cli, Command, LaunchArgs, OutDir, RunOptions, ScenarioCommand};
use crate::command_error::CommandError;
use crate::export_args::{load, SourceArgs};
use crate::print_certificate::print_certificate;
use crate::progress::Spinner;
use crate::run_summary::summary;
use cdm_exit::{Exit, Failure};
use cdm_launch::launch::{launch, LaunchOptions};
use cdm_launch::steer::{write_commands, FileCommands};
use cdm_report::{report, ReportError};

pub fn run(cli: Cli) -> Result<Exit, Failure> {
    match cli.command {
        Command::Plan {
            source,
            json,
            sweep,
            sweep_delay,
            out,
            losses,
            suggest,
        } => {
            let sweeps = Sweeps {
                travel_s: sweep
                    .map(|t| parse_sweep(&t, "--sweep", "seconds", false, "40:200:20"))
                    .transpose()?,
                delay_ms: sweep_delay
                    .map(|t| parse_sweep(&t, "--sweep-delay", "milliseconds", true, "0:200:10"))
                    .transpose()?,
                out,
            };
            plan(
                &source,
                json.as_deref(),
                sweeps,
                PlanAlso { losses, suggest },
                cli.quiet,
            )
        }
        Command::Simulate {
            source,
            out,
            run,
            commands,
        } => simulate_command(&source, &out, &run, commands.as_deref(), cli.quiet),
        Command::Replay(args) => replay_command(&args, cli.quiet),
        Command::Report {
            dir,
            follow,
            against,
        } => report_command(&dir, follow, against.as_deref(), cli.quiet),
        Command::Launch(args) => launch_command(*args, cli.quiet),
        Command::Steer(args) => crate::steer_cmd::run(&args),
        Command::View {
            dir,
            serve,
            foxglove,
        } => match foxglove.options()? {
            Some(o) => view_foxglove(&dir, &o, cli.quiet),
            None => view(&dir, serve.as_deref(), cli.quiet),
        },
        Command::Clean => clean(cli.quiet),
        Command::Host {
            connect,
            keys,
            insecure,
            team,
            host,
            scenario,
            join_timeout,
        } => {
            let t = cdm_hosts::Transport::choose("--connect", &connect, keys.as_deref(), insecure)
                .map_err(Failure::bad_input)?;
            host_daemon(connect, t, team, host, scenario, join_timeout, cli.quiet)
        }
        Command::Keys { action } => keys_command(action, cli.quiet),
        Command::Export { target } => crate::export_cmd::run(target, cli.quiet),
        Command::Scenario {
            command: ScenarioCommand::Export { name, n, out },
        } => scenario_export(name, n, out.as_deref()),
    }
}

/// `orchestrator simulate`: the whole team in one process, audited and recorded.
fn simulate_command(
    source: &SourceArgs,
    out: &OutDir,
    run: &RunOptions,
    commands: Option<&Path>,
    quiet: bool,
) -> Result<Exit, Failure> {
    cdm_team::telemetry::check_available(run.telemetry).map_err(Failure::bad_input)?;
    let s = run.link.apply(&load(source)?).map_err(Failure::bad_input)?;
    check_follow(&s, run.follow)?;
    // Checked before the run directory exists: a refused loss writes nothing.
    let losses = LossSchedule::new(&s, &run.lose, run.max_ticks).map_err(Failure::bad_input)?;
    let steered = match commands {
        Some(path) => {
            let list = cdm_scenario::load_commands(path, &s).map_err(Failure::bad_input)?;
            Some(apply_commands(&s, &list))
        }
        None => None,
    };
    let dir = RunDir::create(&out.out, out.force).map_err(Failure::from)?;
    let (s, records) = match steered {
        Some((flown, records)) => (flown, Some(records)),
        None => (s, None),
    };
    let flight = InProcess {
        what: "simulate",
        mode: RunMode::Simulate,
        records: records.as_deref(),
        losses,
        every: out.every,
        run,
        quiet,
    };
    let report = fly_in_process(&s, &dir, flight)?;
    after_run(dir.path(), &report, run, quiet);
    Ok(crate::run_summary::exit_of(&report))
}

/// `orchestrator replay`: the run directory checked and flown again (changed or not), then
/// compared with the run.
fn replay_command(a: &crate::cli::ReplayArgs, quiet: bool) -> Result<Exit, Failure> {
    if crate::replay_realtime::is_realtime(&a.run) {
        return crate::replay_realtime::replay_realtime(a, quiet);
    }
    let p = crate::replay::prepare(a)?;
    let flight = InProcess {
        what: "replay",
        mode: RunMode::Replay,
        records: p.records.as_deref(),
        losses: p.losses,
        every: Some(p.every),
        run: &p.run,
        quiet,
    };
    let report = fly_in_process(&p.flown, &p.dir, flight)?;
    let differs = crate::replay::compare(&a.run, p.dir.path(), p.format, quiet)?;
    after_run(p.dir.path(), &report, &p.run, quiet);
    crate::replay::outcome(a, p.what_if, differs)?;
    Ok(crate::run_summary::exit_of(&report))
}

/// A flight with the in-process engine: `simulate`, and `replay` with the run's options.
struct InProcess<'a> {
    /// The command's name, in the progress and summary lines.
    pub what: &'static str,
    /// What run.json says flew the run.
    pub mode: RunMode,
    /// The commands applied to the plan flown, when the run has a command file.
    pub records: Option<&'a [CommandRecord]>,
    pub losses: LossSchedule,
    /// `--every` as given.
    pub every: Option<u64>,
    pub run: &'a RunOptions,
    pub quiet: bool,
}

/// Fly `s` (its plan the commanded one) into `dir`: commands.json, run.json, telemetry and the
/// audit, with progress and the summary.
fn fly_in_process(s: &Scenario, dir: &RunDir, f: InProcess) -> Result<AuditReport, Failure> {
    let run = f.run;
    if let Some(records) = f.records {
        write_commands(dir, records).map_err(Failure::fault)?;
    }
    let started = Instant::now();
    let every = crate::cli::every_or_default(f.every, s.file.agents.len());
    if !f.quiet {
        out!("{}", crate::cli::every_line(f.every, s.file.agents.len()));
    }
    run_record(s, f.mode, every, run, &f.losses)
        .write(dir.path())
        .map_err(Failure::from)?;
    let opts = SimulateOptions {
        every,
        stop_on_violation: run.stop_on_violation,
        max_ticks: run.max_ticks,
        telemetry: run.telemetry,
        losses: f.losses,
        on_loss: run.on_loss.into(),
        commands: (f.records.unwrap_or_default().iter())
            .map(CommandRecord::summary)
            .collect(),
    };
    let mut tel =
        cdm_team::telemetry::open(dir, run.telemetry, every, s).map_err(Failure::bad_input)?;
    let last = run
        .max_ticks
        .map_or(s.last_tick(), |k| k.min(s.last_tick()));
    let mut progress = crate::notices::sink(f.quiet).progress(f.what, last, s.dt_s());
    let report = simulate(s, dir, opts, tel.as_mut(), |tick, audit| {
        progress.tick(tick, audit.report())
    })
    .map_err(Failure::fault)?;
    progress.finish();
    summary(f.what, &report, started, dir.path(), f.quiet);
    Ok(report)
}

/// run.json: what the run's other files do not say of how it was flown.
fn run_record(
    s: &Scenario,
    mode: RunMode,
    every: u64,
    run: &RunOptions,
    losses: &LossSchedule,
) -> RunRecord {
    RunRecord {
        format: cdm_records::run_record::RUN_RECORD_FORMAT.into(),
        mode,
        scenario_hash: RunRecord::hash_text(s.content_hash()),
        every,
        max_ticks: run.max_ticks,
        stop_on_violation: run.stop_on_violation,
        stop_on_loss: run.on_loss == crate::cli::OnLossArg::Stop,
        telemetry: RunRecord::telemetry_name(run.telemetry).into(),
        losses: losses.events.clone(),
    }
}

/// The figures and replay.html of a finished in-process run.
fn after_run(dir: &Path, report: &AuditReport, run: &RunOptions, quiet: bool) {
    figures_after_run(dir, run, quiet);
    if report.ticks > 0 {
        replay_after_run(dir, quiet);
    }
}

/// `orchestrator report RUN_DIR`: the figures of a finished run.
fn report_command(
    dir: &Path,
    follow: Option<u32>,
    against: Option<&Path>,
    quiet: bool,
) -> Result<Exit, Failure> {
    let started = Instant::now();
    let files = match against {
        Some(other) => cdm_report::compare(dir, other),
        None => report(dir, follow),
    }
    .map_err(|e| match e {
        ReportError::Read(_) => Failure::bad_input(e),
        ReportError::Draw(_) => Failure::fault(e),
    })?;
    if !quiet {
        out!(
            "report: {} files in {} ({:.2} s)",
            files.len(),
            dir.display(),
            started.elapsed().as_secs_f64()
        );
        for f in &files {
            out!("  {}", f.display());
        }
    }
    Ok(Exit::Safe)
}

/// `orchestrator scenario export`: a built-in or generated scenario as TOML.
fn scenario_export(
    name: Option<String>,
    n: Option<usize>,
    out: Option<&Path>,
) -> Result<Exit, Failure> {
    let source = SourceArgs {
        scenario: None,
        n,
        builtin: name,
        t_total: None,
    };
    let s = load(&source)?;
    match out {
        Some(p) => cdm_records::rundir::write_atomic(p, s.to_toml().as_bytes())
            .map_err(Failure::bad_input)?,
        None => {
            use std::io::Write as _;
            let _ = std::io::stdout().write_all(s.to_toml().as_bytes());
        }
    }
    Ok(Exit::Safe)
}

/// `orchestrator launch`: the team as processes, then its summary, figures and replay.
fn launch_command(a: LaunchArgs, quiet: bool) -> Result<Exit, Failure> {
    let (s, opts) = launch_options(&a, quiet)?;
    // Said only when the default thins the telemetry (over 40 members): before the launch, which
    // may still refuse its input, so a small team's refusal keeps stdout empty.
    if !quiet && a.every.is_none() && crate::cli::every_or_default(None, s.file.agents.len()) > 1 {
        out!("{}", crate::cli::every_line(a.every, s.file.agents.len()));
    }
    let started = Instant::now();
    let launched = launch(&s, &opts).map_err(crate::launch_failure::launch_failure)?;
    let mode = match opts.realtime {
        Some(_) => RunMode::Realtime,
        None => RunMode::Lockstep,
    };
    let record = run_record(&s, mode, opts.every, &a.run, &opts.losses);
    if let Err(e) = record.write(&opts.out) {
        tracing::error!("run.json not written: {e}");
    }
    print_launched(&launched, started, &opts.out, quiet);
    if launched.report.ticks > 0 {
        figures_after_run(&opts.out, &a.run, quiet);
        replay_after_run(&opts.out, quiet);
    }
    let exit = crate::run_summary::exit_of(&launched.report);
    // The live view (`--serve`) served until the figures and the replay were written.
    drop(launched.live);
    Ok(exit)
}

/// `--window`, or the default for the team's size and the free shared memory
/// ([`cdm_iox::lockstep_window`]); said when short shared memory narrowed it.
fn lockstep_window(a: &LaunchArgs, s: &Scenario, quiet: bool) -> u32 {
    if let Some(w) = a.window {
        return w;
    }
    let agents = s.formation.members.len();
    let delay = u32::try_from(s.link_model().max_ticks()).unwrap_or(u32::MAX);
    let free = cdm_iox::shm_free_bytes();
    let window = cdm_iox::lockstep_window(agents, delay, free);
    if !quiet && window < cdm_iox::lockstep_window(agents, delay, None) {
        out!(
            "window: {window} ticks (/dev/shm has {} KiB free; --window W to choose)",
            free.unwrap_or(0) / 1024
        );
    }
    window
}

/// The scenario and the launch options from the command line, every value checked.
fn launch_options(a: &LaunchArgs, quiet: bool) -> Result<(Scenario, LaunchOptions), Failure> {
    cdm_team::telemetry::check_available(a.run.telemetry).map_err(Failure::bad_input)?;
    let vehicles = a
        .vehicle
        .validate(a.realtime.realtime)
        .map_err(Failure::bad_input)?;
    let s = a
        .run
        .link
        .apply(&load(&a.source)?)
        .map_err(Failure::bad_input)?;
    vehicles.check(&s).map_err(Failure::bad_input)?;
    let realtime = a.realtime.options(&s)?;
    if let Some(why) =
        realtime.and_then(|rt| cdm_member::options::realtime_links_refusal(&s, rt.stale_after))
    {
        return Err(Failure::bad_input(why));
    }
    check_follow(&s, a.run.follow)?;
    let losses = LossSchedule::new(&s, &a.run.lose, a.run.max_ticks).map_err(Failure::bad_input)?;
    if realtime.is_some() && a.hosts.hosts > 1 && !a.run.lose.is_empty() {
        // Real time repairs losses on one host only: across hosts a scripted one stops the team.
        return Err(Failure::bad_input(
            "--lose with --realtime needs one host: real time repairs a lost member only on one host (fly the losses in lockstep, or on one host)",
        ));
    }
    if a.no_spawn && !a.run.lose.is_empty() {
        // The orchestrator carries out a scripted loss by killing the member's process.
        return Err(Failure::bad_input(
            "--lose needs members spawned by launch (not --no-spawn)",
        ));
    }
    let (s, commands, realtime_commands) = file_commands(a, s, realtime.as_ref())?;
    let team_name = a
        .team
        .clone()
        .unwrap_or_else(|| format!("cdm{}", std::process::id()));
    let team = TeamName::new(&team_name)
        .map_err(|e| Failure::bad_input(CommandError::option("--team")(e)))?;
    let secs = |v: f64, what: &str| timeout(what, v).map_err(Failure::bad_input);
    let opts = LaunchOptions {
        out: a
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(team.as_str())),
        team,
        force: a.force,
        every: crate::cli::every_or_default(a.every, s.file.agents.len()),
        telemetry: a.run.telemetry,
        // Real time reads the newest states: a short buffer is enough.
        window: if realtime.is_some() {
            cdm_launch::realtime::REALTIME_WINDOW
        } else {
            lockstep_window(a, &s, quiet)
        },
        spawn: !a.no_spawn,
        agent_timeout: secs(a.agent_timeout, "--agent-timeout")?,
        join_timeout: secs(a.join_timeout, "--join-timeout")?,
        notices: crate::notices::sink(quiet),
        stop_on_violation: a.run.stop_on_violation,
        max_ticks: a.run.max_ticks,
        land_on_interrupt: land_on_interrupt(a, &vehicles)?,
        vehicles,
        serve: a
            .serve
            .as_deref()
            .map(crate::cli::serve_addr)
            .transpose()
            .map_err(Failure::bad_input)?,
        ros2: a.ros2.options()?,
        foxglove: a.foxglove.options()?,
        hosts: host_options(a)?,
        realtime,
        losses,
        on_loss: a.run.on_loss.into(),
        commands,
        realtime_commands,
    };
    Ok((s, opts))
}

/// `--on-interrupt`: whether SIGINT or SIGTERM lands the team before it stops (by default
/// with MAVLink vehicles, which would otherwise fall back to their own failsafes), in lockstep
/// or real time, on any number of hosts.
fn land_on_interrupt(
    a: &LaunchArgs,
    vehicles: &cdm_member::vehicles::Vehicles,
) -> Result<bool, Failure> {
    use crate::cli::OnInterruptArg;
    let mavlink = matches!(vehicles, cdm_member::vehicles::Vehicles::Mavlink(_));
    Ok(match a.on_interrupt {
        Some(what) => what == OnInterruptArg::Land,
        None => mavlink,
    })
}

/// A launch's `--commands FILE`: in lockstep decided for the team of `s` before the flight
/// (the commanded scenario to launch, and the commands); in real time the file's commands, each
/// proposed to the leaders in flight (`s` launched as it is). `s` itself without the option.
type Commanded = (
    Scenario,
    Option<FileCommands>,
    Vec<cdm_scenario::TimedCommand>,
);

/// `--commands FILE` for the team of `s` (see [`Commanded`]).
fn file_commands(
    a: &LaunchArgs,
    s: Scenario,
    realtime: Option<&cdm_launch::realtime::RealtimeOptions>,
) -> Result<Commanded, Failure> {
    let Some(path) = &a.commands else {
        return Ok((s, None, Vec::new()));
    };
    let list = cdm_scenario::load_commands(path, &s).map_err(Failure::bad_input)?;
    if let Some(rt) = realtime {
        check_realtime_commands(path, &list, &s, rt)?;
        return Ok((s, None, list));
    }
    let (flown, c) = FileCommands::decide(&s, &list);
    Ok((flown, Some(c), Vec::new()))
}

/// `launch --realtime --commands FILE`: each command is proposed to the leaders in flight, which
/// needs the switch margin twice over before its switch (`earliest_file_switch_s`); a command
/// switching earlier is refused up front, named, not left to be withdrawn in flight.
fn check_realtime_commands(
    path: &Path,
    list: &[cdm_scenario::TimedCommand],
    s: &Scenario,
    rt: &cdm_launch::realtime::RealtimeOptions,
) -> Result<(), Failure> {
    let earliest_s = cdm_runtime::team_core::earliest_file_switch_s(s.dt_s(), rt.stale_after);
    let early = (list.iter().enumerate())
        .find(|(_, c)| cdm_model::step::tick_time(c.switch_tick, s.dt_s()) < earliest_s - 1e-9);
    match early {
        Some((k, c)) => Err(Failure::bad_input(format!(
            "{}: commands[{k}] ({} at_s = {} s) switches too early for a real-time team: a file's command is proposed to the leaders in flight and needs twice the switch margin (the larger of {} ticks and {} of --stale-after) before its switch, here at_s >= {:.3} s",
            path.display(),
            c.spec.command,
            c.spec.at_s,
            cdm_runtime::team_core::SWITCH_MARGIN_TICKS,
            cdm_runtime::team_core::SWITCH_MARGIN_OF_STALE,
            earliest_s
        ))),
        None => Ok(()),
    }
}

/// `--hosts`, `--listen` and its security: a `tls/` endpoint needs `--keys`, a `tcp/` one
/// `--insecure` (a one-host launch opens no network link).
fn host_options(a: &LaunchArgs) -> Result<cdm_hosts::HostOptions, Failure> {
    let transport = match a.hosts.listen.as_deref() {
        Some(l) if a.hosts.hosts > 1 => {
            cdm_hosts::Transport::choose("--listen", l, a.hosts.keys.as_deref(), a.hosts.insecure)
                .map_err(Failure::bad_input)?
        }
        _ => cdm_hosts::Transport::Insecure,
    };
    Ok(cdm_hosts::HostOptions {
        hosts: a.hosts.hosts,
        listen: a.hosts.listen.clone(),
        link_timeout: timeout("--link-timeout", a.hosts.link_timeout)
            .map_err(Failure::bad_input)?,
        transport,
    })
}

/// The launch's summary: the audit, the tick rate and start-up, the peak memory.
fn print_launched(l: &cdm_launch::launch::Launched, started: Instant, out: &Path, quiet: bool) {
    summary("launch", &l.report, started, out, quiet);
    if !quiet && l.ticking > Duration::ZERO {
        out!(
            "  ticking: {:.2} s ({:.0} ticks/s), start-up {:.2} s (command to first tick)",
            l.ticking.as_secs_f64(),
            l.report.ticks as f64 / l.ticking.as_secs_f64(),
            l.startup.as_secs_f64()
        );
        if let (Some(m), Some(me)) = (l.member_peak_rss, cdm_team::team::own_peak_rss()) {
            let (id, member) = m.largest;
            out!(
                "  peak resident memory: largest member {:.1} MiB (agent {id}), \
                 orchestrator {:.1} MiB, all {} members together {:.1} MiB",
                member as f64 / 1024.0,
                me as f64 / 1024.0,
                m.members,
                m.total_kib as f64 / 1024.0
            );
        }
    }
}

/// `orchestrator clean`: removes the resources of this user's teams whose processes are all
/// dead, and the dead nodes of no known team, and says what it removed.
fn clean(quiet: bool) -> Result<Exit, Failure> {
    use cdm_iox::TransportError;
    use std::io::Write;
    let removed = cdm_iox::remove_dead_teams().map_err(|e| match e {
        TransportError::UnsafeIox2Path { .. } => Failure::bad_input(e),
        e => Failure::fault(e),
    })?;
    let mut text = String::new();
    for t in &removed.teams {
        text += &format!(
            "removed team {}: the iceoryx2 resources of {} dead processes\n",
            t.team, t.removed
        );
    }
    if removed.unknown_nodes > 0 {
        text += &format!(
            "removed {} dead iceoryx2 node(s) of unknown teams: the monitor files killed processes left\n",
            removed.unknown_nodes
        );
    }
    let channels = cdm_launch::channel::remove_dead_channels();
    for team in &channels {
        text += &format!("removed team {team}'s command channel: its orchestrator is gone\n");
    }
    if removed.teams.is_empty() && removed.unknown_nodes == 0 && channels.is_empty() {
        text += &format!(
            "nothing to remove: no team under {} has all its processes dead, and no dead node of an unknown team is left\n",
            cdm_iox::iox2_root()
        );
    }
    if !quiet {
        // A closed standard output is no reason to fail: the cleaning is done.
        let _ = std::io::stdout().lock().write_all(text.as_bytes());
    }
    Ok(Exit::Safe)
}

/// `--follow ID` names a member of the scenario: checked before the flight, not after it.
fn check_follow(s: &Scenario, follow: Option<u32>) -> Result<(), Failure> {
    match follow {
        Some(id) if s.role_of(id).is_none() => Err(Failure::bad_input(format!(
            "--follow {id}: {} has no agent with this id",
            s.origin
        ))),
        _ => Ok(()),
    }
}

/// A travel time from `option` (`--sweep`) checked as `--t-total` is: the same scenario rules
/// (enough ticks to resolve the motion, at most 1e8 ticks).
fn check_travel_time(s: &Scenario, t: f64, option: &str) -> Result<(), Failure> {
    let mut f = s.file.clone();
    f.t_total_s = t;
    let origin = format!("{} with {option} travel time {t}", s.origin);
    Scenario::from_file(f, &origin, Checks::Member)
        .map(drop)
        .map_err(Failure::bad_input)
}

/// Draw the figures of a finished run (unless `--no-figures`). A drawing failure is logged, not
/// fatal: the run's own outcome decides the exit code.
fn figures_after_run(dir: &Path, run: &RunOptions, quiet: bool) {
    if run.no_figures {
        return;
    }
    match report(dir, run.follow) {
        Ok(files) => {
            if !quiet {
                out!(
                    "  figures: {} files (orchestrator report redraws them)",
                    files.len()
                );
            }
        }
        Err(e) => tracing::error!("figures not drawn: {e}"),
    }
}

/// Write replay.html into a finished run's directory. A failure is logged, not fatal (as for the
/// figures): the run's own outcome decides the exit code.
fn replay_after_run(dir: &Path, quiet: bool) {
    let started = Instant::now();
    match cdm_viewer::write_replay(dir) {
        Ok(path) if !quiet => out!(
            "  replay: {} ({:.2} s; orchestrator view redraws it)",
            path.display(),
            started.elapsed().as_secs_f64()
        ),
        Ok(_) => {}
        Err(e) => tracing::error!("replay.html not written: {e}"),
    }
}

/// `view RUN_DIR [--serve ADDR]`: (re)write replay.html, and serve it until interrupted.
fn view(dir: &Path, serve: Option<&str>, quiet: bool) -> Result<Exit, Failure> {
    let addr = serve
        .map(crate::cli::serve_addr)
        .transpose()
        .map_err(Failure::bad_input)?;
    let scene = cdm_viewer::replay_scene(dir).map_err(Failure::bad_input)?;
    let page = cdm_viewer::page(Some(&scene));
    let path = dir.join("replay.html");
    cdm_records::rundir::write_atomic(&path, page.as_bytes()).map_err(Failure::bad_input)?;
    if !quiet {
        out!(
            "view: {} ({} frames, every {} tick(s) of telemetry, {:.1} MB)",
            path.display(),
            scene.frames.len(),
            scene.stride,
            page.len() as f64 / 1e6
        );
    }
    let Some(addr) = addr else {
        return Ok(Exit::Safe);
    };
    let interrupted = cdm_process::signals::install();
    let server =
        cdm_viewer::serve_page(&addr.to_string(), page, None).map_err(Failure::bad_input)?;
    // Only the final line goes to stdout in quiet mode: tools read the address from it.
    out!("serving http://{}/ (Ctrl-C stops)", server.addr);
    while !interrupted.load(std::sync::atomic::Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(Exit::Safe)
}

/// `view RUN_DIR --foxglove [ADDR]`: the run played to Foxglove once a client connects, at
/// simulation time's pace; the server stops at the end of the run or on Ctrl-C.
fn view_foxglove(
    dir: &Path,
    o: &cdm_foxglove::FoxgloveOptions,
    quiet: bool,
) -> Result<Exit, Failure> {
    let interrupted = cdm_process::signals::install();
    let s = cdm_foxglove::replay(dir, o, interrupted, |addr| {
        // Only this line goes to stdout in quiet mode: tools read the address from it.
        out!("foxglove: ws://{addr} (plays once a client connects; Ctrl-C stops)");
    })
    .map_err(Failure::bad_input)?;
    if !quiet {
        out!(
            "foxglove: {} ticks published, {} dropped",
            s.ticks,
            s.dropped
        );
    }
    Ok(Exit::Safe)
}

/// `plan`'s sweeps (`--sweep`, `--sweep-delay`) and where they go (`--out`, required by both).
struct Sweeps {
    travel_s: Option<Vec<f64>>,
    delay_ms: Option<Vec<f64>>,
    out: Option<PathBuf>,
}

/// `FLAG LO:HI:STEP`: the values LO, LO + STEP, .. up to HI (LO may be 0 when `zero_ok`).
fn parse_sweep(
    text: &str,
    flag: &str,
    unit: &str,
    zero_ok: bool,
    example: &str,
) -> Result<Vec<f64>, Failure> {
    let lowest = if zero_ok { "0 <= LO" } else { "0 < LO" };
    let bad = || {
        Failure::bad_input(format!(
            "{flag} {text}: expected LO:HI:STEP in {unit} with {lowest} <= HI and STEP > 0, e.g. {example}"
        ))
    };
    let parts: Vec<f64> = text
        .split(':')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    let [lo, hi, step] = parts[..] else {
        return Err(bad());
    };
    let lo_ok = lo > 0.0 || (zero_ok && lo == 0.0);
    if !(lo.is_finite() && hi.is_finite() && step.is_finite() && lo_ok && hi >= lo && step > 0.0) {
        return Err(bad());
    }
    if zero_ok && hi > MAX_DELAY_MS {
        return Err(Failure::bad_input(format!(
            "{flag} {text}: delays up to {MAX_DELAY_MS} ms"
        )));
    }
    let n = ((hi - lo) / step + 1e-9).floor() as usize + 1;
    if n > 1000 {
        return Err(Failure::bad_input(format!(
            "{flag} {text}: {n} values, at most 1000"
        )));
    }
    Ok((0..n).map(|k| lo + step * k as f64).collect())
}

/// Fly the plan once per value with `fly` (E_max of one flight) behind a spinner.
fn sweep_flights(
    values: &[f64],
    what: &str,
    quiet: bool,
    fly: impl Fn(f64) -> f64,
) -> Vec<(f64, f64)> {
    let spinner = Spinner::new("sweep", quiet);
    let mut points = Vec::with_capacity(values.len());
    for (k, &v) in values.iter().enumerate() {
        spinner.set_message(format!(
            "sweep: flight {}/{} at {what} {v}",
            k + 1,
            values.len()
        ));
        points.push((v, fly(v)));
    }
    spinner.finish();
    points
}

/// `plan --sweep` and `--sweep-delay`: the figures and data into `--out`.
fn write_sweeps(
    s: &Scenario,
    c: &Certificate,
    sweeps: &Sweeps,
    quiet: bool,
) -> Result<(), Failure> {
    let Some(dir) = &sweeps.out else {
        return Ok(());
    };
    if sweeps.travel_s.is_none() && sweeps.delay_ms.is_none() {
        return Ok(());
    }
    std::fs::create_dir_all(dir)
        .map_err(|e| Failure::bad_input(format!("--out {}: {e}", dir.display())))?;
    let mut files = Vec::new();
    if let Some(times) = &sweeps.travel_s {
        let points = sweep_flights(times, "T_total =", quiet, |t| deviation_at(s, t));
        files.extend(
            cdm_report::deviation_sweep(dir, &points, c.numbers.delta_m, c.t_threshold_s)
                .map_err(Failure::fault)?,
        );
    }
    if let Some(delays) = &sweeps.delay_ms {
        let points = sweep_flights(delays, "link delay (ms)", quiet, |ms| {
            deviation_at_delay(s, ms, f64::INFINITY)
        });
        let bound = c.max_link_delay_ms.filter(|_| !c.max_link_delay_at_least);
        files.extend(
            cdm_report::delay_sweep(dir, &points, c.numbers.delta_m, bound)
                .map_err(Failure::fault)?,
        );
    }
    if !quiet {
        out!("sweep: {} files in {}", files.len(), dir.display());
    }
    Ok(())
}

/// What `plan` certifies beyond the plan itself.
struct PlanAlso {
    /// `--losses`: the loss of every single member.
    losses: bool,
    /// `--suggest`: the offsets that clear the airspace's breaches, the travel times that meet
    /// the vehicles' limits.
    suggest: bool,
}

fn plan(
    source: &SourceArgs,
    json: Option<&Path>,
    sweeps: Sweeps,
    also: PlanAlso,
    quiet: bool,
) -> Result<Exit, Failure> {
    let s = load(source)?;
    if let Some(times) = &sweeps.travel_s {
        for t in [times.first(), times.last()].into_iter().flatten() {
            check_travel_time(&s, *t, "--sweep")?;
        }
    }
    let spinner = Spinner::new(
        "certifying: E_max at several travel times for T_threshold and link delays",
        quiet,
    );
    let mut c = certify(&s);
    spinner.finish();
    if also.suggest {
        if let Some(v) = &mut c.vehicle {
            v.suggestion = Some(suggest_times(&s));
        }
        match &mut c.airspace {
            Some(a) => a.suggestion = Some(suggest(&s, a.radius_m)),
            None if !quiet && c.vehicle.is_none() => out!(
                "suggest: the scenario has no [geofence], [[obstacle]] or [vehicle]: nothing to clear"
            ),
            None => {}
        }
    }
    if also.losses {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let spinner = Spinner::new(
            &format!("loss certificate: losing each of {} members", c.agents),
            quiet,
        );
        let started = Instant::now();
        c.losses = Some(certify_losses(&s, threads));
        spinner.finish();
        tracing::info!(
            seconds = started.elapsed().as_secs_f64(),
            threads,
            "loss certificate"
        );
    }
    write_sweeps(&s, &c, &sweeps, quiet)?;
    if !quiet {
        print_certificate(&c);
        crate::print_origin::print_origin(&s);
        if let Some(v) = &c.vehicle {
            print_vehicle(v);
        }
        if let Some(l) = &c.losses {
            print_loss_certificate(l);
        }
    } else {
        out!("{}", c.verdict);
    }
    if let Some(p) = json {
        let text = serde_json::to_string_pretty(&c).map_err(Failure::fault)?;
        cdm_records::rundir::write_atomic(p, text.as_bytes()).map_err(Failure::bad_input)?;
    }
    let loses = c
        .losses
        .as_ref()
        .is_some_and(|l| !l.survives_any_single_loss);
    Ok(if c.verdict == Verdict::Safe && !loses {
        Exit::Safe
    } else {
        Exit::Unsafe
    })
}

/// The `[vehicle]` part: each limit's largest commanded value, the downwash clearance, and
/// with `--suggest` the shortest travel time per phase.
fn print_vehicle(v: &VehicleCertificate) {
    if !v.limits.is_empty() {
        out!("vehicle limits: the largest commanded value over every phase (exact)");
    }
    for p in &v.limits {
        let ok = if p.exceeded() { "EXCEEDED" } else { "ok" };
        out!(
            "  {:<20} {:>10.4} of {:<8} member {:<4} {} at t = {:.2} s  {ok}",
            p.limit,
            p.value,
            p.max,
            p.agent,
            p.phase,
            p.t_s
        );
    }
    if let Some(d) = &v.downwash {
        out!(
            "  downwash (ratio {}): closest desired positions {:.4} m apart (members {} and {}, {} at t = {:.2} s), need 2 (eps + delta) = {:.4} m",
            d.downwash_ratio, d.min_m, d.agents[0], d.agents[1], d.phase, d.t_s, d.required_m
        );
    }
    for t in v.suggestion.iter().flatten() {
        let why = match (t.limit, t.agent) {
            (Some(l), Some(a)) => format!("{l}, member {a}"),
            _ => "no member loads a limit".into(),
        };
        out!(
            "  suggest: {} ({}) now {} s, shortest meeting the limits {} s ({why})",
            t.phase,
            t.key,
            t.t_s,
            t.shortest_t_s
        );
    }
}

fn print_loss_certificate(l: &LossCertificate) {
    out!(
        "loss certificate: each member lost after tick {} (t = {:.2} s, the nominal peak follower deviation {:.4} m)",
        l.loss_last_tick, l.loss_t_s, l.nominal_max_follower_deviation_m
    );
    out!("  id  role       verdict  switched  degraded  affected  max repaired dev  max shift");
    for m in &l.members {
        out!(
            "  {:<3} {:<10} {:<8} {:>8}  {:>8}  {:>8}  {:>14.4} m  {:>7.4} m",
            m.id,
            m.role.as_str(),
            m.verdict.as_str(),
            m.retriangulated.len(),
            m.degraded.len(),
            m.affected,
            m.max_repaired_deviation_m,
            m.max_shift_m
        );
        for r in &m.reasons {
            out!("      - {r}");
        }
    }
    let worst = l.members.iter().max_by(|a, b| {
        a.max_repaired_deviation_m
            .total_cmp(&b.max_repaired_deviation_m)
    });
    if let Some(w) = worst {
        out!(
            "  worst repair transient: losing {} ({}), follower {} deviates {:.4} m at t = {:.2} s (delta {:.4} m)",
            w.id,
            w.role.as_str(),
            w.worst_id.map_or("-".into(), |id| id.to_string()),
            w.max_repaired_deviation_m, w.worst_t_s, l.delta_m
        );
    }
    let degraded: usize = l.members.iter().filter(|m| !m.degraded.is_empty()).count();
    out!("  losses that leave a follower flying its plan: {degraded}");
    out!("loss verdict: {}", l.verdict);
}

/// `orchestrator host`: validates the options and runs the daemon.
#[cfg(feature = "hosts")]
fn host_daemon(
    connect: String,
    transport: cdm_hosts::Transport,
    team: Option<String>,
    host: Option<u32>,
    scenario: Option<PathBuf>,
    join_timeout: f64,
    quiet: bool,
) -> Result<Exit, Failure> {
    let team = team
        .map(|t| {
            TeamName::new(&t).map_err(|e| Failure::bad_input(CommandError::option("--team")(e)))
        })
        .transpose()?;
    let o = cdm_hosts::daemon::DaemonOptions {
        connect,
        transport,
        team,
        host,
        scenario,
        join_timeout: timeout("--join-timeout", join_timeout).map_err(Failure::bad_input)?,
    };
    cdm_hosts::daemon::run(&o, &*crate::notices::sink(quiet))
        .map(|()| Exit::Safe)
        .map_err(|e| Failure {
            exit: daemon_exit(&e),
            error: Box::new(e),
        })
}

/// A daemon's exit: bad input is the operator's (2), the rest the team's fault (3).
#[cfg(feature = "hosts")]
fn daemon_exit(e: &cdm_hosts::error::DaemonError) -> Exit {
    use cdm_hosts::error::DaemonError as E;
    match e {
        E::Binaries(cdm_team::team::MemberBinaryError::Locate(_)) => Exit::Fault,
        E::NotCertified { .. }
        | E::Binaries(_)
        | E::Scenario(_)
        | E::Security(_)
        | E::Connect(_)
        | E::Refused { .. }
        | E::Priority { .. }
        | E::Services(_) => Exit::BadInput,
        _ => Exit::Fault,
    }
}

/// Without the `hosts` feature there is no daemon.
#[cfg(not(feature = "hosts"))]
fn host_daemon(
    _connect: String,
    _transport: cdm_hosts::Transport,
    _team: Option<String>,
    _host: Option<u32>,
    _scenario: Option<PathBuf>,
    _join_timeout: f64,
    _quiet: bool,
) -> Result<Exit, Failure> {
    Err(Failure::bad_input(
        "host: this orchestrator was built without the `hosts` feature (zenoh)",
    ))
}

/// `orchestrator keys new|add-host`: writes the team's keys and says where each directory goes.
fn keys_command(action: crate::cli::KeysCommand, quiet: bool) -> Result<Exit, Failure> {
    use crate::cli::KeysCommand;
    let dirs = match action {
        KeysCommand::New { dir, daemons } => {
            cdm_keys::new_team(&dir, daemons).map_err(Failure::bad_input)?
        }
        KeysCommand::AddHost { dir } => {
            vec![cdm_keys::add_host(&dir).map_err(Failure::bad_input)?.1]
        }
    };
    if !quiet {
        for d in &dirs {
            let (to, how) = match d.file_name().and_then(|n| n.to_str()) {
                Some("orchestrator") => ("the orchestrator's machine".to_owned(), "launch"),
                Some(h) => (format!("{h}'s machine"), "orchestrator host"),
                None => (String::new(), ""),
            };
            out!("{}: to {to} ({how} --keys {})", d.display(), d.display());
        }
        out!("keep the authority (its ca.key signs new hosts) off the hosts; every file is owner-only");
    }
    Ok(Exit::Safe)
}
