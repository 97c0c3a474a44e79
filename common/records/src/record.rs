//! What every flown tick gets, in one place for `simulate` (the engine) and `launch` (the
//! processes), so the two cannot drift apart: the desired positions r_HT (eqs. 13, 23), the
//! audit of the tick, and its telemetry rows sorted by id. Buffers are reused from tick to tick.

use crate::audit::{Auditor, FaultRecord};
use crate::telemetry::{Row, TelemetrySink};
use cdm_math::{Real, Vec3};
use cdm_model::outcome::FaultKind;
use cdm_model::step::tick_time;
use cdm_scenario::Scenario;

/// Audits and writes one tick at a time.
#[derive(Debug, Clone)]
pub struct TickRecorder {
    /// Member indices sorted by id (telemetry order).
    order: Vec<usize>,
    ht: Vec<Vec3>,
    pos: Vec<Vec3>,
    /// Velocities, kept only when the audit checks `[vehicle]` limits.
    vel: Vec<Vec3>,
    rows: Vec<Row>,
}

impl TickRecorder {
    /// A recorder for `s`'s team.
    pub fn new(s: &Scenario) -> Self {
        let n = s.formation.members.len();
        TickRecorder {
            order: s.id_order(),
            ht: Vec::with_capacity(n),
            pos: vec![Vec3::zeros(); n],
            vel: vec![Vec3::zeros(); n],
            rows: Vec::with_capacity(n),
        }
    }

    /// Records `tick`: `member(k)` gives member k's (formation order) position and velocity, or
    /// `None` for a member no longer flying (lost: no telemetry row; the audit, which has taken
    /// it out, keeps its last position). Returns the tick's time t_k = k * dt.
    pub fn record(
        &mut self,
        s: &Scenario,
        tick: u64,
        audit: &mut Auditor,
        tel: &mut dyn TelemetrySink,
        member: impl Fn(usize) -> Option<(Vec3, Vec3)>,
    ) -> Result<Real, FaultRecord> {
        let t = tick_time(tick, s.dt_s());
        self.record_at(s, (tick, t), audit, tel, member)?;
        Ok(t)
    }

    /// [`Self::record`] at time `t` rather than the tick's: the real-time monitor's audit
    /// instants (`tick` is the audit index, `t` = index / audit rate).
    pub fn record_at(
        &mut self,
        s: &Scenario,
        (tick, t): (u64, Real),
        audit: &mut Auditor,
        tel: &mut dyn TelemetrySink,
        member: impl Fn(usize) -> Option<(Vec3, Vec3)>,
    ) -> Result<(), FaultRecord> {
        s.desired_positions(t, &mut self.ht);
        for (k, p) in self.pos.iter_mut().enumerate() {
            if let Some((r, _)) = member(k) {
                *p = r;
            }
        }
        audit.observe(tick, t, &self.pos, &self.ht);
        if audit.wants_velocities() {
            for (k, v) in self.vel.iter_mut().enumerate() {
                if let Some((_, flown)) = member(k) {
                    *v = flown;
                }
            }
            audit.observe_velocities(tick, t, &self.vel);
        }
        if !tel.keeps(tick) {
            return Ok(());
        }
        self.rows.clear();
        for &k in &self.order {
            let Some((r, v)) = member(k) else { continue };
            let m = &s.formation.members[k];
            self.rows.push(Row {
                tick,
                t_s: t,
                id: m.id,
                role: m.role,
                r,
                v,
                ht: self.ht[k],
            });
        }
        tel.write_tick(&self.rows)
            .map_err(|e| write_fault(tick, &e))
    }

    /// The positions of the last recorded tick (formation order).
    pub fn positions(&self) -> &[Vec3] {
        &self.pos
    }

    /// The desired positions r_HT of the last recorded tick (formation order).
    pub fn desired(&self) -> &[Vec3] {
        &self.ht
    }
}

/// A telemetry write or flush that failed (a full disk) at `tick`: the run stops there and its
/// audit names the file's error; the file keeps its whole ticks.
pub fn write_fault(tick: u64, e: &std::io::Error) -> FaultRecord {
    FaultRecord::new(
        FaultKind::Io,
        None,
        None,
        tick,
        format!("cannot write telemetry: {e}"),
    )
}
