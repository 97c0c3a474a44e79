//! The arguments of a member process (`agent`, `leader`), checked into cdm-member's
//! `MemberConfig` before anything runs.

use std::path::PathBuf;

use cdm_iox::{TeamName, TransportError};
use cdm_member::member::DEFAULT_SILENCE_TIMEOUT_S;
use cdm_member::member::{Binary, Deadlines, Flight, MemberConfig, Mode};

use crate::link_args::LinkArgs;
use crate::timeout::{timeout, TimeoutError};
use crate::vehicle_args::{VehicleArgs, VehicleArgsError};

/// Arguments of a member process (`agent` or `leader`).
#[derive(Debug, Clone, clap::Parser)]
#[command(
    version,
    about = "One quadcopter of a continuum-deformation team, as a process"
)]
pub struct MemberArgs {
    /// The team's scenario file (the run directory's scenario.toml, or the same file the
    /// orchestrator was given).
    #[arg(long, value_name = "FILE")]
    pub scenario: PathBuf,
    /// The team to join (the orchestrator's --team).
    #[arg(long)]
    pub team: String,
    /// This quadcopter's id in the scenario.
    #[arg(long)]
    pub id: u32,
    /// Seconds to wait for the team to start (at most 86400).
    #[arg(
        long = "join-timeout",
        allow_negative_numbers = true,
        default_value_t = 300.0
    )]
    pub join_timeout_s: f64,
    /// Seconds without progress mid-run before stopping (at most 86400).
    #[arg(
        long = "silence-timeout",
        allow_negative_numbers = true,
        default_value_t = DEFAULT_SILENCE_TIMEOUT_S
    )]
    pub silence_timeout_s: f64,
    #[command(flatten)]
    pub link: LinkArgs,
    /// Fly in real time on this process's own clock, from the start instant the orchestrator
    /// announces (its `launch --realtime`), with no grant and no barrier.
    #[arg(long)]
    pub realtime: bool,
    /// With --realtime: seconds after which an in-neighbour's newest state is too old (a fault:
    /// reported, and this member holds position).
    #[arg(
        long = "stale-after",
        allow_negative_numbers = true,
        default_value_t = 0.5,
        value_name = "SECONDS"
    )]
    pub stale_after_s: f64,
    /// With --realtime: run this member under SCHED_FIFO at this priority (1-99), so its
    /// wake-ups preempt ordinary processes (needs root, CAP_SYS_NICE or `ulimit -r`).
    #[arg(long = "rt-priority", value_name = "P", value_parser = clap::value_parser!(u8).range(cdm_process::sched::RT_PRIORITIES))]
    pub rt_priority: Option<u8>,
    /// What this member flies (the model, or a MAVLink vehicle: needs --realtime).
    #[command(flatten)]
    pub vehicle: VehicleArgs,
    /// With --realtime: write this member's recording (the neighbour states each tick flew on,
    /// for `orchestrator replay`) as DIR/<id>.mcap.
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
}

/// Why a member's arguments are refused (bad input: exit 2). Each names its option.
#[derive(Debug, thiserror::Error)]
pub enum ArgsError {
    #[error("--team: {0}")]
    Team(TransportError),
    #[error(transparent)]
    Timeout(#[from] TimeoutError),
    #[error(transparent)]
    Vehicles(#[from] VehicleArgsError),
    /// Lockstep is paced by grants, not by wake-ups on time.
    #[error("member {id}: --rt-priority needs --realtime")]
    PriorityWithoutRealtime { id: u32 },
    /// `SCHED_FIFO` refused (not root, no CAP_SYS_NICE, `ulimit -r` too low).
    #[error("member {id}: {error}: {}", error.source)]
    Priority {
        id: u32,
        error: cdm_process::sched::SchedError,
    },
    /// A lockstep flight is replayed without one.
    #[error("--record needs --realtime (a lockstep flight is replayed without one)")]
    RecordWithoutRealtime,
}

impl MemberArgs {
    /// The arguments checked, in the order a member has always refused them (the team, the
    /// timeouts, the vehicles, the stale bound, the priority, the recording).
    pub fn config(self, binary: Binary) -> Result<MemberConfig, ArgsError> {
        let team = TeamName::new(&self.team).map_err(ArgsError::Team)?;
        let deadlines = Deadlines {
            join: timeout("--join-timeout", self.join_timeout_s)?,
            silence: timeout("--silence-timeout", self.silence_timeout_s)?,
        };
        let vehicles = self.vehicle.validate(self.realtime)?;
        let mode = if self.realtime {
            Mode::Realtime {
                stale_after: timeout("--stale-after", self.stale_after_s)?,
            }
        } else {
            Mode::Lockstep
        };
        if self.rt_priority.is_some() && !self.realtime {
            return Err(ArgsError::PriorityWithoutRealtime { id: self.id });
        }
        if self.record.is_some() && !self.realtime {
            return Err(ArgsError::RecordWithoutRealtime);
        }
        Ok(MemberConfig {
            binary,
            scenario: self.scenario,
            team,
            id: self.id,
            links: self.link.overrides(),
            flight: Flight {
                deadlines,
                mode,
                vehicles,
                record: self.record,
            },
        })
    }
}

/// `--rt-priority`, applied before the member opens anything so its threads inherit it.
pub fn realtime_priority(id: u32, priority: Option<u8>) -> Result<(), ArgsError> {
    match priority {
        None => Ok(()),
        Some(p) => cdm_process::sched::fifo(p).map_err(|error| ArgsError::Priority { id, error }),
    }
}
