//! Scenario files (TOML) and the validated scenario the engine and processes fly.
//!
//! `ScenarioFile` is the file's shape (serde, `deny_unknown_fields`); `Scenario` is what remains
//! after validation, projection onto the leaders' plane and graph synthesis. Writing
//! `Scenario::file` back out gives the scenario actually flown (`scenario.toml`).

mod airspace;
mod builtin;
mod commands;
mod fields;
mod flight;
mod locate;
mod mission;
mod origin;
mod validate;
mod vehicle;

use std::path::Path;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use cdm_math::Real;
use cdm_model::formation::{Formation, FormationError, Role};
use cdm_model::graph::SynthesisError;
use cdm_model::link::{LinkModel, LinkSpec};
use cdm_model::plan::TeamPlan;

pub use airspace::{has_airspace, GeofenceSpec, ObstacleShapeError, ObstacleSpec};
pub use builtin::{generated, paper40, TeamSizeError, MAX_AGENTS};
pub use commands::{
    check_command, load_commands, parse_commands, CommandSpec, CommandsError, TimedCommand,
};
pub use fields::{MAX_COORD_M, MAX_TICKS};
pub use mission::{closest_ground_pair, GroundSpec, SegmentSpec};
pub use origin::{GeoOrigin, GeoPoint};
pub use vehicle::VehicleSpec;

/// Default tolerance for members off the primary leaders' plane (ERRATA 10): within it a member
/// is projected onto the plane (and the tool says so); beyond it the scenario is refused.
pub const DEFAULT_PLANE_TOLERANCE_M: Real = 1.0;
/// Default RK4 substeps per tick.
pub const DEFAULT_SUBSTEPS: u32 = 1;

/// The file format. Optional keys have documented defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    pub name: String,
    /// Travel time of the plan T_total (eq. 15), seconds.
    pub t_total_s: Real,
    /// Radius of the ball around each quadcopter (Sec. VI-A), metres.
    pub eps_m: Real,
    /// Rate of the shared clock and state exchange, Hz; dt = 1 / comm_hz.
    pub comm_hz: Real,
    /// k1..k4 (eq. 44).
    pub gains: [Real; 4],
    /// Fix lambda_CD,min (eq. 38); default: the plan's smallest lambda_1(U_D).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lambda_cd_min: Option<Real>,
    /// Fix delta (eq. 36); lambda_CD,min then follows from eq. 38. Exclusive with lambda_cd_min.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_m: Option<Real>,
    /// RK4 substeps per tick (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub substeps: Option<u32>,
    /// Smallest weight a synthesised graph may use (default 0.05).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight_floor: Option<Real>,
    /// Largest distance off the leaders' plane that is projected rather than refused (default 1 m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_tolerance_m: Option<Real>,
    /// Imperfect links between the members (delay, jitter, loss; default perfect). Set by
    /// `--link-*` flags; `launch` hands it to its members inside the scenario, so that its
    /// content hash covers it and a member with other links is refused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<LinkSpec>,
    /// `[origin]`: the scenario's frame on the Earth (WGS-84; `origin.rs`). Without it the
    /// scenario is only local metres.
    #[serde(default, rename = "origin", skip_serializing_if = "Option::is_none")]
    pub geo_origin: Option<GeoOrigin>,
    /// `[takeoff]`: start on the ground below the start formation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub takeoff: Option<GroundSpec>,
    /// `[[segment]]`: further deformations after the agents' own goals, in flight order
    /// (segment 2, 3, ...).
    #[serde(default, rename = "segment", skip_serializing_if = "Vec::is_empty")]
    pub segments: Vec<SegmentSpec>,
    /// `[landing]`: land below the final formation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landing: Option<GroundSpec>,
    /// `[geofence]`: the airspace the team may use.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geofence: Option<GeofenceSpec>,
    /// `[[obstacle]]`: solids the team must not touch, each named.
    #[serde(default, rename = "obstacle", skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<ObstacleSpec>,
    /// `[vehicle]`: the quadcopters' speed and acceleration limits and their downwash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<VehicleSpec>,
    pub agents: Vec<AgentSpec>,
}

/// One member in a file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AgentSpec {
    pub id: u32,
    pub role: Role,
    pub position: [Real; 3],
    /// Primary leaders only: the destination r_g (eq. 15).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal: Option<[Real; 3]>,
    /// Followers only: exactly three in-neighbours; synthesised when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub in_neighbors: Option<Vec<u32>>,
}

/// A scenario that cannot be flown, with where it came from and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{origin}: {kind}")]
pub struct ScenarioError {
    /// The file path, or `built-in NAME`.
    pub origin: String,
    pub kind: ScenarioErrorKind,
}

/// What is wrong with a scenario; every variant names the field or the member(s).
#[derive(Debug, thiserror::Error)]
pub enum ScenarioErrorKind {
    #[error("cannot read the file: {0}")]
    Io(String),
    #[error("malformed scenario: {0}")]
    Parse(String),
    #[error("field `{field}` must be a finite number, got {value}")]
    NonFinite { field: String, value: Real },
    #[error("field `{field}` {reason}")]
    Invalid { field: String, reason: String },
    #[error("agent id {id} appears more than once")]
    DuplicateId { id: u32 },
    #[error("there must be exactly 3 primary leaders, found {found:?}")]
    PrimaryCount { found: Vec<u32> },
    #[error("primary leader {id}: `goal` is missing")]
    MissingGoal { id: u32 },
    #[error("agent {id} ({role}): only primary leaders have a `goal`")]
    GoalOnNonPrimary { id: u32, role: &'static str },
    #[error("agent {id} ({role}): only followers have `in_neighbors`")]
    NeighborsOnLeader { id: u32, role: &'static str },
    #[error("primary leaders {ids:?} are (nearly) collinear {when} (sine {sine:.2e}; eq. 7 needs a triangle)")]
    Collinear {
        ids: [u32; 3],
        when: String,
        sine: Real,
    },
    #[error("agent {id}: {distance_m:.3} m off the primary leaders' plane (tolerance {tolerance_m} m; a 2-D continuum needs every agent on it, ERRATA 10)")]
    OffPlane {
        id: u32,
        distance_m: Real,
        tolerance_m: Real,
    },
    #[error(transparent)]
    Formation(#[from] FormationError),
    #[error(transparent)]
    Synthesis(#[from] SynthesisError),
    /// `[geofence]` or an `[[obstacle]]` (`what`: `geofence`, `obstacle "NAME"`).
    #[error("{what}: {reason}")]
    Airspace { what: String, reason: String },
    #[error("gains {gains:?} are unstable for this graph: a root of eq. 26 has real part {worst_real:.4} >= 0")]
    UnstableGains { gains: [Real; 4], worst_real: Real },
}

/// How much a loader checks. Members of a running team load a scenario the orchestrator already
/// validated in full (they compare its hash), so they skip the O(N^3) eigenvalue checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Checks {
    /// Everything, including the stability of the gains over spec(W) (eq. 26).
    Full,
    /// Everything but the eigenvalue computations.
    Member,
}

/// A validated scenario, ready to fly.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Where it came from (path or `built-in NAME`).
    pub origin: String,
    /// The scenario as flown: positions projected, in-neighbours filled in.
    pub file: ScenarioFile,
    pub formation: Formation,
    pub plan: TeamPlan,
    /// Things the loader changed and the user should know (projections).
    pub notes: Vec<String>,
    /// Stability margin of the gains (eq. 26), when computed (`Checks::Full`).
    pub gains_margin: Option<Real>,
}

impl Scenario {
    /// Read and validate a scenario file.
    pub fn load(path: &Path, checks: Checks) -> Result<Self, ScenarioError> {
        let origin = path.display().to_string();
        // Regular files only, and at most 64 MiB: `/dev/zero` or a FIFO is refused at once.
        let text =
            cdm_files::read_input(path, cdm_files::MAX_INPUT_BYTES).map_err(|e| ScenarioError {
                origin: origin.clone(),
                kind: ScenarioErrorKind::Io(e.reason()),
            })?;
        if path.extension().is_some_and(|e| e == "json") {
            return Self::parse_json(&text, &origin, checks);
        }
        Self::parse(&text, &origin, checks)
    }

    /// Validate scenario text in JSON (the same fields as the TOML file). `launch` hands its
    /// members this form: serde_json reads straight into the structs, where the TOML parser
    /// builds a document first (a 1000-member file: about 0.2 MiB against 3.9 MiB of peak memory
    /// in each of 1000 processes).
    pub fn parse_json(text: &str, origin: &str, checks: Checks) -> Result<Self, ScenarioError> {
        let parsed = serde_json::from_str(text).map_err(|e| {
            let who = locate::json_agent(text);
            ScenarioErrorKind::Parse(locate::named(who, e.to_string()))
        });
        Self::from_parsed(parsed, origin, checks)
    }

    /// Validate scenario text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str, checks: Checks) -> Result<Self, ScenarioError> {
        let parsed = toml::from_str(text).map_err(|e: toml::de::Error| {
            let who = locate::toml_agent(text, e.span().map(|r| r.start));
            ScenarioErrorKind::Parse(locate::named(who, e.to_string()))
        });
        Self::from_parsed(parsed, origin, checks)
    }

    /// A parser's result, validated; a parse error becomes `Parse`, naming `origin`.
    fn from_parsed(
        parsed: Result<ScenarioFile, ScenarioErrorKind>,
        origin: &str,
        checks: Checks,
    ) -> Result<Self, ScenarioError> {
        let file = parsed.map_err(|kind| ScenarioError {
            origin: origin.to_string(),
            kind,
        })?;
        Self::from_file(file, origin, checks)
    }

    /// Validate an in-memory scenario.
    pub fn from_file(
        file: ScenarioFile,
        origin: &str,
        checks: Checks,
    ) -> Result<Self, ScenarioError> {
        let mut s = validate::validate(file, checks).map_err(|kind| ScenarioError {
            origin: origin.to_string(),
            kind,
        })?;
        s.origin = origin.to_string();
        Ok(s)
    }

    /// A built-in scenario by name (`paper40`).
    pub fn builtin(name: &str) -> Result<Self, ScenarioError> {
        match name {
            "paper40" => Self::from_file(paper40(), "built-in paper40", Checks::Full),
            "paper40-mission" => Self::from_file(
                builtin::paper40_mission(),
                "built-in paper40-mission",
                Checks::Full,
            ),
            other => Err(ScenarioError {
                origin: format!("built-in {other}"),
                kind: ScenarioErrorKind::Invalid {
                    field: "scenario".into(),
                    reason: "is not a built-in scenario (known: paper40, paper40-mission)".into(),
                },
            }),
        }
    }

    /// A generated team of `n` members (see `builtin::generated`).
    pub fn generated(n: usize) -> Result<Self, ScenarioError> {
        let origin = format!("generated --n {n}");
        let file = generated(n).map_err(|e| ScenarioError {
            origin: origin.clone(),
            kind: ScenarioErrorKind::Invalid {
                field: "--n".into(),
                reason: e.to_string(),
            },
        })?;
        Self::from_file(file, &origin, Checks::Full)
    }

    /// The scenario as compact JSON (what `launch` hands its members; see [`Self::parse_json`]).
    pub fn to_json(&self) -> String {
        serde_json::to_string(&self.file).unwrap_or_else(|e| format!("cannot serialise: {e}"))
    }

    /// The scenario as TOML (what `scenario.toml` and `scenario export` write).
    pub fn to_toml(&self) -> String {
        toml::to_string(&self.file).unwrap_or_else(|e| format!("# cannot serialise: {e}\n"))
    }

    /// Content hash of the scenario as flown (canonical JSON, SHA-256, first 8 bytes): two
    /// processes fly the same team only if their hashes agree. JSON rather than TOML because
    /// every member computes it at start: serde_json writes the 1000-member file in a fifth of
    /// the instructions the TOML writer needs (BENCHMARKS.md, start-up). Both forms are
    /// canonical (fields in declaration order, shortest round-trip floats), and the keys are
    /// written, so two optional fields cannot be mistaken for each other.
    pub fn content_hash(&self) -> u64 {
        let json = serde_json::to_vec(&self.file).unwrap_or_default();
        let digest = Sha256::digest(&json);
        let mut b = [0u8; 8];
        b.copy_from_slice(&digest[..8]);
        u64::from_le_bytes(b)
    }

    /// dt = 1 / comm_hz.
    pub fn dt_s(&self) -> Real {
        1.0 / self.file.comm_hz
    }

    /// The last tick of the plan: ceil(T_total * comm_hz), over the whole mission when there is
    /// one (its last phase's end). Ticks run 0..=last_tick.
    pub fn last_tick(&self) -> u64 {
        last_tick_of(self.plan.flight_end_s(), self.file.comm_hz)
    }

    /// The links at this scenario's tick length (perfect unless `[link]` says otherwise).
    pub fn link_model(&self) -> LinkModel {
        LinkModel::new(self.file.link.unwrap_or_default(), self.dt_s())
    }

    /// The same scenario over other links (`None` or a perfect spec: the paper's model). The
    /// formation and plan do not depend on the links, so nothing is validated again.
    pub fn with_link(&self, spec: Option<LinkSpec>) -> Result<Self, ScenarioError> {
        if let Some((field, reason)) = spec.and_then(|l| l.problem()) {
            return Err(ScenarioError {
                origin: self.origin.clone(),
                kind: ScenarioErrorKind::Invalid {
                    field: field.into(),
                    reason,
                },
            });
        }
        let mut s = self.clone();
        // Without impairments the seed changes nothing: leave the scenario (and its hash) as is.
        s.file.link = spec.filter(|l| !l.is_perfect());
        Ok(s)
    }

    /// RK4 substeps per tick.
    pub fn substeps(&self) -> u32 {
        self.file.substeps.unwrap_or(DEFAULT_SUBSTEPS)
    }

    /// The downwash ellipsoid's vertical semi-axis over its horizontal one (`[vehicle]`
    /// `downwash_ratio`), when the file sets it; without it separation is the paper's spheres.
    pub fn downwash_ratio(&self) -> Option<Real> {
        self.file.vehicle.and_then(|v| v.downwash_ratio)
    }

    /// The role of a member id, if present.
    pub fn role_of(&self, id: u32) -> Option<Role> {
        self.formation.member(id).map(|m| m.role)
    }
}

/// The last tick of a plan of `t_total_s` at `comm_hz`: ceil(T_total * comm_hz), at least 1.
pub fn last_tick_of(t_total_s: Real, comm_hz: Real) -> u64 {
    (t_total_s * comm_hz - 1e-9).ceil().max(1.0) as u64
}
