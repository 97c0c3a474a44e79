//! [`MavlinkPlant`]: the member's `Vehicle` seam (cdm-runtime) over a MAVLink vehicle. The
//! real-time member core (`--realtime`: it paces the ticks on the wall clock and counts the late
//! ones) calls `fly_tick_at` with the in-neighbours' states as it would for the model; the plant
//! turns them into the tick's setpoint (`setpoint::setpoint_for`), and its state is the
//! vehicle's newest measurement.
//!
//! One thread per member owns the socket: every `1 / comm_hz` it reads the vehicle's messages,
//! checks the link (loss), and sends the current setpoint (and a HEARTBEAT each second, and the
//! `--arm` commands). So the stream goes on, at comm_hz, while the member waits for its team or
//! its neighbours: PX4 leaves OFFBOARD when setpoints stop for a moment.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use cdm_math::Vec3;
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::Member;
use cdm_model::plan::{PhaseKind, TeamPlan};
use cdm_model::step::{law_for, tick_time, Law, StepConfig, StepFault, TickAt};
use cdm_runtime::messages::VehicleLoss;
use cdm_runtime::seams::{RelinkUnsupported, Vehicle, VehicleFault};

use crate::arming::{ArmStage, VehicleMode};
use crate::battery::BatteryFigures;
use crate::messages::Setpoint;
use crate::setpoint::{hold_at, measured_state, setpoint_for, FeedForward};
use crate::signing::SigningKey;
use crate::udp::{UdpError, UdpLink};
use crate::vehicle::{AttitudeFigures, LinkCounters, MavlinkVehicle, VehicleConfig, VehicleError};

/// How one member's plant is set up.
#[derive(Debug, Clone, PartialEq)]
pub struct PlantConfig {
    /// The link: member id, `--vehicle-origin`, `--arm`, the connect deadline.
    pub vehicle: VehicleConfig,
    /// `H:(P + i)`.
    pub bind: SocketAddr,
    /// The setpoint period, 1 / comm_hz.
    pub period: Duration,
    /// `--mavlink-signing-key`: sign what is sent, take only what is signed with it.
    pub signing: Option<SigningKey>,
    /// `--vehicle-feed-forward`: the acceleration and jerk published with the measured state.
    pub feed_forward: FeedForward,
    /// `--upload-fence`: the geofence items the vehicle must hold before it reports ready.
    pub fence: Option<Vec<crate::fence::FenceItem>>,
}

/// Why the plant could not start (or stopped).
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    #[error(transparent)]
    Udp(#[from] UdpError),
    #[error(transparent)]
    Vehicle(#[from] VehicleError),
    #[error("agent {agent}: interrupted while waiting for its vehicle ({waiting})")]
    Interrupted { agent: u32, waiting: String },
    #[error("agent {agent}: cannot start the vehicle link's thread")]
    Thread {
        agent: u32,
        #[source]
        source: std::io::Error,
    },
}

/// Why `--disarm-at-end` did not see the vehicle landed and disarmed after the flight.
#[derive(Debug, thiserror::Error)]
pub enum DisarmError {
    /// The link failed (its text names the member); shown as the member said it, no more.
    #[error("{0}")]
    Link(PlantError),
    #[error("agent {agent}: --disarm-at-end: the vehicle was not seen disarmed after the flight")]
    NotDisarmed { agent: u32 },
}

/// What the streaming thread and the member share.
#[derive(Debug)]
struct Shared {
    vehicle: MavlinkVehicle,
    setpoint: Setpoint,
    /// The link's first failure (the stream stopped with it).
    fault: Option<PlantError>,
    stop: bool,
    /// The team's arm order arrived (`--arm` waits for it: [`MavlinkPlant::order_arm`]).
    team_ready: bool,
    /// The stream's own punctuality (late setpoints), for the vehicle report.
    sends: SendTimes,
    /// The plan's landing is over (`--disarm-at-end` lands and disarms from then on).
    landing_over: bool,
}

/// How punctually the streaming thread sent its setpoints.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SendTimes {
    /// Setpoints sent more than one period after their scheduled instant.
    pub late: u64,
    /// The latest a setpoint was sent after its instant (s).
    pub max_late_s: f64,
}

/// Where the member's `--arm` sequence is, as the team's arm order sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmProgress {
    /// Not armed yet (or the order has not come).
    Pending,
    /// In OFFBOARD/GUIDED and armed.
    Armed,
    /// No `--arm`: the member only streams; the operator arms.
    StreamOnly,
}

fn lock(shared: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    // A panic in the other thread leaves plain data behind; the fault (if any) is in it.
    shared.lock().unwrap_or_else(|e| e.into_inner())
}

/// A member's MAVLink vehicle behind the `Vehicle` seam.
#[derive(Debug)]
pub struct MavlinkPlant<'a> {
    agent: u32,
    /// `--arm`.
    arm: bool,
    step: StepConfig,
    /// The launched plan, or the commanded one once a command to the team arrived.
    plan: std::borrow::Cow<'a, TeamPlan>,
    law: Law,
    neighbor_ids: [u32; 3],
    shared: Arc<Mutex<Shared>>,
    streamer: Option<JoinHandle<()>>,
    /// The state before the first measurement (the scenario start, hovering).
    x0: QuadState,
    /// `--vehicle-feed-forward`.
    feed_forward: FeedForward,
    /// When the plan's last phase, a landing, ends (none without one).
    landing_end_s: Option<f64>,
}

impl<'a> MavlinkPlant<'a> {
    /// Binds the member's port, starts streaming a hold at its initial position, and returns
    /// once the vehicle is heard (and, with `--arm`, in OFFBOARD/GUIDED and armed). Bounded by
    /// the link's connect deadline and the arming retries.
    pub fn connect(
        config: PlantConfig,
        step: StepConfig,
        plan: &'a TeamPlan,
        member: &Member,
        interrupted: &AtomicBool,
    ) -> Result<Self, PlantError> {
        let agent = config.vehicle.agent;
        // Link id 0: a member has one link (the MAVLink guide's "normally the channel").
        let signing = config.signing.as_ref().map(|k| k.signing_data(0));
        let link = UdpLink::bind(agent, config.bind, signing)?;
        tracing::info!(agent, listen = %link.local_addr(), "waiting for the vehicle");
        let clock = Instant::now();
        let mut vehicle = MavlinkVehicle::new(config.vehicle);
        if let Some(items) = config.fence {
            vehicle.upload_fence(items);
        }
        let shared = Arc::new(Mutex::new(Shared {
            vehicle,
            setpoint: hold_at(member.start),
            fault: None,
            stop: false,
            team_ready: false,
            sends: SendTimes::default(),
            landing_over: false,
        }));
        let for_thread = Arc::clone(&shared);
        let streamer = std::thread::Builder::new()
            .name(format!("mavlink-{agent}"))
            .spawn(move || stream(link, &for_thread, config.period, clock))
            .map_err(|source| PlantError::Thread { agent, source })?;
        let (law, neighbor_ids) = law_for(member);
        let mut plant = MavlinkPlant {
            agent,
            arm: config.vehicle.arm,
            step,
            plan: std::borrow::Cow::Borrowed(plan),
            law,
            neighbor_ids,
            shared,
            streamer: Some(streamer),
            x0: QuadState::hover(member.start),
            feed_forward: config.feed_forward,
            landing_end_s: landing_end_s(plan),
        };
        plant.wait_ready(interrupted)?;
        Ok(plant)
    }

    /// Waits until the vehicle is heard (HEARTBEAT and position). `--arm` waits for the team's
    /// order ([`Self::order_arm`]): the member joins its team only once its vehicle is heard,
    /// and the orchestrator orders the arming once every member has joined.
    fn wait_ready(&mut self, interrupted: &AtomicBool) -> Result<(), PlantError> {
        loop {
            {
                let mut g = lock(&self.shared);
                if let Some(f) = g.fault.take() {
                    return Err(f);
                }
                if interrupted.load(Ordering::Relaxed) {
                    let waiting = if g.vehicle.ready() {
                        format!("heard; --arm at {:?}", g.vehicle.arm_stage())
                    } else {
                        format!("not heard: {:?}", g.vehicle.counters())
                    };
                    return Err(PlantError::Interrupted {
                        agent: self.agent,
                        waiting,
                    });
                }
                if let (true, Some(m)) = (g.vehicle.ready(), g.vehicle.state()) {
                    tracing::info!(agent = self.agent, position = ?m.position, "vehicle ready");
                    return Ok(());
                }
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The member's id.
    pub fn agent(&self) -> u32 {
        self.agent
    }

    /// Whether the member arms its vehicle (`--arm`).
    pub fn arms(&self) -> bool {
        self.arm
    }

    /// The team's arm order: from now on the streaming thread runs `--arm` (mode change, then
    /// arming). Without `--arm` it changes nothing.
    pub fn order_arm(&self) {
        lock(&self.shared).team_ready = true;
    }

    /// Where `--arm` is, or the link's failure (lost vehicle, refused mode or arming).
    pub fn arm_progress(&self) -> Result<ArmProgress, VehicleFault> {
        let g = lock(&self.shared);
        if let Some(f) = &g.fault {
            return Err(Self::link_fault(f));
        }
        Ok(match g.vehicle.arm_stage() {
            ArmStage::StreamOnly => ArmProgress::StreamOnly,
            ArmStage::Armed if g.vehicle.ready_to_fly() => ArmProgress::Armed,
            _ => ArmProgress::Pending,
        })
    }

    /// A handle on the link's figures that outlives handing the plant to the member core.
    pub fn figures(&self) -> LinkFigures {
        LinkFigures(Arc::clone(&self.shared))
    }

    /// The link's message counts so far.
    pub fn counters(&self) -> LinkCounters {
        *lock(&self.shared).vehicle.counters()
    }

    /// The link's failure as the member reports it (the message names the member; a take-over
    /// or a disarm is a loss of its own kind, recorded as its cause).
    fn link_fault(f: &PlantError) -> VehicleFault {
        use crate::health::LinkFault;
        let loss = match f {
            PlantError::Vehicle(VehicleError::Link(LinkFault::LeftMode { .. })) => {
                VehicleLoss::LeftMode
            }
            PlantError::Vehicle(VehicleError::Link(LinkFault::Disarmed { .. })) => {
                VehicleLoss::Disarmed
            }
            _ => VehicleLoss::Lost,
        };
        VehicleFault::Link {
            what: f.to_string(),
            loss,
        }
    }
}

impl SendTimes {
    /// A setpoint sent `late` after its instant (the stream's period `period`).
    fn on_send(&mut self, late: Duration, period: Duration) {
        if late > period {
            self.late += 1;
        }
        self.max_late_s = self.max_late_s.max(late.as_secs_f64());
    }
}

impl Vehicle for MavlinkPlant<'_> {
    /// The newest measurement (one streaming period old at most), in the wire layout, with the
    /// acceleration and jerk of the setpoint in force (`--vehicle-feed-forward commanded`: the
    /// real-time core publishes tick k's state before it flies tick k, so the setpoint in
    /// force is tick k - 1's, r_d at t_k, the published state's time) or zero.
    fn state(&self) -> [f64; 12] {
        let g = lock(&self.shared);
        let (a, j) = match self.feed_forward {
            FeedForward::Commanded => (g.setpoint.acceleration, g.setpoint.jerk),
            FeedForward::Zero => (Vec3::zeros(), Vec3::zeros()),
        };
        let x = g
            .vehicle
            .state()
            .map_or(self.x0, |m| measured_state(m.position, m.velocity, a, j));
        x.0
    }

    fn fly_tick(&mut self, tick: u64, neighbors: &[Flat; 3]) -> Result<(), VehicleFault> {
        let at = TickAt {
            tick,
            offset_s: 0.0,
        };
        self.fly_tick_at(at, neighbors)
    }

    /// Sets the setpoint of the tick that starts now and returns at once: the vehicle flies the
    /// tick on its own; the streaming thread sends the setpoint.
    fn fly_tick_at(&mut self, at: TickAt, neighbors: &[Flat; 3]) -> Result<(), VehicleFault> {
        if let Law::Follower { .. } = self.law {
            for (f, &peer) in neighbors.iter().zip(&self.neighbor_ids) {
                if !f.is_finite() {
                    return Err(StepFault::NeighborNonFinite { peer }.into());
                }
            }
        }
        let t_k = tick_time(at.tick, self.step.dt_s) + at.offset_s;
        let sp = setpoint_for(&self.step, &self.plan, &self.law, t_k, neighbors);
        let mut g = lock(&self.shared);
        if let Some(f) = &g.fault {
            return Err(Self::link_fault(f));
        }
        g.setpoint = sp;
        // The plan's landing is over: the streaming thread lands and disarms the vehicle
        // (`--disarm-at-end`, `landing.rs`).
        if self.landing_end_s.is_some_and(|end_s| t_k >= end_s) {
            g.landing_over = true;
        }
        Ok(())
    }

    /// A repair after a team-mate's loss: the setpoints follow the new in-neighbours with the
    /// new weights (or the plan, for a follower left with no triangle) from the next tick.
    fn relink(&mut self, member: &Member) -> Result<(), RelinkUnsupported> {
        (self.law, self.neighbor_ids) = law_for(member);
        Ok(())
    }

    /// A command to the team in flight: the setpoints follow the commanded plan (the same as
    /// the launched one before its switch), and a land ends in the vehicle's own landing.
    fn replan(&mut self, plan: &TeamPlan) -> Result<(), RelinkUnsupported> {
        self.landing_end_s = landing_end_s(plan);
        self.plan = std::borrow::Cow::Owned(plan.clone());
        Ok(())
    }
}

/// When `plan`'s last phase, a landing, ends (none without one).
fn landing_end_s(plan: &TeamPlan) -> Option<f64> {
    (plan.phases().last())
        .filter(|p| p.kind == PhaseKind::Landing)
        .map(|p| p.t_end_s())
}

impl Drop for MavlinkPlant<'_> {
    fn drop(&mut self) {
        lock(&self.shared).stop = true;
        if let Some(h) = self.streamer.take() {
            let _ = h.join();
        }
        let c = self.counters();
        tracing::info!(
            agent = self.agent,
            setpoints_sent = c.setpoints_sent,
            heartbeats_received = c.heartbeats_received,
            positions_received = c.positions_received,
            "vehicle link closed"
        );
    }
}

/// What [`LinkFigures::read`] reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkRead {
    pub counters: LinkCounters,
    pub attitude: AttitudeFigures,
    pub battery: BatteryFigures,
    pub sends: SendTimes,
    /// The last HEARTBEAT's mode and armed state (`None` before the first).
    pub mode: Option<VehicleMode>,
}

/// A read-only view of a plant's link for the vehicle report (`crate::report`).
#[derive(Debug, Clone)]
pub struct LinkFigures(Arc<Mutex<Shared>>);

impl LinkFigures {
    /// The link's counters, newest attitude and extremes, battery, the stream's punctuality,
    /// and the last HEARTBEAT's mode and armed state.
    pub fn read(&self) -> LinkRead {
        let g = lock(&self.0);
        let v = &g.vehicle;
        LinkRead {
            counters: *v.counters(),
            attitude: v.attitude_figures(),
            battery: v.battery_figures(),
            sends: g.sends,
            mode: v.mode().copied(),
        }
    }

    /// After the flight (`--disarm-at-end`): waits until the landing ordered at the end of the
    /// plan's landing has seen the vehicle disarmed, while the streaming thread goes on. Ok at
    /// once when no landing was ordered (no `--disarm-at-end`, or a team stopped before its
    /// landing ended). The landing's own deadline (`landing::LANDING_DEADLINE`, counted from
    /// its order) ends the wait with the link's fault; this wait is bounded by it too.
    pub fn wait_landed(&self, interrupted: &AtomicBool) -> Result<(), DisarmError> {
        let until = Instant::now() + crate::landing::LANDING_DEADLINE + LANDED_MARGIN;
        loop {
            {
                // The member ends with this wait: the fault is its to report, taken from here.
                let mut g = lock(&self.0);
                if let Some(f) = g.fault.take() {
                    return Err(DisarmError::Link(f));
                }
                if g.vehicle.landing_done() {
                    return Ok(());
                }
            }
            if interrupted.load(Ordering::Relaxed) || Instant::now() >= until {
                let agent = lock(&self.0).vehicle.agent();
                return Err(DisarmError::NotDisarmed { agent });
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// A margin over the landing's deadline for [`LinkFigures::wait_landed`] (the streaming thread
/// reports the deadline at its next tick).
const LANDED_MARGIN: Duration = Duration::from_secs(1);

/// The streaming thread: every `period`, read, check, send. Ends on `stop` or the first fault
/// (kept in `shared` for the member).
fn stream(mut link: UdpLink, shared: &Mutex<Shared>, period: Duration, clock: Instant) {
    let mut next = clock.elapsed();
    let mut flooded;
    loop {
        let now = clock.elapsed();
        let out = {
            let mut g = lock(shared);
            if g.stop {
                return;
            }
            let (sp, team_ready) = (g.setpoint, g.team_ready);
            let g = &mut *g;
            if g.landing_over {
                g.vehicle.on_landing_over(now);
            }
            g.sends.on_send(now.saturating_sub(next), period);
            let r = link.receive(now, &mut g.vehicle).map_err(PlantError::from);
            let r = r.and_then(|got| Ok((got, g.vehicle.on_tick(now, Some(&sp), team_ready)?)));
            if let Some(warning) = g.vehicle.take_warning() {
                tracing::warn!("{warning}");
            }
            match r {
                Ok((got, out)) => {
                    flooded = got.foreign > 0;
                    out
                }
                Err(e) => {
                    tracing::warn!("{e}");
                    g.fault = Some(e);
                    return;
                }
            }
        };
        if let Err(e) = link.send(&out) {
            tracing::warn!("{e}");
            lock(shared).fault = Some(e.into());
            return;
        }
        // Fixed-rate schedule (the average rate is comm_hz); after a long stall, no burst.
        next += period;
        let now = clock.elapsed();
        match next.checked_sub(now) {
            Some(_) if flooded => drain_until(&mut link, shared, clock, next),
            Some(wait) => std::thread::sleep(wait),
            None if now - next > period * 5 => next = now,
            None => {}
        }
    }
}

/// How often the socket is drained between two ticks while foreign datagrams arrive.
const DRAIN_EVERY: Duration = Duration::from_millis(1);

/// Waits until `until` on `clock`, draining the socket every [`DRAIN_EVERY`] while foreign
/// datagrams keep arriving (a flood on the port): read only once a tick, a flood of large
/// datagrams fills the kernel's receive buffer ([`crate::udp::RECEIVE_BUFFER_BYTES`] asked,
/// `net.core.rmem_max` granted: three 64 KiB datagrams on a stock kernel) between two ticks,
/// and the kernel then drops the vehicle's own packets with the rest. Once a drain finds
/// nothing foreign, the rest of the wait is one sleep. A receive error here is left to the next
/// tick's receive, which reports it.
fn drain_until(link: &mut UdpLink, shared: &Mutex<Shared>, clock: Instant, until: Duration) {
    loop {
        let Some(left) = until.checked_sub(clock.elapsed()) else {
            return;
        };
        std::thread::sleep(left.min(DRAIN_EVERY));
        if left <= DRAIN_EVERY {
            return;
        }
        // Its own statement: the guard is dropped here, not held through the sleep below.
        let got = link.receive(clock.elapsed(), &mut lock(shared).vehicle);
        match got {
            Ok(got) if got.foreign > 0 => {}
            Ok(_) => {
                if let Some(rest) = until.checked_sub(clock.elapsed()) {
                    std::thread::sleep(rest);
                }
                return;
            }
            Err(_) => return,
        }
    }
}
