//! The team's formation at t0: in-plane coordinates (eq. 12), alpha parameters (eq. 14),
//! follower communication weights (eq. 18), the weight matrix W and its blocks (eqs. 1-2,
//! 19-20), W_L (eq. 22 as corrected, ERRATA 5) and the checks of Theorems 1 and 2.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::frame::Frame;
use crate::geometry::{barycentric, convex_hull, signed_boundary_distance};
use cdm_math::{eigenvalues_by_components, DMat, Real, Vec2, Vec3};

/// What a member is in the team.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// One of the three leaders that define the CRF and Q, d (Sec. IV).
    Primary,
    /// A leader that follows Q, d through its alpha parameters (Sec. VII-B).
    Secondary,
    /// Tracks the weighted sum of three in-neighbours (eq. 6).
    Follower,
}

impl Role {
    /// The lowercase name used in files and telemetry.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Primary => "primary",
            Role::Secondary => "secondary",
            Role::Follower => "follower",
        }
    }

    /// The role of a lowercase name (the inverse of [`Role::as_str`]).
    pub fn from_name(name: &str) -> Option<Role> {
        [Role::Primary, Role::Secondary, Role::Follower]
            .into_iter()
            .find(|r| r.as_str() == name)
    }

    /// Leaders (primary or secondary) track r_HT directly.
    pub fn is_leader(self) -> bool {
        !matches!(self, Role::Follower)
    }
}

/// One member of a formation, with everything derived at t0.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    pub id: u32,
    pub role: Role,
    /// Initial position r_i0 (on the leaders' plane): the reference formation of eqs. 11-18.
    pub position: Vec3,
    /// Where the member is at t = 0: `position`, or the ground below it when the mission takes
    /// off.
    pub start: Vec3,
    /// In-plane coordinates (gamma_i, beta_i) at t0 (eq. 12).
    pub planar: Vec2,
    /// alpha_i1..3 (eq. 14): r_i,HT = sum_j alpha_ij r_j,HT (eq. 13).
    pub alpha: [Real; 3],
    /// Followers only: the three in-neighbours' ids and weights w_i,j (eq. 18).
    pub link: Option<Link>,
}

/// A follower's three in-neighbours and its communication weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    pub in_neighbors: [u32; 3],
    pub weights: [Real; 3],
}

/// A formation problem, named by the member(s) at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FormationError {
    #[error("agent {id}: in-neighbour {neighbor} does not exist")]
    UnknownNeighbor { id: u32, neighbor: u32 },
    #[error("agent {id}: lists itself as an in-neighbour")]
    SelfNeighbor { id: u32 },
    #[error("agent {id}: in-neighbours must be 3 distinct agents, got {given:?}")]
    NotThreeNeighbors { id: u32, given: Vec<u32> },
    #[error("agent {id}: not strictly inside the triangle of its in-neighbours {neighbors:?} (weights {weights:?}, eq. 18 / Assumption 1)")]
    NotInsideTriangle {
        id: u32,
        neighbors: [u32; 3],
        weights: [Real; 3],
    },
    #[error("agent {id}: in-neighbours {neighbors:?} are collinear, weights undefined (eq. 17)")]
    DegenerateTriangle { id: u32, neighbors: [u32; 3] },
    #[error("agents {ids:?}: not reachable from the leaders through the communication graph (Assumption 2)")]
    Unreachable { ids: Vec<u32> },
    #[error("leader {id}: the leading polygon is not strictly convex at this leader (every leader must be a vertex, Sec. II-A)")]
    NotConvex { id: u32 },
    #[error("agent {id}: outside the leading polygon (signed distance {distance_m:.3} m to its boundary)")]
    OutsidePolygon { id: u32, distance_m: Real },
    #[error("follower {id}: has no in-neighbours (none given and none synthesised)")]
    MissingLink { id: u32 },
}

/// Weights of the point `p` against three in-neighbour points (eq. 18).
pub fn triangle_weights(p: &Vec2, n: &[Vec2; 3]) -> Option<[Real; 3]> {
    barycentric(p, &n[0], &n[1], &n[2])
}

/// The formation: members ordered primaries (file order), secondaries, followers, as in eq. 2.
#[derive(Debug, Clone, PartialEq)]
pub struct Formation {
    pub frame: Frame,
    pub members: Vec<Member>,
    index: BTreeMap<u32, usize>,
    /// Member indices of the leading polygon's vertices, counter-clockwise in (gamma, beta).
    pub polygon: Vec<usize>,
}

/// Input for one member: id, role, position on the plane, optional in-neighbours.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberInput {
    pub id: u32,
    pub role: Role,
    pub position: Vec3,
    pub in_neighbors: Option<[u32; 3]>,
}

impl Formation {
    /// Build the formation: alpha parameters for everyone, the leading polygon (must be strictly
    /// convex with every leader a vertex), every follower strictly inside it, and the weights of
    /// followers whose in-neighbours are given (the others get `link = None`: see `graph`).
    /// The frame and the primary leaders are assumed already validated (3 primaries, not collinear).
    pub fn new(frame: Frame, inputs: &[MemberInput]) -> Result<Self, FormationError> {
        let mut ordered: Vec<&MemberInput> = Vec::with_capacity(inputs.len());
        for role in [Role::Primary, Role::Secondary, Role::Follower] {
            ordered.extend(inputs.iter().filter(|m| m.role == role));
        }
        let planar: Vec<Vec2> = ordered
            .iter()
            .map(|m| {
                let (g, b, _) = frame.coords(&m.position);
                Vec2::new(g, b)
            })
            .collect();
        let prim = [planar[0], planar[1], planar[2]];
        let index: BTreeMap<u32, usize> =
            ordered.iter().enumerate().map(|(k, m)| (m.id, k)).collect();
        let mut members = Vec::with_capacity(ordered.len());
        for (k, m) in ordered.iter().enumerate() {
            // eq. 14; primaries get unit vectors exactly.
            let alpha = if k < 3 {
                let mut a = [0.0; 3];
                a[k] = 1.0;
                a
            } else {
                triangle_weights(&planar[k], &prim).ok_or(FormationError::DegenerateTriangle {
                    id: m.id,
                    neighbors: [ordered[0].id, ordered[1].id, ordered[2].id],
                })?
            };
            members.push(Member {
                id: m.id,
                role: m.role,
                position: m.position,
                start: m.position,
                planar: planar[k],
                alpha,
                link: None,
            });
        }
        let n_leaders = members.iter().filter(|m| m.role.is_leader()).count();
        let leader_pts: Vec<Vec2> = planar[..n_leaders].to_vec();
        let hull = convex_hull(&leader_pts);
        if hull.len() != n_leaders {
            let missing = (0..n_leaders).find(|i| !hull.contains(i)).unwrap_or(0);
            return Err(FormationError::NotConvex {
                id: members[missing].id,
            });
        }
        let mut formation = Formation {
            frame,
            members,
            index,
            polygon: hull,
        };
        let poly = formation.polygon_points();
        for m in &formation.members[n_leaders..] {
            let d = signed_boundary_distance(&m.planar, &poly);
            if d.is_nan() || d <= 0.0 {
                return Err(FormationError::OutsidePolygon {
                    id: m.id,
                    distance_m: d,
                });
            }
        }
        for m in ordered.iter().filter(|m| m.role == Role::Follower) {
            if let Some(n) = m.in_neighbors {
                formation.set_link(m.id, n)?;
            }
        }
        Ok(formation)
    }

    /// Number of leaders N_L.
    pub fn n_leaders(&self) -> usize {
        self.members.iter().filter(|m| m.role.is_leader()).count()
    }

    /// The member index of an id.
    pub fn index_of(&self, id: u32) -> Option<usize> {
        self.index.get(&id).copied()
    }

    /// The member with this id.
    pub fn member(&self, id: u32) -> Option<&Member> {
        self.index_of(id).map(|k| &self.members[k])
    }

    /// The leading polygon's vertices in (gamma, beta), counter-clockwise.
    pub fn polygon_points(&self) -> Vec<Vec2> {
        self.polygon
            .iter()
            .map(|&k| self.members[k].planar)
            .collect()
    }

    /// Validate and set follower `id`'s in-neighbours, computing its weights (eq. 18).
    pub fn set_link(&mut self, id: u32, neighbors: [u32; 3]) -> Result<(), FormationError> {
        let weights = self.weights_for(id, neighbors)?;
        if let Some(k) = self.index_of(id) {
            self.members[k].link = Some(Link {
                in_neighbors: neighbors,
                weights,
            });
        }
        Ok(())
    }

    /// The weights follower `id` would have with these in-neighbours, or why it cannot.
    pub fn weights_for(&self, id: u32, neighbors: [u32; 3]) -> Result<[Real; 3], FormationError> {
        if neighbors.contains(&id) {
            return Err(FormationError::SelfNeighbor { id });
        }
        if neighbors[0] == neighbors[1]
            || neighbors[0] == neighbors[2]
            || neighbors[1] == neighbors[2]
        {
            return Err(FormationError::NotThreeNeighbors {
                id,
                given: neighbors.to_vec(),
            });
        }
        let mut pts = [Vec2::zeros(); 3];
        for (slot, n) in neighbors.iter().enumerate() {
            let k = self
                .index_of(*n)
                .ok_or(FormationError::UnknownNeighbor { id, neighbor: *n })?;
            pts[slot] = self.members[k].planar;
        }
        let me = self
            .member(id)
            .map(|m| m.planar)
            .ok_or(FormationError::UnknownNeighbor { id, neighbor: id })?;
        let weights = triangle_weights(&me, &pts)
            .ok_or(FormationError::DegenerateTriangle { id, neighbors })?;
        if weights.iter().any(|w| w.is_nan() || *w <= 1e-9) {
            return Err(FormationError::NotInsideTriangle {
                id,
                neighbors,
                weights,
            });
        }
        Ok(weights)
    }

    /// Every follower must have a link and be reachable from a leader (Assumption 2).
    pub fn check_links(&self) -> Result<(), FormationError> {
        for m in &self.members {
            if m.role == Role::Follower && m.link.is_none() {
                return Err(FormationError::MissingLink { id: m.id });
            }
        }
        let n = self.members.len();
        let mut out: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (k, m) in self.members.iter().enumerate() {
            if let Some(link) = &m.link {
                for nb in link.in_neighbors {
                    if let Some(j) = self.index_of(nb) {
                        out[j].push(k);
                    }
                }
            }
        }
        let mut seen = vec![false; n];
        let mut stack: Vec<usize> = (0..n)
            .filter(|&k| self.members[k].role.is_leader())
            .collect();
        for &k in &stack {
            seen[k] = true;
        }
        while let Some(j) = stack.pop() {
            for &k in &out[j] {
                if !seen[k] {
                    seen[k] = true;
                    stack.push(k);
                }
            }
        }
        let ids: Vec<u32> = (0..n)
            .filter(|&k| !seen[k])
            .map(|k| self.members[k].id)
            .collect();
        if ids.is_empty() {
            Ok(())
        } else {
            Err(FormationError::Unreachable { ids })
        }
    }

    /// The members that read `id` (its out-neighbours), sorted: its entry of
    /// [`Self::out_neighbors`] without building every member's (each member asks at start).
    pub fn readers_of(&self, id: u32) -> Vec<u32> {
        let mut v: Vec<u32> = self
            .members
            .iter()
            .filter(|m| m.link.is_some_and(|l| l.in_neighbors.contains(&id)))
            .map(|m| m.id)
            .collect();
        v.sort_unstable();
        v
    }

    /// Out-neighbours of every member (who subscribes to whom), sorted, by id.
    pub fn out_neighbors(&self) -> BTreeMap<u32, Vec<u32>> {
        let mut out: BTreeMap<u32, Vec<u32>> =
            self.members.iter().map(|m| (m.id, Vec::new())).collect();
        for m in &self.members {
            if let Some(link) = &m.link {
                for nb in link.in_neighbors {
                    if let Some(v) = out.get_mut(&nb) {
                        v.push(m.id);
                    }
                }
            }
        }
        for v in out.values_mut() {
            v.sort_unstable();
        }
        out
    }

    /// The weight matrix W of eq. 1 in member order (leaders first).
    pub fn weight_matrix(&self) -> DMat {
        let n = self.members.len();
        let mut w = DMat::zeros(n, n);
        for (i, m) in self.members.iter().enumerate() {
            w[(i, i)] = -1.0;
            if let Some(link) = &m.link {
                for (nb, wij) in link.in_neighbors.iter().zip(link.weights) {
                    if let Some(j) = self.index_of(*nb) {
                        w[(i, j)] = wij;
                    }
                }
            }
        }
        w
    }

    /// The follower-follower block L of W (eq. 2).
    pub fn l_block(&self) -> DMat {
        let nl = self.n_leaders();
        let nf = self.members.len() - nl;
        self.weight_matrix().view((nl, nl), (nf, nf)).into_owned()
    }

    /// The checks of Theorems 1 and 2 (ERRATA 5, 7): eq. 21 at t0, L Hurwitz, and
    /// W_L = -L^{-1}(Omega_pf + Omega_sf Omega_ps) one-sum row and equal to the alpha parameters.
    pub fn theorem_checks(&self) -> TheoremChecks {
        let n = self.members.len();
        let nl = self.n_leaders();
        let nf = n - nl;
        let w = self.weight_matrix();
        let l = w.view((nl, nl), (nf, nf)).into_owned();
        let omega = w.view((nl, 0), (nf, nl)).into_owned();
        let omega_pf = omega.columns(0, 3).into_owned();
        let omega_sf = omega.columns(3, nl - 3).into_owned();
        let omega_ps = DMat::from_fn(nl - 3, 3, |i, j| self.members[3 + i].alpha[j]);
        let rhs = -(omega_pf + omega_sf * omega_ps);
        let w_l = l
            .clone()
            .lu()
            .solve(&rhs)
            .unwrap_or_else(|| DMat::from_element(nf, 3, Real::NAN));
        let mut row_sum_error: Real = 0.0;
        let mut alpha_error: Real = 0.0;
        for i in 0..nf {
            let row = w_l.row(i);
            row_sum_error = row_sum_error.max((row.sum() - 1.0).abs());
            for j in 0..3 {
                alpha_error = alpha_error.max((row[j] - self.members[nl + i].alpha[j]).abs());
            }
        }
        // Theorem 1 (eq. 21): [Omega_ps -I 0; Omega_pf Omega_sf L] z_HT(t0) = 0, per component.
        let mut eq21_residual: Real = 0.0;
        for c in 0..3 {
            let z = cdm_math::DVec::from_fn(n, |k, _| self.members[k].position[c]);
            let r = &w * &z;
            for i in 3..n {
                let resid = if i < nl {
                    let a = self.members[i].alpha;
                    a[0] * z[0] + a[1] * z[1] + a[2] * z[2] - z[i]
                } else {
                    r[i]
                };
                let scale = z.amax().max(1.0);
                eq21_residual = eq21_residual.max(resid.abs() / scale);
            }
        }
        let l_max_real = match eigenvalues_by_components(&l) {
            Some(ev) => ev.iter().map(|e| e.0).fold(Real::NEG_INFINITY, Real::max),
            None => Real::NAN,
        };
        TheoremChecks {
            l_max_real_eigenvalue: l_max_real,
            w_l_row_sum_error: row_sum_error,
            w_l_alpha_error: alpha_error,
            eq21_relative_residual: eq21_residual,
        }
    }
}

/// Numbers behind Theorems 1 and 2 for one formation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TheoremChecks {
    /// Largest real part of an eigenvalue of L (Hurwitz when negative).
    pub l_max_real_eigenvalue: Real,
    /// max_i |sum_j W_L[i, j] - 1|.
    pub w_l_row_sum_error: Real,
    /// max_ij |W_L[i, j] - alpha_ij|.
    pub w_l_alpha_error: Real,
    /// Largest residual of eq. 21 relative to the largest coordinate.
    pub eq21_relative_residual: Real,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_team() -> Formation {
        let pts = [
            (1, Role::Primary, [0.0, 0.0, 0.0]),
            (2, Role::Primary, [100.0, 0.0, 0.0]),
            (3, Role::Primary, [0.0, 100.0, 0.0]),
            (4, Role::Secondary, [100.0, 100.0, 0.0]),
            (5, Role::Follower, [40.0, 40.0, 0.0]),
            (6, Role::Follower, [60.0, 60.0, 0.0]),
        ];
        let inputs: Vec<MemberInput> = pts
            .iter()
            .map(|(id, role, p)| MemberInput {
                id: *id,
                role: *role,
                position: Vec3::new(p[0], p[1], p[2]),
                in_neighbors: None,
            })
            .collect();
        let frame = Frame::new(
            &inputs[0].position,
            &inputs[1].position,
            &inputs[2].position,
        )
        .unwrap();
        Formation::new(frame, &inputs).unwrap()
    }

    #[test]
    fn unreachable_followers_are_named() {
        // Strict containment makes every follower reachable (see `graph`), so a closed cycle
        // can only be built by bypassing `set_link`: the check must still catch it.
        let mut f = square_team();
        for (id, other) in [(5u32, 6u32), (6, 5)] {
            let k = f.index_of(id).unwrap();
            f.members[k].link = Some(Link {
                in_neighbors: [other, other, other],
                weights: [1.0 / 3.0; 3],
            });
        }
        assert_eq!(
            f.check_links(),
            Err(FormationError::Unreachable { ids: vec![5, 6] })
        );
        f.set_link(5, [1, 2, 3]).unwrap();
        f.set_link(6, [2, 3, 4]).unwrap();
        assert_eq!(f.check_links(), Ok(()));
    }

    #[test]
    fn links_are_validated() {
        let mut f = square_team();
        assert!(matches!(
            f.set_link(5, [5, 1, 2]),
            Err(FormationError::SelfNeighbor { id: 5 })
        ));
        assert!(matches!(
            f.set_link(5, [9, 1, 2]),
            Err(FormationError::UnknownNeighbor { id: 5, neighbor: 9 })
        ));
        // 6 = (60, 60) is outside the triangle 1, 2, 3 (x + y < 100).
        assert!(matches!(
            f.set_link(6, [1, 2, 3]),
            Err(FormationError::NotInsideTriangle { id: 6, .. })
        ));
        assert!(matches!(
            f.check_links(),
            Err(FormationError::MissingLink { .. })
        ));
    }
}
