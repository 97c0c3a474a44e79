//! The data behind the figures, read back from a run directory alone: scenario.toml (the plan
//! and the graph), audit.json (the safety numbers and violations) and telemetry.csv, which is
//! streamed one tick at a time (paper40 is 800k rows) so memory holds per-tick series only.

use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use common::formation::Role;
use common::math::{vec3, Real, Vec3};
use common::plan::Segment;
use common::safety::{min_separation, Prism};
use common::scenario::{Checks, Scenario};

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
}

/// One tick of the run, as drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickSample {
    pub tick: u64,
    pub t_s: Real,
    /// Eigenvalues of U_D, ascending (Fig. 8).
    pub lambdas: [Real; 3],
    /// Smallest distance between two agents, D_B(t) (Fig. 11).
    pub min_separation_m: Real,
    /// Smallest signed distance of a follower to the containment prism's sides, D_S(t) (Fig. 11).
    pub min_boundary_m: Real,
    /// The followed agent: actual and desired position (Fig. 9).
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
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(path, e.to_string()))?;
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
                    _ => "violation",
                };
                Some((kind, f.get("t_s")?.as_f64()?))
            }),
        losses: v
            .get("losses")
            .and_then(|x| x.as_array())
            .map(|a| {
                a.iter()
                    .filter_map(|l| {
                        let id = u32::try_from(l.get("id")?.as_u64()?).ok()?;
                        Some((id, l.get("tick")?.as_u64()?))
                    })
                    .collect()
            })
            .unwrap_or_default(),
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

/// Eigenvalues of U_D at time t, exactly as the audit computes them (eq. 37).
pub fn lambdas_at(s: &Scenario, t: Real) -> [Real; 3] {
    let seg = if t <= s.plan.quintic.t_total_s {
        Segment::Motion
    } else {
        Segment::Hold
    };
    let sp = s.plan.quintic.derivatives(t, seg)[0];
    s.plan.lambdas_at_s(sp).unwrap_or([0.0; 3])
}

/// Read a run directory. `follow` overrides the followed agent (it must be a member).
pub fn read_run(dir: &Path, follow: Option<u32>) -> Result<RunData, ReadError> {
    let sc_path = dir.join("scenario.toml");
    let scenario =
        Scenario::load(&sc_path, Checks::Member).map_err(|e| invalid(&sc_path, e.to_string()))?;
    let audit = read_audit(&dir.join("audit.json"))?;
    let members = &scenario.formation.members;
    let index: BTreeMap<u32, usize> = members.iter().enumerate().map(|(k, m)| (m.id, k)).collect();
    let follow = match follow {
        Some(id) if index.contains_key(&id) => id,
        Some(id) => {
            return Err(invalid(
                &sc_path,
                format!("--follow {id}: no agent with this id"),
            ))
        }
        None => deepest_follower(&scenario).unwrap_or(members[0].id),
    };
    let follow_k = index[&follow];
    let followers: Vec<usize> = (0..members.len())
        .filter(|&k| members[k].role == Role::Follower)
        .collect();
    let eps_half = audit.delta_m + audit.eps_m;
    // A lost member has no rows from its loss's tick on; it leaves separation and containment.
    let lost_from: Vec<(usize, u64)> = audit
        .losses
        .iter()
        .filter_map(|(id, tick)| Some((*index.get(id)?, *tick)))
        .collect();
    let alive = |k: usize, tick: u64| lost_from.iter().all(|&(j, t)| j != k || tick < t);
    let expected_rows = |tick: u64| (0..members.len()).filter(|&k| alive(k, tick)).count();

    let tel_path = dir.join("telemetry.csv");
    let file = File::open(&tel_path).map_err(io(&tel_path))?;
    let mut lines = BufReader::with_capacity(1 << 20, file).lines();
    match lines.next() {
        Some(Ok(h)) if h.trim() == common::telemetry::HEADER => {}
        Some(Ok(h)) => {
            return Err(invalid(
                &tel_path,
                format!(
                    "unexpected header `{h}`, expected `{}`",
                    common::telemetry::HEADER
                ),
            ))
        }
        Some(Err(e)) => return Err(io(&tel_path)(e)),
        None => return Err(invalid(&tel_path, "empty file")),
    }
    let n = members.len();
    let mut pos = vec![Vec3::zeros(); n];
    let mut ht = vec![Vec3::zeros(); n];
    let mut seen = 0usize;
    let mut current: Option<(u64, Real)> = None;
    let mut data = RunData {
        scenario: scenario.clone(),
        audit,
        follow,
        samples: Vec::new(),
        first: Vec::new(),
        last: Vec::new(),
        primary_paths: [Vec::new(), Vec::new(), Vec::new()],
    };
    let expected_ticks = scenario.last_tick() + 1;
    let path_stride = (expected_ticks / 400).max(1);
    let finish_tick = |tick: u64, t: Real, pos: &[Vec3], ht: &[Vec3], data: &mut RunData| {
        let living: Vec<Vec3> = (0..pos.len())
            .filter(|&k| alive(k, tick))
            .map(|k| pos[k])
            .collect();
        let (sep, _, _) = min_separation(&living);
        // Theorem 3's prism over the leaders' desired polygon, as the audit builds it.
        let verts: Vec<Vec3> = scenario.formation.polygon.iter().map(|&k| ht[k]).collect();
        let mut boundary = Real::INFINITY;
        if verts.len() >= 3 {
            let normal = (verts[1] - verts[0])
                .cross(&(verts[2] - verts[0]))
                .normalize();
            let prism = Prism::new(verts, normal, eps_half);
            for &k in followers.iter().filter(|&&k| alive(k, tick)) {
                boundary = boundary.min(prism.side_distance(&pos[k]));
            }
        }
        if data.first.is_empty() {
            data.first = pos.to_vec();
        }
        if tick.is_multiple_of(path_stride) {
            for (p, path) in data.primary_paths.iter_mut().enumerate() {
                path.push(pos[p]);
            }
        }
        data.samples.push(TickSample {
            tick,
            t_s: t,
            lambdas: lambdas_at(&scenario, t),
            min_separation_m: sep,
            min_boundary_m: boundary,
            follow_r: pos[follow_k],
            follow_ht: ht[follow_k],
        });
    };
    for (lineno, line) in lines.enumerate() {
        let line = line.map_err(io(&tel_path))?;
        let bad = |what: &str| invalid(&tel_path, format!("line {}: {what}", lineno + 2));
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 13 {
            return Err(bad("expected 13 fields"));
        }
        let num = |i: usize| f[i].parse::<Real>().map_err(|_| bad("not a number"));
        let tick: u64 = f[0].parse().map_err(|_| bad("bad tick"))?;
        let id: u32 = f[2].parse().map_err(|_| bad("bad id"))?;
        let Some(&k) = index.get(&id) else {
            return Err(bad(&format!("agent {id} is not in scenario.toml")));
        };
        if let Some((ct, t)) = current {
            if ct != tick {
                let n = expected_rows(ct);
                if seen != n {
                    return Err(bad(&format!("tick {ct} has {seen} rows, expected {n}")));
                }
                finish_tick(ct, t, &pos, &ht, &mut data);
                seen = 0;
            }
        }
        current = Some((tick, num(1)?));
        pos[k] = vec3([num(4)?, num(5)?, num(6)?]);
        ht[k] = vec3([num(10)?, num(11)?, num(12)?]);
        seen += 1;
    }
    match current {
        Some((ct, t)) if seen == expected_rows(ct) => finish_tick(ct, t, &pos, &ht, &mut data),
        Some((ct, _)) => {
            return Err(invalid(
                &tel_path,
                format!(
                    "last tick {ct} has {seen} rows, expected {}",
                    expected_rows(ct)
                ),
            ))
        }
        None => return Err(invalid(&tel_path, "no rows")),
    }
    data.last = pos;
    Ok(data)
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
