//! One member's MAVLink link, standing alone: stream a straight-line plan (the quintic of
//! eq. 16 from `--from` to `--to`) to one vehicle at comm_hz, read its measured state, and
//! print a JSON summary. It exercises everything the member loop will use: binding `H:(P + i)`,
//! replying to the vehicle's address, the loss detector and `--arm`.
//!
//! How to run (two terminals, loopback):
//!   Terminal 1: cargo run --release -p cdm-mavlink --example follow_setpoints -- \
//!                 --index 0 --from 0,0,2 --to 2,1,3
//!   Terminal 2: .venv/bin/python tests/python/mavlink_vehicle.py --port 14540 --start-ned 0,0,-2
//!
//! Exit codes: 0 plan flown, 2 bad arguments, 3 the vehicle link failed (message names the member).

use std::net::IpAddr;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use cdm_math::{Real, Vec3};
use cdm_mavlink::{
    member_addr, LinkTimeouts, MavlinkVehicle, Setpoint, UdpLink, VehicleConfig, VehicleFrame,
    VehicleOrigin, DEFAULT_BASE_PORT, DEFAULT_HEARTBEAT_TIMEOUT, DEFAULT_POSITION_TIMEOUT,
};
use cdm_model::plan::{Quintic, Segment};
use clap::Parser;

#[derive(Debug, Parser)]
#[command(about = "Stream a straight-line plan to one MAVLink vehicle and report how it went")]
struct Args {
    /// The member's id (named in faults).
    #[arg(long, default_value_t = 0)]
    agent: u32,
    /// The member's index in scenario order: it listens on base port + index.
    #[arg(long, default_value_t = 0)]
    index: u32,
    #[arg(long, default_value = "127.0.0.1")]
    mavlink_host: IpAddr,
    #[arg(long, default_value_t = DEFAULT_BASE_PORT)]
    mavlink_base_port: u16,
    /// Scenario coordinates (ENU, m) of the vehicle's NED origin: x,y,z.
    #[arg(long, default_value = "0,0,0")]
    vehicle_origin: String,
    /// Start of the line (ENU, m): x,y,z.
    #[arg(long)]
    from: String,
    /// End of the line (ENU, m): x,y,z.
    #[arg(long)]
    to: String,
    /// Duration of the motion (s).
    #[arg(long, default_value_t = 3.0)]
    move_s: Real,
    /// Time holding the goal after the motion (s).
    #[arg(long, default_value_t = 1.0)]
    hold_s: Real,
    /// Setpoint rate (Hz).
    #[arg(long, default_value_t = 50.0)]
    comm_hz: Real,
    /// Switch the vehicle to OFFBOARD/GUIDED and arm it; otherwise stream only.
    #[arg(long)]
    arm: bool,
    /// How long to wait for the vehicle's first HEARTBEAT and position (s).
    #[arg(long, default_value_t = 10.0)]
    connect_timeout_s: Real,
    /// No HEARTBEAT for this long (s): the vehicle is lost (the members' --heartbeat-timeout).
    #[arg(long = "heartbeat-timeout", default_value_t = DEFAULT_HEARTBEAT_TIMEOUT.as_secs_f64(), allow_negative_numbers = true)]
    heartbeat_timeout_s: Real,
    /// No LOCAL_POSITION_NED for this long (s): the vehicle is lost (--position-timeout).
    #[arg(long = "position-timeout", default_value_t = DEFAULT_POSITION_TIMEOUT.as_secs_f64(), allow_negative_numbers = true)]
    position_timeout_s: Real,
}

/// The validated run.
struct Run {
    config: VehicleConfig,
    bind: std::net::SocketAddr,
    from: Vec3,
    to: Vec3,
    quintic: Quintic,
    period: Duration,
    ticks: u64,
}

fn parse_vec3(flag: &str, text: &str) -> anyhow::Result<Vec3> {
    let parts: Vec<&str> = text.split(',').collect();
    let [x, y, z] = parts.as_slice() else {
        bail!("--{flag} {text:?}: expected three numbers x,y,z");
    };
    let num = |s: &str| -> anyhow::Result<Real> {
        let v: Real = s
            .trim()
            .parse()
            .with_context(|| format!("--{flag} {text:?}: {s:?} is not a number"))?;
        anyhow::ensure!(v.is_finite(), "--{flag} {text:?}: {s:?} is not finite");
        Ok(v)
    };
    Ok(Vec3::new(num(x)?, num(y)?, num(z)?))
}

fn positive_s(flag: &str, v: Real) -> anyhow::Result<Duration> {
    anyhow::ensure!(
        v.is_finite() && v > 0.0 && v < 3600.0,
        "--{flag} {v}: must be in (0, 3600)"
    );
    Ok(Duration::from_secs_f64(v))
}

fn validate(a: &Args) -> anyhow::Result<Run> {
    let period = positive_s("comm-hz", 1.0 / a.comm_hz)?;
    positive_s("move-s", a.move_s)?;
    anyhow::ensure!(
        a.hold_s.is_finite() && a.hold_s >= 0.0,
        "--hold-s {}: must be >= 0",
        a.hold_s
    );
    let connect_deadline = positive_s("connect-timeout-s", a.connect_timeout_s)?;
    let config = VehicleConfig {
        agent: a.agent,
        frame: VehicleFrame::Local(VehicleOrigin(parse_vec3(
            "vehicle-origin",
            &a.vehicle_origin,
        )?)),
        arm: a.arm,
        connect_deadline,
        timeouts: LinkTimeouts {
            heartbeat: positive_s("heartbeat-timeout", a.heartbeat_timeout_s)?,
            position: positive_s("position-timeout", a.position_timeout_s)?,
        },
        min_battery_pct: None,
        // One member and a straight line: no mission, so no take-off or landing.
        takeoff: None,
        disarm_at_end: false,
    };
    // Ticks 0..=ticks cover [0, move + hold] at comm_hz.
    let ticks = ((a.move_s + a.hold_s) * a.comm_hz).round() as u64;
    Ok(Run {
        config,
        bind: member_addr(a.agent, a.mavlink_host, a.mavlink_base_port, a.index)?,
        from: parse_vec3("from", &a.from)?,
        to: parse_vec3("to", &a.to)?,
        quintic: Quintic {
            t_total_s: a.move_s,
        },
        period,
        ticks,
    })
}

/// r_d(t) on the line and its first three derivatives (eq. 16 scaled by to - from).
fn setpoint(run: &Run, t: Real) -> Setpoint {
    let segment = if t <= run.quintic.t_total_s {
        Segment::Motion
    } else {
        Segment::Hold
    };
    let [s, ds, dds, ddds, _] = run.quintic.derivatives(t, segment);
    let d = run.to - run.from;
    Setpoint {
        position: run.from + d * s,
        velocity: d * ds,
        acceleration: d * dds,
        jerk: d * ddds,
    }
}

/// Wait (polling the socket every period) until the vehicle has been heard.
fn connect(
    link: &mut UdpLink,
    vehicle: &mut MavlinkVehicle,
    clock: Instant,
    period: Duration,
) -> anyhow::Result<()> {
    while !vehicle.ready() {
        let now = clock.elapsed();
        link.receive(now, vehicle)?;
        let out = vehicle.on_tick(now, None, false)?;
        link.send(&out)?;
        std::thread::sleep(period);
    }
    Ok(())
}

/// Stream ticks 0..=run.ticks, each at its own deadline (late ticks are sent at once, never
/// skipped, so the average rate is comm_hz).
fn stream(
    run: &Run,
    link: &mut UdpLink,
    vehicle: &mut MavlinkVehicle,
    clock: Instant,
) -> anyhow::Result<u64> {
    let t0 = clock.elapsed();
    let mut late = 0;
    for k in 0..=run.ticks {
        let k32 = u32::try_from(k).context("too many ticks")?;
        let due = t0 + run.period * k32;
        match due.checked_sub(clock.elapsed()) {
            Some(wait) => std::thread::sleep(wait),
            None => late += 1,
        }
        let now = clock.elapsed();
        link.receive(now, vehicle)?;
        let sp = setpoint(run, (run.period * k32).as_secs_f64());
        let out = vehicle.on_tick(now, Some(&sp), vehicle.ready())?;
        link.send(&out)?;
    }
    Ok(late)
}

fn summary(run: &Run, link: &UdpLink, vehicle: &MavlinkVehicle, late: u64) -> serde_json::Value {
    let c = vehicle.counters();
    let pos = vehicle.state().map(|s| s.position);
    serde_json::json!({
        "agent": vehicle.agent(),
        "listen": link.local_addr().to_string(),
        "peer": link.peer().map(|p| p.to_string()),
        "goal": [run.to.x, run.to.y, run.to.z],
        "final_position": pos.map(|p| [p.x, p.y, p.z]),
        "final_error_m": pos.map(|p| (p - run.to).norm()),
        "arm_stage": format!("{:?}", vehicle.arm_stage()),
        "late_ticks": late,
        "setpoints_sent": c.setpoints_sent,
        "heartbeats_sent": c.heartbeats_sent,
        "commands_sent": c.commands_sent,
        "heartbeats_received": c.heartbeats_received,
        "positions_received": c.positions_received,
        "attitudes_received": c.attitudes_received,
    })
}

/// How the run failed: the arguments (exit 2) or the vehicle link (exit 3).
#[derive(Debug, thiserror::Error)]
enum RunError {
    #[error(transparent)]
    BadInput(anyhow::Error),
    #[error(transparent)]
    Link(anyhow::Error),
}

fn run(args: &Args) -> Result<(), RunError> {
    let run = validate(args).map_err(RunError::BadInput)?;
    let agent = run.config.agent;
    let mut link =
        UdpLink::bind(agent, run.bind, None).map_err(|e| RunError::BadInput(e.into()))?;
    let mut vehicle = MavlinkVehicle::new(run.config);
    let clock = Instant::now();
    eprintln!("agent {agent}: listening on {}", link.local_addr());
    connect(&mut link, &mut vehicle, clock, run.period).map_err(RunError::Link)?;
    eprintln!("agent {agent}: vehicle heard from {:?}", link.peer());
    let late = stream(&run, &mut link, &mut vehicle, clock).map_err(RunError::Link)?;
    println!("{}", summary(&run, &link, &vehicle, late));
    Ok(())
}

fn main() -> ExitCode {
    match run(&Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(RunError::BadInput(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
        Err(RunError::Link(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(3)
        }
    }
}
