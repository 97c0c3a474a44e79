//! The data behind the figures, read back from a run directory alone: scenario.toml (the plan
//! and the graph), audit.json (the safety numbers and violations) and the telemetry (CSV or
//! Parquet, [`read_telemetry`]), streamed one tick at a time (paper40 is 800k rows) so memory
//! holds per-tick series only.

use std::collections::{BTreeMap, VecDeque};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use cdm_math::{vec3, Real, Vec3};
use cdm_model::formation::Role;
use cdm_records::audit::CommandSummary;
use cdm_records::margins::{boundary_distance, lambdas_at, living_separation};
use cdm_records::telemetry::{Row, TelemetryFormat, HEADER};
use cdm_scenario::{Checks, Scenario};

// The per-tick margins moved to the core (the ROS 2 bag computes them during a run too); named
// here as before.

/// A run directory that cannot be read, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    /// Not a regular file, or too large to read whole.
    #[error(transparent)]
    File(#[from] cdm_files::FileError),
}

/// The longest telemetry line read (a row is about 250 bytes).
const MAX_LINE_BYTES: u64 = 4096;

/// The next line of `r` without its newline, at most [`MAX_LINE_BYTES`] long; `None` at the end.
fn next_line(r: &mut impl BufRead, line: &mut String) -> std::io::Result<Option<()>> {
    line.clear();
    let n = r.take(MAX_LINE_BYTES + 1).read_line(line)?;
    if n == 0 {
        return Ok(None);
    }
    if line.len() as u64 > MAX_LINE_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("a line longer than {MAX_LINE_BYTES} bytes"),
        ));
    }
    let end = line.trim_end_matches(['\n', '\r']).len();
    line.truncate(end);
    Ok(Some(()))
}

/// The safety numbers the audit used (audit.json).
#[derive(Debug, Clone, PartialEq)]
pub struct AuditNumbers {
    pub lambda_cd_min: Real,
    pub lambda1_min_run: Real,
    pub eps_m: Real,
    pub delta_m: Real,
    pub t_total_s: Real,
    pub verdict_safe: bool,
    /// The first violation's kind and time, if any.
    pub first_violation: Option<(&'static str, Real)>,
    /// Members lost in flight: (id, the first tick without its row in telemetry.csv).
    pub losses: Vec<(u32, u64)>,
    /// What each loss changed, in loss order (audit.json `losses`).
    pub repairs: Vec<RepairRecord>,
}

/// One loss as audit.json records it: the followers that switched triangles (eq. 18 weights
/// of the new triangle) and those left flying their plan.
#[derive(Debug, Clone, PartialEq)]
pub struct RepairRecord {
    pub id: u32,
    /// The first tick the repair applies to.
    pub tick: u64,
    /// (follower, new in-neighbours).
    pub retriangulated: Vec<(u32, [u32; 3])>,
    pub degraded: Vec<u32>,
}

/// audit.json's `losses` list (absent in a run that lost nobody).
fn read_repairs(v: &serde_json::Value) -> Vec<RepairRecord> {
    let ids = |x: &serde_json::Value| -> Vec<u32> {
        x.as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|i| u32::try_from(i.as_u64()?).ok())
                    .collect()
            })
            .unwrap_or_default()
    };
    let one = |l: &serde_json::Value| -> Option<RepairRecord> {
        let retriangulated = l
            .get("retriangulated")?
            .as_array()?
            .iter()
            .filter_map(|r| {
                let id = u32::try_from(r.get("id")?.as_u64()?).ok()?;
                let new: [u32; 3] = ids(r.get("new")?).try_into().ok()?;
                Some((id, new))
            })
            .collect();
        Some(RepairRecord {
            id: u32::try_from(l.get("id")?.as_u64()?).ok()?,
            tick: l.get("tick")?.as_u64()?,
            retriangulated,
            degraded: l.get("degraded").map(ids).unwrap_or_default(),
        })
    };
    v.get("losses")
        .and_then(|x| x.as_array())
        .map(|a| a.iter().filter_map(one).collect())
        .unwrap_or_default()
}

/// One tick of the run, as drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickSample {
    pub tick: u64,
    pub t_s: Real,
    /// Eigenvalues of U_D, ascending (Fig. 8).
    pub lambdas: [Real; 3],
    /// Smallest distance between two members, D_B(t) (Fig. 11).
    pub min_separation_m: Real,
    /// Smallest signed distance of a follower to the containment prism's sides, D_S(t) (Fig. 11).
    pub min_boundary_m: Real,
    /// Largest ||r_i - r_i,HT||_2 over the living members (against delta, eq. 38).
    pub max_deviation_m: Real,
    /// The followed member: actual and desired position (Fig. 9).
    pub follow_r: Vec3,
    pub follow_ht: Vec3,
}

/// Everything the figures need.
pub struct RunData {
    pub scenario: Scenario,
    pub audit: AuditNumbers,
    /// The follower of `fig_agent_<id>`.
    pub follow: u32,
    pub samples: Vec<TickSample>,
    /// Positions (member order) at the first and the last tick in telemetry.
    pub first: Vec<Vec3>,
    pub last: Vec<Vec3>,
    /// The primary leaders' actual paths, decimated (member order 0..3).
    pub primary_paths: [Vec<Vec3>; 3],
    /// The deviation |r - r_HT| (eq. 13) over time of every follower a loss repaired or left
    /// flying its plan, decimated like the primary paths: the repair transients.
    pub transients: Vec<Transient>,
    /// The run's commands (`commands.json`; none for a run without).
    pub commands: Vec<CommandSummary>,
}

/// One repaired follower's deviation from its desired position, (t, |r - r_HT|) pairs.
#[derive(Debug, Clone, PartialEq)]
pub struct Transient {
    pub id: u32,
    /// The time of the first tick a loss repaired it from: its transient starts there.
    pub from_s: Real,
    pub points: Vec<(Real, Real)>,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ReadError + '_ {
    move |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn invalid(path: &Path, message: impl Into<String>) -> ReadError {
    ReadError::Invalid {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Read audit.json's safety numbers.
pub fn read_audit(path: &Path) -> Result<AuditNumbers, ReadError> {
    let text = cdm_files::read_input(path, cdm_files::MAX_INPUT_BYTES)?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(path, e.to_string()))?;
    let repairs = read_repairs(&v);
    let num = |key: &str| {
        v.get(key)
            .and_then(serde_json::Value::as_f64)
            .ok_or_else(|| invalid(path, format!("field `{key}` is missing or not a number")))
    };
    Ok(AuditNumbers {
        lambda_cd_min: num("lambda_cd_min")?,
        lambda1_min_run: num("lambda1_min_run")?,
        eps_m: num("eps_m")?,
        delta_m: num("delta_m")?,
        t_total_s: num("t_total_s")?,
        verdict_safe: v.get("verdict").and_then(|x| x.as_str()) == Some("SAFE"),
        first_violation: v
            .get("violations")
            .and_then(|x| x.as_array())
            .and_then(|a| a.first())
            .and_then(|f| {
                let kind = match f.get("kind")?.as_str()? {
                    "collision" => "collision",
                    "containment" => "containment",
                    "tracking" => "tracking",
                    "deformation" => "deformation",
                    "geofence" => "geofence",
                    "obstacle" => "obstacle",
                    _ => "violation",
                };
                Some((kind, f.get("t_s")?.as_f64()?))
            }),
        losses: repairs.iter().map(|r| (r.id, r.tick)).collect(),
        repairs,
    })
}

/// The follower deepest in the communication graph: the longest shortest path from the leaders
/// (ties: the smallest id). `None` for a team without followers.
pub fn deepest_follower(s: &Scenario) -> Option<u32> {
    let members = &s.formation.members;
    let mut depth: BTreeMap<u32, usize> = members
        .iter()
        .filter(|m| m.role.is_leader())
        .map(|m| (m.id, 0))
        .collect();
    // Out-neighbour lists from the followers' in-neighbours (eq. 18).
    let mut out: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for m in members {
        if let Some(l) = m.link {
            for j in l.in_neighbors {
                out.entry(j).or_default().push(m.id);
            }
        }
    }
    let mut queue: VecDeque<u32> = depth.keys().copied().collect();
    while let Some(i) = queue.pop_front() {
        let d = depth.get(&i).copied().unwrap_or(0);
        for &j in out.get(&i).map(Vec::as_slice).unwrap_or(&[]) {
            if let std::collections::btree_map::Entry::Vacant(e) = depth.entry(j) {
                e.insert(d + 1);
                queue.push_back(j);
            }
        }
    }
    members
        .iter()
        .filter(|m| m.role == Role::Follower)
        .map(|m| (depth.get(&m.id).copied().unwrap_or(usize::MAX), m.id))
        .max_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)))
        .map(|(_, id)| id)
}

/// The run's commands.json (none for a run without), its errors naming the file.
fn read_run_commands(dir: &Path) -> Result<Vec<CommandSummary>, ReadError> {
    use cdm_records::commands::{read_commands, COMMANDS_FILE};
    read_commands(dir).map_err(|e| invalid(&dir.join(COMMANDS_FILE), e.to_string()))
}

/// The member the figures follow: `follow` when it is in the scenario (`index`: id to
/// formation position), else the deepest follower; an unknown id is an error naming `path`.
fn followed(
    scenario: &Scenario,
    index: &BTreeMap<u32, usize>,
    follow: Option<u32>,
    path: &Path,
) -> Result<u32, ReadError> {
    match follow {
        Some(id) if index.contains_key(&id) => Ok(id),
        Some(id) => Err(invalid(
            path,
            format!("--follow {id}: no agent with this id"),
        )),
        None => Ok(deepest_follower(scenario).unwrap_or(scenario.formation.members[0].id)),
    }
}

/// Read a run directory. `follow` overrides the followed member (it must be in the scenario).
pub fn read_run(dir: &Path, follow: Option<u32>) -> Result<RunData, ReadError> {
    let sc_path = dir.join("scenario.toml");
    let scenario =
        Scenario::load(&sc_path, Checks::Member).map_err(|e| invalid(&sc_path, e.to_string()))?;
    let audit = read_audit(&dir.join("audit.json"))?;
    let commands = read_run_commands(dir)?;
    let members = &scenario.formation.members;
    let index: BTreeMap<u32, usize> = members.iter().enumerate().map(|(k, m)| (m.id, k)).collect();
    let follow = followed(&scenario, &index, follow, &sc_path)?;
    let follow_k = index[&follow];
    let followers: Vec<usize> = (0..members.len())
        .filter(|&k| members[k].role == Role::Follower)
        .collect();
    let eps_half = audit.delta_m + audit.eps_m;

    let mut data = RunData {
        scenario: scenario.clone(),
        audit,
        follow,
        samples: Vec::new(),
        first: Vec::new(),
        last: Vec::new(),
        primary_paths: [Vec::new(), Vec::new(), Vec::new()],
        transients: Vec::new(),
        commands,
    };
    let repaired = repaired_members(&data.audit.repairs, &index);
    data.transients = repaired
        .iter()
        .map(|&(_, id, from_tick)| Transient {
            id,
            from_s: from_tick as Real * scenario.dt_s(),
            points: Vec::new(),
        })
        .collect();
    let expected_ticks = scenario.last_tick() + 1;
    let path_stride = (expected_ticks / 400).max(1);
    let transient_stride = (expected_ticks / 4000).max(1);
    stream_ticks(dir, &scenario, &data.audit.losses.clone(), |tp| {
        let (tick, t, pos, ht) = (tp.tick, tp.t_s, tp.pos, tp.ht);
        let (sep, _, _) = living_separation(pos, tp.alive);
        let boundary = boundary_distance(&scenario, &followers, eps_half, pos, ht, tp.alive);
        if data.first.is_empty() {
            data.first = pos.to_vec();
        }
        if tick.is_multiple_of(path_stride) {
            for (p, path) in data.primary_paths.iter_mut().enumerate() {
                path.push(pos[p]);
            }
        }
        data.last.clear();
        data.last.extend_from_slice(pos);
        if tick.is_multiple_of(transient_stride) {
            for (&(k, _, _), tr) in repaired.iter().zip(&mut data.transients) {
                if tp.alive[k] {
                    tr.points.push((t, (pos[k] - ht[k]).norm()));
                }
            }
        }
        data.samples.push(TickSample {
            tick,
            t_s: t,
            lambdas: lambdas_at(&scenario, t),
            min_separation_m: sep,
            min_boundary_m: boundary,
            max_deviation_m: max_deviation(pos, ht, tp.alive),
            follow_r: pos[follow_k],
            follow_ht: ht[follow_k],
        });
    })?;
    Ok(data)
}

/// Largest ||r_i - r_i,HT||_2 over the living members.
fn max_deviation(pos: &[Vec3], ht: &[Vec3], alive: &[bool]) -> Real {
    (0..pos.len())
        .filter(|&k| alive[k])
        .map(|k| (pos[k] - ht[k]).norm())
        .fold(0.0, Real::max)
}

/// The followers any loss re-triangulated or left flying its plan, as (member index, id, first
/// tick repaired) in id order. An id audit.json names that the scenario lacks has no row to
/// draw: skipped.
fn repaired_members(
    repairs: &[RepairRecord],
    index: &BTreeMap<u32, usize>,
) -> Vec<(usize, u32, u64)> {
    let mut first: BTreeMap<u32, u64> = BTreeMap::new();
    for r in repairs {
        let ids = r
            .retriangulated
            .iter()
            .map(|x| x.0)
            .chain(r.degraded.iter().copied());
        for id in ids {
            first
                .entry(id)
                .and_modify(|t| *t = (*t).min(r.tick))
                .or_insert(r.tick);
        }
    }
    first
        .into_iter()
        .filter_map(|(id, tick)| Some((*index.get(&id)?, id, tick)))
        .collect()
}

/// One complete tick of a run's telemetry, in the scenario's member order.
pub struct TickPositions<'a> {
    pub tick: u64,
    pub t_s: Real,
    /// Actual positions r_i.
    pub pos: &'a [Vec3],
    /// Desired positions r_i,HT.
    pub ht: &'a [Vec3],
    /// Members still flying at this tick; a lost member's `pos`/`ht` hold its last row.
    pub alive: &'a [bool],
}

/// The telemetry of a run directory, row by row in file order (tick, then id), in whichever
/// format the run wrote: telemetry.parquet when present, else telemetry.csv (a regular file,
/// lines of bounded length). One row (CSV) or one record batch (Parquet) is in memory at a time.
/// `visit` refuses a row with a message, which is reported with the file and row. Returns the
/// file read.
pub fn read_telemetry<E: std::fmt::Display>(
    dir: &Path,
    mut visit: impl FnMut(&Row) -> Result<(), E>,
) -> Result<PathBuf, ReadError> {
    let parquet = dir.join(TelemetryFormat::Parquet.file_name());
    if parquet.exists() {
        read_parquet(&parquet, visit)?;
        return Ok(parquet);
    }
    let path = dir.join(TelemetryFormat::Csv.file_name());
    let mut reader = BufReader::with_capacity(1 << 20, cdm_files::open_input(&path)?);
    let mut line = String::new();
    match next_line(&mut reader, &mut line) {
        Ok(Some(())) if line.trim() == HEADER => {}
        Ok(Some(())) => {
            return Err(invalid(
                &path,
                format!("unexpected header `{line}`, expected `{HEADER}`"),
            ))
        }
        Err(e) => return Err(io(&path)(e)),
        Ok(None) => return Err(invalid(&path, "empty file")),
    }
    let mut lineno = 1usize;
    while next_line(&mut reader, &mut line)
        .map_err(|e| io(&path)(e))?
        .is_some()
    {
        lineno += 1;
        let bad = |what: &str| invalid(&path, format!("line {lineno}: {what}"));
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 13 {
            return Err(bad("expected 13 fields"));
        }
        // A NaN or an infinity would pass for a position and leave the member out of every
        // distance the readers compute (the audit topic, the figures): refused like text.
        let num = |i: usize| match f[i].parse::<Real>() {
            Ok(x) if x.is_finite() => Ok(x),
            Ok(_) => Err(bad("not a finite number")),
            Err(_) => Err(bad("not a number")),
        };
        let row = Row {
            tick: f[0].parse().map_err(|_| bad("bad tick"))?,
            t_s: num(1)?,
            id: f[2].parse().map_err(|_| bad("bad id"))?,
            role: Role::from_name(f[3]).ok_or_else(|| bad("bad role"))?,
            r: vec3([num(4)?, num(5)?, num(6)?]),
            v: vec3([num(7)?, num(8)?, num(9)?]),
            ht: vec3([num(10)?, num(11)?, num(12)?]),
        };
        visit(&row).map_err(|e| bad(&e.to_string()))?;
    }
    Ok(path)
}

#[cfg(feature = "parquet")]
fn read_parquet<E: std::fmt::Display>(
    path: &Path,
    visit: impl FnMut(&Row) -> Result<(), E>,
) -> Result<(), ReadError> {
    cdm_parquet::read_rows(path, visit).map_err(|e| invalid(path, e.to_string()))
}

#[cfg(not(feature = "parquet"))]
fn read_parquet<E: std::fmt::Display>(
    path: &Path,
    _visit: impl FnMut(&Row) -> Result<(), E>,
) -> Result<(), ReadError> {
    Err(invalid(
        path,
        "this orchestrator was built without its `parquet` feature",
    ))
}

/// A telemetry row that does not fit the scenario or the rows before it.
#[derive(Debug, thiserror::Error)]
enum RowMisfit {
    #[error("agent {0} is not in scenario.toml")]
    Agent(u32),
    #[error("tick {tick} has {seen} rows, expected {expected}")]
    Rows {
        tick: u64,
        seen: usize,
        expected: usize,
    },
}

/// Stream a run directory's telemetry one complete tick at a time (paper40 is 800k rows, so
/// nothing but one tick is held). Every reader of telemetry goes through here. `losses` are
/// audit.json's (id, first tick without its row): from that tick a tick has fewer rows.
pub fn stream_ticks(
    dir: &Path,
    scenario: &Scenario,
    losses: &[(u32, u64)],
    mut on_tick: impl FnMut(TickPositions<'_>),
) -> Result<(), ReadError> {
    let members = &scenario.formation.members;
    let index: BTreeMap<u32, usize> = members.iter().enumerate().map(|(k, m)| (m.id, k)).collect();
    let n = members.len();
    let mut pos = vec![Vec3::zeros(); n];
    let mut ht = vec![Vec3::zeros(); n];
    let mut seen = 0usize;
    let mut current: Option<(u64, Real)> = None;
    let lost_from: Vec<(usize, u64)> = losses
        .iter()
        .filter_map(|(id, tick)| Some((*index.get(id)?, *tick)))
        .collect();
    let mut alive = vec![true; n];
    // The members flying at `tick` (into `alive`) and how many rows that tick has.
    let expected_rows = |tick: u64, alive: &mut [bool]| {
        for (k, a) in alive.iter_mut().enumerate() {
            *a = lost_from.iter().all(|&(j, t)| j != k || tick < t);
        }
        alive.iter().filter(|&&a| a).count()
    };
    let tel_path = read_telemetry(dir, |row| {
        let Some(&k) = index.get(&row.id) else {
            return Err(RowMisfit::Agent(row.id));
        };
        if let Some((ct, t)) = current {
            if ct != row.tick {
                let n = expected_rows(ct, &mut alive);
                if seen != n {
                    return Err(RowMisfit::Rows {
                        tick: ct,
                        seen,
                        expected: n,
                    });
                }
                on_tick(TickPositions {
                    tick: ct,
                    t_s: t,
                    pos: &pos,
                    ht: &ht,
                    alive: &alive,
                });
                seen = 0;
            }
        }
        current = Some((row.tick, row.t_s));
        pos[k] = row.r;
        ht[k] = row.ht;
        seen += 1;
        Ok(())
    })?;
    match current {
        Some((ct, t)) if seen == expected_rows(ct, &mut alive) => on_tick(TickPositions {
            tick: ct,
            t_s: t,
            pos: &pos,
            ht: &ht,
            alive: &alive,
        }),
        Some((ct, _)) => {
            return Err(invalid(
                &tel_path,
                format!(
                    "last tick {ct} has {seen} rows, expected {}",
                    expected_rows(ct, &mut alive)
                ),
            ))
        }
        None => return Err(invalid(&tel_path, "no rows")),
    }
    Ok(())
}

/// One violation of audit.json, as the viewer marks it on its timeline.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ViolationMark {
    pub tick: u64,
    pub kind: String,
    pub agents: Vec<u32>,
}

/// What the viewer's timeline needs from audit.json.
#[derive(Debug, Clone, PartialEq)]
pub struct Timeline {
    pub verdict: String,
    /// Ticks audited (and so in telemetry, every K-th with `--every K`).
    pub ticks: u64,
    pub violations: Vec<ViolationMark>,
}

/// Read audit.json's verdict, tick count and violations (the timeline markers of the viewer).
pub fn read_timeline(path: &Path) -> Result<Timeline, ReadError> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(path, e.to_string()))?;
    let verdict = v
        .get("verdict")
        .and_then(|x| x.as_str())
        .ok_or_else(|| invalid(path, "field `verdict` is missing or not a string"))?
        .to_owned();
    let marks = v
        .get("violations")
        .and_then(|x| x.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|f| {
                    Some(ViolationMark {
                        tick: f.get("tick")?.as_u64()?,
                        kind: f.get("kind")?.as_str()?.to_owned(),
                        agents: f
                            .get("agents")?
                            .as_array()?
                            .iter()
                            .filter_map(|x| x.as_u64().and_then(|x| u32::try_from(x).ok()))
                            .collect(),
                    })
                })
                .collect()
        })
        .unwrap_or_default();
    let ticks = v
        .get("ticks")
        .and_then(serde_json::Value::as_u64)
        .ok_or_else(|| invalid(path, "field `ticks` is missing or not a count"))?;
    Ok(Timeline {
        verdict,
        ticks,
        violations: marks,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deepest_follower_of_paper40_is_a_follower() {
        let s = Scenario::builtin("paper40").expect("paper40");
        let id = deepest_follower(&s).expect("has followers");
        assert_eq!(s.role_of(id), Some(Role::Follower));
    }
}
