//! One team member as a process: the member core (cdm-runtime, no I/O) flown over the iceoryx2
//! ports by the generic loop. This file only loads the scenario, checks the binary flies this
//! member's role, opens the ports and maps the outcome to a typed error (the binary prints it
//! and exits with its code).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use cdm_runtime::member_core::{in_neighbors, subscriptions};
use cdm_runtime::member_lockstep::LockstepCore;
use cdm_runtime::member_loop::{fly, BeforePublish};
use cdm_runtime::member_loss::MemberLosses;
use cdm_runtime::member_steer::MemberSteering;
use cdm_runtime::realtime::{RealtimeCore, RealtimeSetup};
use cdm_runtime::seams::{Clock, LockstepClock, ModelVehicle, MonotonicClock};

use crate::member_vehicle::BeforeStart;
use crate::options::LinkOverrides;
use crate::vehicles::Vehicles;
use cdm_iox::{MemberPorts, TeamName};
use cdm_model::dynamics::QuadState;
use cdm_model::formation::{Member, Role};
use cdm_records::loss_log::LossLog;
use cdm_scenario::{Checks, Scenario};

pub use crate::member_error::MemberError;
pub use cdm_runtime::member_core::{Deadlines, Finished, MemberFault};

/// A member's default silence timeout, seconds (the orchestrator passes a longer one only when
/// its own `--agent-timeout` asks for more patience).
pub const DEFAULT_SILENCE_TIMEOUT_S: f64 = 10.0;

/// Which binary is running: `leader` flies primary and secondary leaders, `agent` flies followers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Binary {
    Leader,
    Agent,
}

impl Binary {
    fn accepts(self, role: Role) -> bool {
        match self {
            Binary::Leader => role.is_leader(),
            Binary::Agent => role == Role::Follower,
        }
    }

    /// The binary's name (`leader`, `agent`).
    pub fn name(self) -> &'static str {
        match self {
            Binary::Leader => "leader",
            Binary::Agent => "agent",
        }
    }
}

/// How the member flies: on the orchestrator's grants (the default) or on its own clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    Lockstep,
    /// `--realtime`: a neighbour whose newest state is older than `stale_after` is a fault.
    Realtime {
        stale_after: Duration,
    },
}

/// How a member flies: its deadlines, lockstep or real time, and what it flies.
#[derive(Debug, Clone, PartialEq)]
pub struct Flight {
    pub deadlines: Deadlines,
    pub mode: Mode,
    pub vehicles: Vehicles,
    /// `--record DIR`: where a real-time member writes its recording.
    pub record: Option<std::path::PathBuf>,
}

/// One member process, every value checked: which binary, the scenario file, the team and the
/// member to fly, the links it flies over and how it flies.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberConfig {
    pub binary: Binary,
    pub scenario: PathBuf,
    pub team: TeamName,
    pub id: u32,
    pub links: LinkOverrides,
    pub flight: Flight,
}

/// Run one member until the orchestrator stops the team.
pub fn run(config: &MemberConfig, interrupted: &AtomicBool) -> Result<Finished, MemberError> {
    let MemberConfig {
        binary,
        ref scenario,
        ref team,
        id,
        links,
        ref flight,
    } = *config;
    let Flight {
        deadlines,
        mode,
        ref vehicles,
        ref record,
    } = *flight;
    let s = Scenario::load(scenario, Checks::Member)?;
    let s = links.apply(&s)?;
    if let Mode::Realtime { stale_after } = mode {
        if let Some(refusal) = crate::options::realtime_links_refusal(&s, stale_after) {
            return Err(MemberError::StaleLinks(refusal));
        }
    }
    let Some(me) = s.formation.member(id).cloned() else {
        return Err(MemberError::NotInScenario {
            id,
            origin: s.origin.clone(),
        });
    };
    if !binary.accepts(me.role) {
        return Err(MemberError::WrongRole {
            id,
            role: me.role.as_str(),
            binary: binary.name(),
            flies: if binary == Binary::Leader {
                "primary and secondary leaders"
            } else {
                "followers"
            },
            origin: s.origin.clone(),
        });
    }
    let member = Joined {
        s: &s,
        me: &me,
        team,
        deadlines,
        mode,
        record: record.as_deref(),
    };
    match vehicles {
        Vehicles::Model => member.fly(
            ModelVehicle::new(s.step_config(), &s.plan, &me),
            interrupted,
        ),
        // The vehicle first: the team starts only once every member's vehicle is heard (and
        // armed with --arm), since a member joins only then.
        Vehicles::Mavlink(o) => {
            vehicles.check(&s)?;
            let plant = crate::vehicles::connect(&s, &me, o, deadlines.join, interrupted)?;
            member.fly(plant, interrupted)
        }
    }
}

/// A member about to join its team.
struct Joined<'a> {
    s: &'a Scenario,
    me: &'a Member,
    team: &'a TeamName,
    deadlines: Deadlines,
    mode: Mode,
    record: Option<&'a Path>,
}

impl Joined<'_> {
    /// Opens the ports and flies `vehicle` until the team stops.
    fn fly<V: BeforeStart>(
        &self,
        vehicle: V,
        interrupted: &AtomicBool,
    ) -> Result<Finished, MemberError> {
        let (s, me, team, id) = (self.s, self.me, self.team, self.me.id);
        let hash = s.content_hash();
        let ins = subscriptions(me);
        let outs = s.formation.readers_of(id);
        let mut ports = MemberPorts::open(team, id, hash, &ins, &outs)?;
        tracing::info!(
            id,
            role = me.role.as_str(),
            team = %team,
            subscribes = ?ins,
            notifies = ?outs,
            "joined: subscribed to state services of {:?}",
            ins
        );
        // The deadlines start once the ports are open (opening takes seconds at N = 1000).
        let clock = MonotonicClock::start();
        let deadlines = self.deadlines;
        if let Mode::Realtime { stale_after } = self.mode {
            let setup = RealtimeSetup {
                hash,
                last: s.last_tick(),
                dt_s: s.dt_s(),
                stale_after,
                deadlines,
                links: s.link_model(),
            };
            let waits = (&clock, deadlines.join);
            let first = vehicle.before_start(&mut ports, hash, waits, interrupted)?;
            let link = vehicle.link();
            let at_rest = neighbor_positions(s, me);
            let losses = MemberLosses::new(me, LossLog::new(s), &ins, &outs);
            let mut core = RealtimeCore::realtime(me, at_rest, setup, vehicle, clock.now())
                .with_losses(losses)
                .with_steering(MemberSteering::new(s.steering(), s.file.comm_hz));
            if let Some(dir) = self.record {
                core = core.with_journal(Box::new(self.recording(dir)?));
            }
            let done = crate::member_vehicle::fly(
                &mut core,
                &mut ports,
                (first, link.clone()),
                &clock,
                interrupted,
            )
            .map_err(|e| MemberError::from_loop(e, id, team))?;
            // The vehicle (still in `core`, its link streaming) lands and disarms after the
            // plan's landing (`--disarm-at-end`): the process ends once it has.
            if let Some(link) = link {
                link.wait_landed(interrupted)
                    .map_err(MemberError::Landing)?;
            }
            return Ok(done);
        }
        let parts = (vehicle, LockstepClock::default());
        let starts = in_neighbors(me)
            .map(|n| QuadState::hover(s.formation.member(n).map_or(me.start, |m| m.start)).flat());
        let mut core = LockstepCore::new(me, hash, s.last_tick(), parts, deadlines, clock.now())
            .with_links(s.link_model(), &s.step_config(), starts)
            .with_losses(MemberLosses::new(me, LossLog::new(s), &ins, &outs))
            .with_steering(MemberSteering::new(s.steering(), s.file.comm_hz));
        let inject = cdm_process::fault_inject::from_env(id);
        let hook = inject.map(|i| move |m: &mut cdm_runtime::messages::StateMsg| i.apply(m));
        let hook = hook.as_ref().map(|h| h as BeforePublish);
        fly(&mut core, &mut ports, &clock, interrupted, hook)
            .map_err(|e| MemberError::from_loop(e, id, team))
    }
}

impl Joined<'_> {
    /// This member's recording in `dir` (`--record`).
    fn recording(&self, dir: &Path) -> Result<cdm_recording::McapJournal, MemberError> {
        let (s, me) = (self.s, self.me);
        let path = dir.join(cdm_recording::file_name(me.id));
        let leader = !cdm_runtime::member_core::subscriptions(me).is_empty();
        cdm_recording::McapJournal::create(&path, (me.id, !leader), s.content_hash(), s.dt_s())
            .map_err(MemberError::Recording)
    }
}

/// A follower's in-neighbours' initial positions, in the order of its law (a real-time follower
/// assumes them at rest there until their first state arrives); zeros for a leader.
fn neighbor_positions(s: &Scenario, me: &cdm_model::formation::Member) -> [cdm_math::Vec3; 3] {
    let mut at = [cdm_math::Vec3::zeros(); 3];
    if let Some(link) = me.link.filter(|_| me.role == Role::Follower) {
        for (p, j) in at.iter_mut().zip(link.in_neighbors) {
            if let Some(m) = s.formation.member(j) {
                *p = m.position;
            }
        }
    }
    at
}
