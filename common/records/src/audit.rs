//! The safety audit of a run (Sec. VI, Theorem 3), fed tick by tick with the team's positions,
//! identical for `simulate` and `launch`: collisions (separation < 2 eps), containment (a
//! follower outside the containment prism), tracking (||r_i - r_i,HT||_2 > delta, eq. 34) and
//! deformation (lambda_1(U_D) < lambda_CD,min, eq. 37).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::airspace_audit::AirspaceAudit;
use crate::limit_audit::{FlownLimit, LimitAudit};
use cdm_math::{Real, Vec3};
use cdm_model::formation::Role;
use cdm_model::frame::deformation_eigenvalues;
use cdm_model::limits::scaled;
use cdm_model::outcome::{FaultKind, LossCause, Verdict, ViolationKind};
use cdm_model::repair::Retriangulation;
use cdm_model::safety::{self, Prism};
use cdm_scenario::Scenario;

/// At most this many violation records are kept; the rest are counted.
pub const MAX_VIOLATION_RECORDS: usize = 10_000;

/// The safety numbers of a scenario (Sec. VI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SafetyNumbers {
    /// min over the plan of lambda_1(U_D), and when.
    pub lambda1_min: Real,
    pub t_lambda1_min_s: Real,
    /// lambda_CD,min (eq. 37-38): the scenario's, or the plan's lambda1_min by default.
    pub lambda_cd_min: Real,
    pub d_b_m: Real,
    pub d_s_m: Real,
    /// eq. 35.
    pub delta_max_m: Real,
    /// eq. 38 (or the scenario's `delta_m`).
    pub delta_m: Real,
    pub eps_m: Real,
}

impl SafetyNumbers {
    /// Compute them for a validated scenario.
    pub fn of(s: &Scenario) -> Self {
        // Over every deformation segment of a mission (take-off and landing are certified by
        // their ground separation instead: ARCHITECTURE.md).
        // A commanded plan keeps the launched plan's (`TeamPlan::launched_lambda1_min`): the
        // team is held to the numbers it was certified with through every command.
        let l = s.plan.launched_lambda1_min();
        let d_b_m = safety::d_b(&s.formation);
        let d_s_m = safety::d_s(&s.formation);
        let eps = s.file.eps_m;
        let delta_max_m = safety::delta_max(d_b_m, d_s_m, eps);
        let (lambda_cd_min, delta_m) = match (s.file.lambda_cd_min, s.file.delta_m) {
            (_, Some(d)) => (safety::lambda_from_delta(d, delta_max_m, eps), d),
            (Some(lc), None) => (lc, safety::delta_from_lambda(lc, delta_max_m, eps)),
            (None, None) => (
                l.lambda1,
                safety::delta_from_lambda(l.lambda1, delta_max_m, eps),
            ),
        };
        SafetyNumbers {
            lambda1_min: l.lambda1,
            t_lambda1_min_s: l.t_s,
            lambda_cd_min,
            d_b_m,
            d_s_m,
            delta_max_m,
            delta_m,
            eps_m: eps,
        }
    }
}

/// One safety violation (the tick at which a condition starts to fail for these members).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Violation {
    /// `collision`, `containment`, `tracking`, `deformation`, `geofence`, `obstacle` or
    /// `limit`.
    pub kind: ViolationKind,
    /// `geofence`: the side (`floor`, `ceiling`, `edge K`); `obstacle`: its name; `limit`: the
    /// `[vehicle]` key; `collision` with a downwash ratio: `downwash` (absent for the other
    /// kinds, whose records are as they were).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    pub tick: u64,
    pub t_s: Real,
    pub agents: Vec<u32>,
    /// The measured value and the limit it crossed.
    pub value: Real,
    pub limit: Real,
}

impl Violation {
    /// How messages name it: `collision`, `obstacle "tower"`, `geofence ceiling`.
    pub fn label(&self) -> String {
        match (&self.name, self.kind) {
            (Some(n), ViolationKind::Obstacle) => format!("obstacle {n:?}"),
            (Some(n), k) => format!("{k} {n}"),
            (None, k) => k.to_string(),
        }
    }
}

/// A runtime fault that ended a run early.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct FaultRecord {
    pub kind: FaultKind,
    pub agent: Option<u32>,
    pub peer: Option<u32>,
    pub tick: u64,
    pub message: String,
}

impl FaultRecord {
    /// A fault of `kind` at `tick`, about member `agent` (and `peer`), explained by `message`.
    pub fn new(
        kind: FaultKind,
        agent: Option<u32>,
        peer: Option<u32>,
        tick: u64,
        message: String,
    ) -> Self {
        FaultRecord {
            kind,
            agent,
            peer,
            tick,
            message,
        }
    }
}

/// A member lost in flight and what the repair did (`repair`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LossRecord {
    pub id: u32,
    /// `primary`, `secondary` or `follower` (`unknown`: an id outside the formation).
    #[serde(serialize_with = "role_or_unknown")]
    pub role: Option<Role>,
    /// Why it was lost: `scripted` (`--lose`); in `launch` also `killed` (a signal from
    /// outside), `exited` (the process ended by itself) or `silent` (past `--agent-timeout`);
    /// in real time with MAVLink vehicles `vehicle-lost`, `vehicle-mode` (a pilot took it over)
    /// or `vehicle-disarmed`.
    pub cause: LossCause,
    /// The tick of its last published state (real time: the newest the orchestrator heard).
    pub last_tick: u64,
    /// The repair applies, and its body is out of the audit (separation, tracking,
    /// containment) and telemetry, from this tick: last_tick + 1. In real time the first
    /// audit instant (telemetry's `tick`) after the loss was found.
    pub tick: u64,
    pub t_s: Real,
    /// Real time only: the tick, on each member's own clock, from which its readers fly the
    /// repaired link (a lead after the loss was found, `cdm_runtime::team_realtime`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub repair_tick: Option<u64>,
    /// Followers that switched triangles, with old and new in-neighbours.
    pub retriangulated: Vec<Retriangulation>,
    /// Followers left with no valid triangle: they fly their own plan from this tick.
    pub degraded: Vec<u32>,
    /// The host it ran on (`launch --hosts > 1`; host 0 is the orchestrator's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub host: Option<u32>,
}

/// A loss record's role as audit.json spells it.
fn role_or_unknown<S: serde::Serializer>(role: &Option<Role>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(role.map_or("unknown", Role::as_str))
}

/// audit.json.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AuditReport {
    /// SAFE, UNSAFE (a violation), or FAULT (the run did not complete).
    pub verdict: Verdict,
    pub scenario: String,
    pub agents: usize,
    /// Ticks audited (0..=last, or fewer after a fault).
    pub ticks: u64,
    pub complete: bool,
    pub t_total_s: Real,
    pub dt_s: Real,
    /// The scenario's safety numbers (Sec. VI).
    #[serde(flatten)]
    pub numbers: SafetyNumbers,
    /// lambda_1(U_D) minimum over the audited ticks.
    pub lambda1_min_run: Real,
    /// Largest ||r_i - r_i,HT||_2 over the run, every member (ERRATA 11: the guarantee's norm).
    pub max_deviation_m: Real,
    /// Largest ||r_i - r_i,HT||_inf (the paper's E_max, Sec. VII-D).
    pub max_deviation_inf_m: Real,
    pub max_follower_deviation_m: Real,
    /// Smallest distance between two members over the run.
    pub min_separation_m: Real,
    /// Smallest signed distance of a follower to the prism's side faces over the run.
    pub min_boundary_distance_m: Real,
    /// With `[geofence]`: the smallest margin of a member's ball of radius eps inside the fence
    /// over the run (negative: breached); absent without a fence.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_fence_margin_m: Option<Real>,
    /// With `[[obstacle]]`: the smallest distance of a member's ball to an obstacle.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_obstacle_margin_m: Option<Real>,
    /// With `[vehicle]` `downwash_ratio`: the smallest distance between two members in the
    /// downwash metric sqrt(dx^2 + dy^2 + (dz / ratio)^2), where collisions are then judged.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_downwash_separation_m: Option<Real>,
    /// With `[vehicle]` limits: each limit's largest flown value (`limit_audit.rs`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vehicle_limits: Option<Vec<FlownLimit>>,
    pub violations: Vec<Violation>,
    pub violations_dropped: u64,
    /// The run was ended at its first violation (`--stop-on-violation`).
    pub stopped_on_violation: bool,
    pub fault: Option<FaultRecord>,
    /// Members lost in flight, in order (absent when none: runs without a loss keep the
    /// audit.json they always had).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub losses: Vec<LossRecord>,
    /// The pacing of a real-time flight (`launch --realtime`; absent otherwise, so lockstep and
    /// `simulate` keep the audit.json they always had).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub realtime: Option<RealtimeFigures>,
    /// What each member measured on its real vehicle (`launch --vehicles mavlink`), by member id
    /// (absent otherwise, so other runs keep the audit.json they always had).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub vehicles: BTreeMap<u32, VehicleFigures>,
    /// Commands to the team in flight, in order, and what became of each (absent when none,
    /// so other runs keep the audit.json they always had; the certificates are in
    /// commands.json).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub commands: Vec<CommandSummary>,
}

/// One command to the team in flight, as the audit lists it (and as `commands.rs` reads a run's
/// `commands.json` back: its other fields are ignored).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct CommandSummary {
    /// `hold`, `resume`, `land` or `goto`.
    pub command: String,
    /// When it arrived (simulation time, seconds).
    pub arrived_s: Real,
    /// The tick its motion starts at (accepted or not).
    pub switch_tick: u64,
    /// The certificate's verdict; absent when the command did not apply at all.
    pub verdict: Option<Verdict>,
    pub accepted: bool,
    /// Why it was refused.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub why: Option<String>,
}

/// One member's real vehicle, from its newest vehicle report (cdm-mavlink `report`): the
/// stream's punctuality and the vehicle's ATTITUDE. The tracking error against r_HT is in the
/// audit's own deviation figures, from the measured states.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VehicleFigures {
    /// Setpoints sent to the vehicle (SET_POSITION_TARGET_LOCAL_NED).
    pub setpoints_sent: u64,
    /// Setpoints sent more than one period after their scheduled instant.
    pub late_setpoints: u64,
    /// The latest a setpoint was sent after its instant (ms).
    pub max_setpoint_late_ms: Real,
    /// ATTITUDE messages received.
    pub attitudes_received: u64,
    /// The largest |roll| and |pitch| the vehicle reported (degrees).
    pub max_abs_roll_deg: Real,
    pub max_abs_pitch_deg: Real,
    /// The newest ATTITUDE (roll, pitch, yaw; degrees), absent if none arrived.
    pub last_attitude_deg: Option<[Real; 3]>,
    /// What reached the member's port and was not its vehicle's, dropped: datagrams from
    /// another address, oversized ones, messages of another system or component.
    pub foreign_packets: u64,
    /// With `--mavlink-signing-key`: frames dropped unsigned, signed with another key, or
    /// replayed (0 without a key).
    pub bad_signatures: u64,
    /// The lowest battery the vehicle reported in SYS_STATUS (%, V); absent if none.
    pub lowest_battery_pct: Option<u8>,
    pub lowest_battery_v: Option<Real>,
    /// The last HEARTBEAT's flight mode as its autopilot names it ("OFFBOARD", "POSCTL",
    /// "AUTO.RTL", "GUIDED", "LOITER") and whether it was armed; absent before any HEARTBEAT.
    /// A vehicle taken over shows the mode it left for.
    pub mode: Option<String>,
    pub armed: Option<bool>,
}

/// The pacing figures of a real-time flight, from the members' own reports (their pacing
/// messages) and the monitor's audits (README, "Real time and imperfect links").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RealtimeFigures {
    /// Ticks flown, every member together.
    pub ticks: u64,
    /// Ticks computed more than one period after their instant.
    pub late_ticks: u64,
    /// late_ticks / ticks, in percent.
    pub late_ticks_pct: Real,
    /// Median over the followers of their median neighbour age (own time minus the stamp of the
    /// newest state used; ms, to 0.05 ms).
    pub neighbor_age_ms_p50: Real,
    /// The largest of the followers' 99th percentiles (the worst member's; ms).
    pub neighbor_age_ms_p99: Real,
    /// The oldest neighbour state any follower used (ms).
    pub neighbor_age_ms_max: Real,
    /// In-neighbour states the followers received, and how many of them the impaired links
    /// (`--link-loss`) dropped on purpose (0 with perfect links).
    pub link_states_received: u64,
    pub link_states_lost: u64,
    /// The member with the most late ticks (then the latest tick); absent when none reported.
    pub slowest_member: Option<SlowMember>,
    /// Members whose pacing report the monitor received (of `agents`).
    pub members_reported: usize,
    /// Audit instants (telemetry rows per member) and their rate.
    pub audits: u64,
    pub audit_hz: Real,
    /// The phase seed announced with the start (0: aligned, no offsets).
    pub phase_seed: u32,
    /// The bound on a neighbour's age (s).
    pub stale_after_s: Real,
    /// From the start instant to the last audit (s): a plan of T s takes about T s.
    pub wall_s: Real,
    /// CPU of the whole team over the flight (orchestrator and spawned members, user + system,
    /// from /proc), in cores; absent for hand-started members.
    pub team_cpu_cores: Option<Real>,
    /// The members' states the monitor never received (its subscriber's buffer overflowed on a
    /// burst, a member catching up after a stall): it audited around them, and so does a
    /// replay. Absent when it received every one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unheard: Vec<Unheard>,
}

/// Ticks `from..=to` of member `id` whose states the monitor never received.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Unheard {
    pub id: u32,
    pub from: u64,
    pub to: u64,
}

/// The slowest member of a real-time flight.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SlowMember {
    pub id: u32,
    pub late_ticks: u64,
    /// The latest one of its ticks was computed after its instant (ms).
    pub max_late_ms: Real,
}

/// Which conditions are failing right now: a violation is recorded when one starts.
#[derive(Default)]
struct Failing {
    /// Per member (member order): tracking and containment.
    tracking: Vec<bool>,
    containment: Vec<bool>,
    /// Colliding pairs (sorted ids), sorted.
    collisions: Vec<(u32, u32)>,
    deformation: bool,
}

/// A violation's measured value and the limit it crossed.
#[derive(Debug, Clone, Copy)]
struct Measured {
    value: Real,
    limit: Real,
}

/// The audit accumulator.
pub struct Auditor {
    numbers: SafetyNumbers,
    scenario: Scenario,
    ids: Vec<u32>,
    followers: Vec<usize>,
    polygon: Vec<usize>,
    /// Member order: false from the tick a member's loss applies (its body leaves the audit).
    alive: Vec<bool>,
    failing: Failing,
    report: AuditReport,
    /// Buffers of the collision sweep, kept from tick to tick (no allocation per tick).
    sweep: Sweep,
    /// The geofence and the obstacles, when the scenario has them.
    airspace: Option<AirspaceAudit>,
    /// The `[vehicle]` limits, when the scenario sets them.
    limits: Option<LimitAudit>,
    /// The downwash ratio, when the scenario sets one: collisions in its metric.
    downwash_ratio: Option<Real>,
}

/// The collision sweep's buffers: the bodies' order along x (last tick's order sorts in about
/// N steps, `safety::sort_by_x`), the close pairs by index and by id.
#[derive(Default)]
struct Sweep {
    by_x: Vec<usize>,
    close: Vec<(usize, usize, Real)>,
    pairs: Vec<((u32, u32), Real)>,
    seen: Vec<(u32, u32)>,
    /// The bodies in the downwash metric's Euclidean image (z / ratio).
    scaled: Vec<Vec3>,
}

impl Auditor {
    /// A fresh audit for a scenario.
    pub fn new(scenario: &Scenario) -> Self {
        let numbers = SafetyNumbers::of(scenario);
        let f = &scenario.formation;
        Auditor {
            numbers,
            scenario: scenario.clone(),
            ids: f.members.iter().map(|m| m.id).collect(),
            followers: (0..f.members.len())
                .filter(|&k| f.members[k].role == Role::Follower)
                .collect(),
            polygon: f.polygon.clone(),
            alive: vec![true; f.members.len()],
            failing: Failing {
                tracking: vec![false; f.members.len()],
                containment: vec![false; f.members.len()],
                ..Failing::default()
            },
            report: AuditReport {
                verdict: Verdict::Safe,
                scenario: scenario.file.name.clone(),
                agents: f.members.len(),
                ticks: 0,
                complete: false,
                t_total_s: scenario.file.t_total_s,
                dt_s: scenario.dt_s(),
                numbers,
                lambda1_min_run: Real::INFINITY,
                max_deviation_m: 0.0,
                max_deviation_inf_m: 0.0,
                max_follower_deviation_m: 0.0,
                min_separation_m: Real::INFINITY,
                min_boundary_distance_m: Real::INFINITY,
                min_fence_margin_m: None,
                min_obstacle_margin_m: None,
                min_downwash_separation_m: None,
                vehicle_limits: None,
                violations: Vec::new(),
                violations_dropped: 0,
                stopped_on_violation: false,
                fault: None,
                losses: Vec::new(),
                realtime: None,
                vehicles: BTreeMap::new(),
                commands: Vec::new(),
            },
            sweep: Sweep::default(),
            airspace: AirspaceAudit::new(scenario, numbers.delta_m),
            limits: LimitAudit::new(scenario),
            downwash_ratio: scenario.downwash_ratio(),
        }
    }

    /// The team's plan is commanded in flight from a switch on: the rest of the flight is
    /// audited against `flown` (its plan the same before the switch), with the safety numbers
    /// the team was launched and certified with (a command is certified against them too), as
    /// `simulate --commands` audits the commanded plan from the start.
    pub fn replan(&mut self, flown: &Scenario) {
        self.scenario = flown.clone();
    }

    /// Whether the audit needs the members' velocities ([`Self::observe_velocities`]).
    pub fn wants_velocities(&self) -> bool {
        self.limits.is_some()
    }

    /// Audit the `[vehicle]` limits on one instant's flown velocities (member order); nothing
    /// without limits.
    pub fn observe_velocities(&mut self, tick: u64, t: Real, vel: &[Vec3]) {
        let Some(mut a) = self.limits.take() else {
            return;
        };
        let mut breaches = Vec::new();
        a.observe(t, vel, &self.alive, &self.ids, |b| breaches.push(b));
        for b in breaches {
            let m = Measured {
                value: b.value,
                limit: b.allowed,
            };
            let id = self.ids[b.member];
            let name = Some(b.limit.key().to_string());
            self.record_named(ViolationKind::Limit, name, &[id], (tick, t), m);
        }
        self.report.vehicle_limits = Some(a.flown.clone());
        self.limits = Some(a);
    }

    /// The safety numbers used.
    pub fn numbers(&self) -> &SafetyNumbers {
        &self.numbers
    }

    /// The report so far (running extremes, violations), e.g. for progress display.
    pub fn report(&self) -> &AuditReport {
        &self.report
    }

    /// Violations found so far (recorded and dropped).
    pub fn violation_count(&self) -> u64 {
        self.report.violations.len() as u64 + self.report.violations_dropped
    }

    /// The run is being ended at its first violation (`--stop-on-violation`): the report is
    /// UNSAFE, not complete, and not a fault.
    pub fn stop_on_violation(&mut self) {
        self.report.stopped_on_violation = true;
    }

    /// A member is lost: from `loss.tick` on its body is out of the audit.
    pub fn lose(&mut self, loss: LossRecord) {
        if let Some(k) = self.ids.iter().position(|&id| id == loss.id) {
            self.alive[k] = false;
            self.failing.tracking[k] = false;
            self.failing.containment[k] = false;
            if let Some(a) = &mut self.airspace {
                a.lose(k);
            }
        }
        tracing::warn!(id = loss.id, tick = loss.tick, retriangulated = loss.retriangulated.len(), degraded = ?loss.degraded, "member lost, graph repaired");
        self.report.losses.push(loss);
    }

    /// Record a violation that starts at this tick (allocates only then).
    fn record(&mut self, kind: ViolationKind, agents: &[u32], at: (u64, Real), m: Measured) {
        self.record_named(kind, None, agents, at, m);
    }

    /// [`Self::record`] with the name of what was breached (a fence side, an obstacle).
    fn record_named(
        &mut self,
        kind: ViolationKind,
        name: Option<String>,
        agents: &[u32],
        at: (u64, Real),
        Measured { value, limit }: Measured,
    ) {
        let (tick, t) = at;
        if self.report.violations.len() < MAX_VIOLATION_RECORDS {
            tracing::warn!(kind = kind.as_str(), name = ?name, tick, t_s = t, agents = ?agents, value, limit, "safety violation");
            self.report.violations.push(Violation {
                kind,
                name,
                tick,
                t_s: t,
                agents: agents.to_vec(),
                value,
                limit,
            });
        } else {
            self.report.violations_dropped += 1;
        }
    }

    /// Audit one tick: positions and desired positions in member order.
    pub fn observe(&mut self, tick: u64, t: Real, pos: &[Vec3], ht: &[Vec3]) {
        let n = self.numbers;
        let at = (tick, t);
        self.report.ticks = self.report.ticks.max(tick + 1);
        // Tracking (eq. 34), 2-norm and inf-norm (ERRATA 11).
        for (k, (p, h)) in pos.iter().zip(ht).enumerate() {
            if !self.alive[k] {
                continue;
            }
            let e = p - h;
            let d2 = e.norm();
            let r = &mut self.report;
            r.max_deviation_m = r.max_deviation_m.max(d2);
            r.max_deviation_inf_m = r.max_deviation_inf_m.max(e.amax());
            let bad = d2 > n.delta_m;
            if bad && !self.failing.tracking[k] {
                self.record(
                    ViolationKind::Tracking,
                    &[self.ids[k]],
                    at,
                    Measured {
                        value: d2,
                        limit: n.delta_m,
                    },
                );
            }
            self.failing.tracking[k] = bad;
        }
        for &k in &self.followers {
            if !self.alive[k] {
                continue;
            }
            let d2 = (pos[k] - ht[k]).norm();
            self.report.max_follower_deviation_m = self.report.max_follower_deviation_m.max(d2);
        }
        self.observe_collisions(at, pos);
        // Containment (Theorem 3): the prism over the leaders' desired polygon.
        let verts: Vec<Vec3> = self.polygon.iter().map(|&k| ht[k]).collect();
        if verts.len() >= 3 {
            let normal = (verts[1] - verts[0])
                .cross(&(verts[2] - verts[0]))
                .normalize();
            let prism = Prism::new(verts, normal, n.delta_m + n.eps_m);
            for fi in 0..self.followers.len() {
                let k = self.followers[fi];
                if !self.alive[k] {
                    continue;
                }
                let side = prism.side_distance(&pos[k]);
                let height = prism.height(&pos[k]).abs();
                self.report.min_boundary_distance_m = self.report.min_boundary_distance_m.min(side);
                let outside = side < 0.0 || height > prism.half_height_m;
                if outside && !self.failing.containment[k] {
                    let value = if side < 0.0 {
                        side
                    } else {
                        prism.half_height_m - height
                    };
                    let m = Measured { value, limit: 0.0 };
                    self.record(ViolationKind::Containment, &[self.ids[k]], at, m);
                }
                self.failing.containment[k] = outside;
            }
        }
        let plan = &self.scenario.plan;
        let ground = plan.phases()[plan.piece_at(t).phase].kind.is_ground();
        self.observe_airspace(at, pos, ground);
        self.observe_deformation(at, ground);
    }

    /// Deformation (eq. 37), in the deformation segments only: take-off and landing flatten the
    /// team onto the ground, where separation, not lambda_1, is the argument.
    fn observe_deformation(&mut self, at: (u64, Real), ground: bool) {
        let n = self.numbers;
        if ground {
            self.failing.deformation = false;
            return;
        }
        let l1 = match self.scenario.plan.q_d_at(at.1) {
            Ok((q, _)) => deformation_eigenvalues(&q)[0],
            Err(_) => 0.0,
        };
        self.report.lambda1_min_run = self.report.lambda1_min_run.min(l1);
        let bad = l1 < n.lambda_cd_min - 1e-9;
        if bad && !self.failing.deformation {
            let primaries = [self.ids[0], self.ids[1], self.ids[2]];
            self.record(
                ViolationKind::Deformation,
                &primaries,
                at,
                Measured {
                    value: l1,
                    limit: n.lambda_cd_min,
                },
            );
        }
        self.failing.deformation = bad;
    }

    /// The geofence and the obstacles (`airspace_audit.rs`); nothing without them.
    fn observe_airspace(&mut self, at: (u64, Real), pos: &[Vec3], ground: bool) {
        let Some(mut a) = self.airspace.take() else {
            return;
        };
        // Empty (no allocation) on a tick without a new breach.
        let mut breaches = Vec::new();
        a.observe(pos, &self.alive, ground, |b| breaches.push(b));
        for b in breaches {
            let id = self.ids[b.member];
            let m = Measured {
                value: b.margin_m,
                limit: 0.0,
            };
            self.record_named(b.kind, Some(b.name), &[id], at, m);
        }
        if a.has_fence() {
            self.report.min_fence_margin_m = Some(a.min_fence_margin_m);
        }
        if a.has_obstacles() {
            self.report.min_obstacle_margin_m = Some(a.min_obstacle_margin_m);
        }
        self.airspace = Some(a);
    }

    /// Collisions (every pair of living bodies closer than 2 eps) and the smallest separation.
    fn observe_collisions(&mut self, at: (u64, Real), pos: &[Vec3]) {
        let n = self.numbers;
        let (living, idx): (Vec<Vec3>, Vec<usize>) = if self.report.losses.is_empty() {
            (Vec::new(), Vec::new())
        } else {
            (0..pos.len())
                .filter(|&k| self.alive[k])
                .map(|k| (pos[k], k))
                .unzip()
        };
        let bodies = if self.report.losses.is_empty() {
            pos
        } else {
            &living
        };
        let id_of = |i: usize| self.ids[if idx.is_empty() { i } else { idx[i] }];
        let mut sw = std::mem::take(&mut self.sweep);
        safety::sort_by_x(bodies, &mut sw.by_x);
        let (sep, _, _) = safety::min_separation_sorted(bodies, &sw.by_x);
        self.report.min_separation_m = self.report.min_separation_m.min(sep);
        // With a downwash ratio, collisions are judged in its metric: the Euclidean distance of
        // the bodies with heights divided by the ratio. x is unchanged, so the order holds.
        let bodies = match self.downwash_ratio {
            Some(ratio) => {
                sw.scaled.clear();
                sw.scaled.extend(bodies.iter().map(|p| scaled(p, ratio)));
                let (d, _, _) = safety::min_separation_sorted(&sw.scaled, &sw.by_x);
                let r = &mut self.report;
                r.min_downwash_separation_m =
                    Some(r.min_downwash_separation_m.map_or(d, |m| m.min(d)));
                &sw.scaled
            }
            None => bodies,
        };
        let name = self.downwash_ratio.map(|_| "downwash".to_string());
        close_pairs_sorted(bodies, &sw.by_x, 2.0 * n.eps_m, &mut sw.close);
        sw.pairs.clear();
        sw.pairs.extend(sw.close.iter().map(|&(i, j, d)| {
            let (a, b) = (id_of(i), id_of(j));
            ((a.min(b), a.max(b)), d)
        }));
        // Each pair once (ids are unique): sorted by ids, the order violations are recorded in.
        sw.pairs.sort_unstable_by_key(|p| p.0);
        for &((a, b), d) in &sw.pairs {
            if self.failing.collisions.binary_search(&(a, b)).is_err() {
                let m = Measured {
                    value: d,
                    limit: 2.0 * n.eps_m,
                };
                self.record_named(ViolationKind::Collision, name.clone(), &[a, b], at, m);
            }
        }
        std::mem::swap(&mut self.failing.collisions, &mut sw.seen);
        self.failing.collisions.clear();
        self.failing.collisions.extend(sw.pairs.iter().map(|p| p.0));
        self.sweep = sw;
    }

    /// Record a runtime fault (the run did not complete).
    pub fn fault(&mut self, fault: FaultRecord) {
        tracing::error!(kind = %fault.kind, agent = ?fault.agent, tick = fault.tick, "{}", fault.message);
        self.report.fault = Some(fault);
    }

    /// Adds the pacing figures of a real-time flight.
    pub fn set_realtime(&mut self, figures: RealtimeFigures) {
        self.report.realtime = Some(figures);
    }

    /// Records member `id`'s vehicle figures (its newest report replaces an older one).
    pub fn set_vehicle(&mut self, id: u32, figures: VehicleFigures) {
        self.report.vehicles.insert(id, figures);
    }

    /// The finished report; `complete` when every tick of the plan was audited. A run stopped
    /// at its first violation is UNSAFE (not a fault) although it is not complete.
    pub fn finish(mut self, complete: bool) -> AuditReport {
        let violated = self.violation_count() > 0;
        self.report.complete = complete && self.report.fault.is_none();
        self.report.verdict = if self.report.fault.is_some() {
            Verdict::Fault
        } else if self.report.stopped_on_violation && violated {
            Verdict::Unsafe
        } else if !self.report.complete {
            Verdict::Fault
        } else if violated {
            Verdict::Unsafe
        } else {
            Verdict::Safe
        };
        self.report
    }
}

/// Every pair of points closer than `radius` (sweep along x), with their distance.
pub fn close_pairs(pos: &[Vec3], radius: Real) -> Vec<(usize, usize, Real)> {
    let mut order = Vec::new();
    safety::sort_by_x(pos, &mut order);
    let mut out = Vec::new();
    close_pairs_sorted(pos, &order, radius, &mut out);
    out
}

/// [`close_pairs`] into `out`, with `order` from `safety::sort_by_x`.
fn close_pairs_sorted(
    pos: &[Vec3],
    order: &[usize],
    radius: Real,
    out: &mut Vec<(usize, usize, Real)>,
) {
    out.clear();
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if pos[j].x - pos[i].x >= radius {
                break;
            }
            let d = (pos[j] - pos[i]).norm();
            if d < radius {
                out.push((i.min(j), i.max(j), d));
            }
        }
    }
    out.sort_by_key(|a| (a.0, a.1));
}
