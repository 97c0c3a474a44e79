//! `--upload-fence`: before arming, each member uploads the scenario's geofence and obstacles
//! to its vehicle's own geofence (PX4 and ArduPilot keep one that acts even when the ground link
//! is gone), reads it back and compares; its vehicle reports ready only once the fence it holds
//! is the scenario's, so the team arms only once every fence is in place. Pure: messages and the
//! caller's clock in, messages out.
//!
//! The MAVLink mission protocol with mission_type MAV_MISSION_TYPE_FENCE (mavlink.io, "Mission
//! Protocol"): upload is MISSION_COUNT, the vehicle asks for each item with MISSION_REQUEST_INT,
//! MISSION_ITEM_INT answers, and its MISSION_ACK closes (MAV_MISSION_ACCEPTED, or the reason it
//! refuses); read-back is MISSION_REQUEST_LIST, its MISSION_COUNT, a MISSION_REQUEST_INT per
//! item, and our MISSION_ACK. Items (mavlink.io, "Geofence"): the `[geofence]` polygon as
//! MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, one item a vertex, param1 the vertex count;
//! a box obstacle as an exclusion polygon of its footprint's four corners
//! (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION); a cylinder as MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
//! param1 its radius. Latitude and longitude come from the scenario's `[origin]` in 1e-7
//! degree. The autopilots' fence zones are columns: an obstacle's height and the fence's
//! altitude limits are not items (those are parameters: PX4 `GF_MAX_HGT`, ArduPilot
//! `FENCE_ALT_MAX`), so the uploaded fence keeps the vehicle out of the whole column above and
//! below an obstacle, which is stricter than the scenario.

use std::time::Duration;

use mavlink::dialects::common::{
    MavCmd, MavFrame, MavMessage, MavMissionResult, MavMissionType, MISSION_ACK_DATA,
    MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA, MISSION_REQUEST_INT_DATA, MISSION_REQUEST_LIST_DATA,
};

use crate::messages::Target;
use cdm_math::{Real, Vec3};
use cdm_model::airspace::Shape;
use cdm_scenario::{GeoOrigin, GeofenceSpec, ObstacleSpec};

/// Resend what is unanswered after this long (the mission protocol's retry).
pub const FENCE_RETRY: Duration = Duration::from_millis(1500);
/// Give up (the vehicle is named) after this long without the fence in place.
pub const FENCE_DEADLINE: Duration = Duration::from_secs(15);

/// One fence item: its command, param1 (a vertex count or a radius) and its point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FenceItem {
    pub command: MavCmd,
    pub param1: f32,
    /// Latitude and longitude, 1e-7 degree.
    pub lat_e7: i32,
    pub lon_e7: i32,
}

/// The scenario's geofence and obstacles as fence items through `origin`, in file order: the
/// inclusion polygon, then each obstacle.
pub fn fence_items(
    origin: &GeoOrigin,
    fence: Option<&GeofenceSpec>,
    obstacles: &[ObstacleSpec],
) -> Vec<FenceItem> {
    let point = |command, param1: f32, x: Real, y: Real| {
        let g = origin.geodetic(&Vec3::new(x, y, 0.0));
        FenceItem {
            command,
            param1,
            lat_e7: (g.lat_deg * 1e7).round() as i32,
            lon_e7: (g.lon_deg * 1e7).round() as i32,
        }
    };
    let mut items = Vec::new();
    if let Some(f) = fence {
        let n = f.polygon.len() as f32;
        for v in &f.polygon {
            items.push(point(
                MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                n,
                v[0],
                v[1],
            ));
        }
    }
    for o in obstacles {
        match o.shape() {
            Shape::Box { min, max } => {
                for (x, y) in [
                    (min[0], min[1]),
                    (max[0], min[1]),
                    (max[0], max[1]),
                    (min[0], max[1]),
                ] {
                    items.push(point(
                        MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
                        4.0,
                        x,
                        y,
                    ));
                }
            }
            Shape::Cylinder {
                center, radius_m, ..
            } => items.push(point(
                MavCmd::MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
                radius_m as f32,
                center[0],
                center[1],
            )),
        }
    }
    items
}

/// Why a vehicle does not hold the scenario's fence (every variant names the member).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FenceError {
    #[error("agent {agent}: its vehicle refused the fence ({result:?}); nothing is armed")]
    Refused {
        agent: u32,
        result: MavMissionResult,
    },
    #[error("agent {agent}: its vehicle's fence read back differs from the scenario's at item {seq} ({count} items read, {uploaded} uploaded); nothing is armed")]
    Differs {
        agent: u32,
        seq: u16,
        count: u16,
        uploaded: u16,
    },
    #[error("agent {agent}: its vehicle did not take the fence within {} s ({stage}); nothing is armed", deadline.as_secs())]
    Timeout {
        agent: u32,
        stage: &'static str,
        deadline: Duration,
    },
}

#[derive(Debug, Clone, PartialEq)]
enum Stage {
    Upload,
    /// Reading back: the count once known, and the items read so far.
    Read {
        count: Option<u16>,
        read: Vec<MISSION_ITEM_INT_DATA>,
    },
    Done,
}

/// One member's fence upload and read-back.
#[derive(Debug, Clone)]
pub struct FenceUpload {
    agent: u32,
    items: Vec<FenceItem>,
    stage: Stage,
    started: Option<Duration>,
    /// When the last message that waits for an answer went out.
    asked: Option<Duration>,
    outbox: Vec<MavMessage>,
    fault: Option<FenceError>,
}

fn fence_type() -> MavMissionType {
    MavMissionType::MAV_MISSION_TYPE_FENCE
}

impl FenceUpload {
    pub fn new(agent: u32, items: Vec<FenceItem>) -> Self {
        FenceUpload {
            agent,
            items,
            stage: Stage::Upload,
            started: None,
            asked: None,
            outbox: Vec::new(),
            fault: None,
        }
    }

    /// Whether the vehicle holds the fence, read back and equal.
    pub fn done(&self) -> bool {
        self.stage == Stage::Done
    }

    /// What to send at `now` to the vehicle `t` (the first call starts the upload); the
    /// failure once the vehicle refused, answered wrong or stayed silent too long.
    pub fn on_tick(&mut self, now: Duration, t: Target) -> Result<Vec<MavMessage>, FenceError> {
        if let Some(f) = self.fault {
            return Err(f);
        }
        if self.done() {
            // The read-back's closing MISSION_ACK, once.
            return Ok(std::mem::take(&mut self.outbox));
        }
        let started = *self.started.get_or_insert(now);
        if now.saturating_sub(started) > FENCE_DEADLINE {
            let stage = match self.stage {
                Stage::Upload => "upload",
                _ => "read-back",
            };
            let e = FenceError::Timeout {
                agent: self.agent,
                stage,
                deadline: FENCE_DEADLINE,
            };
            self.fault = Some(e);
            return Err(e);
        }
        let due = self
            .asked
            .is_none_or(|a| now.saturating_sub(a) >= FENCE_RETRY);
        if due && self.outbox.is_empty() {
            // Nothing answered in time (or the first call): ask again from where we are.
            let ask = match &self.stage {
                Stage::Upload => self.count_msg(t),
                Stage::Read { count: None, .. } => list_msg(t),
                Stage::Read {
                    count: Some(_),
                    read,
                } => request_msg(t, read.len() as u16),
                Stage::Done => return Ok(Vec::new()),
            };
            self.outbox.push(ask);
        }
        if !self.outbox.is_empty() {
            self.asked = Some(now);
        }
        Ok(std::mem::take(&mut self.outbox))
    }

    fn count_msg(&self, t: Target) -> MavMessage {
        MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: self.items.len() as u16,
            target_system: t.system,
            target_component: t.component,
            mission_type: fence_type(),
            ..MISSION_COUNT_DATA::default()
        })
    }

    /// A fence message from the vehicle `t`; others (another mission type) are not ours.
    /// Returns whether it was one.
    pub fn on_message(&mut self, t: Target, msg: &MavMessage) -> bool {
        match (msg, &mut self.stage) {
            (MavMessage::MISSION_REQUEST_INT(r), Stage::Upload)
                if r.mission_type == fence_type() =>
            {
                if let Some(item) = self.items.get(usize::from(r.seq)) {
                    self.outbox.push(item_msg(t, r.seq, item));
                }
            }
            (MavMessage::MISSION_ACK(a), Stage::Upload) if a.mission_type == fence_type() => {
                if a.mavtype == MavMissionResult::MAV_MISSION_ACCEPTED {
                    self.stage = Stage::Read {
                        count: None,
                        read: Vec::new(),
                    };
                    self.outbox.push(list_msg(t));
                } else {
                    self.fault = Some(FenceError::Refused {
                        agent: self.agent,
                        result: a.mavtype,
                    });
                }
            }
            (MavMessage::MISSION_COUNT(c), Stage::Read { count, read })
                if c.mission_type == fence_type() && count.is_none() =>
            {
                *count = Some(c.count);
                self.outbox.push(if c.count == 0 {
                    ack_msg(t)
                } else {
                    request_msg(t, read.len() as u16)
                });
                if c.count == 0 {
                    self.finish_read();
                }
            }
            (
                MavMessage::MISSION_ITEM_INT(i),
                Stage::Read {
                    count: Some(n),
                    read,
                },
            ) if i.mission_type == fence_type() && usize::from(i.seq) == read.len() => {
                read.push(i.clone());
                if read.len() < usize::from(*n) {
                    self.outbox.push(request_msg(t, read.len() as u16));
                } else {
                    self.outbox.push(ack_msg(t));
                    self.finish_read();
                }
            }
            (
                MavMessage::MISSION_REQUEST_INT(_)
                | MavMessage::MISSION_ACK(_)
                | MavMessage::MISSION_COUNT(_)
                | MavMessage::MISSION_ITEM_INT(_),
                _,
            ) => {}
            _ => return false,
        }
        true
    }

    /// All items read: equal to what was uploaded, or the first difference.
    fn finish_read(&mut self) {
        let Stage::Read { read, .. } = &self.stage else {
            return;
        };
        let differs = (0..read.len().max(self.items.len())).find(|&k| {
            match (read.get(k), self.items.get(k)) {
                (Some(r), Some(u)) => !same(r, u),
                _ => true,
            }
        });
        match differs {
            None => self.stage = Stage::Done,
            Some(k) => {
                self.fault = Some(FenceError::Differs {
                    agent: self.agent,
                    seq: k as u16,
                    count: read.len() as u16,
                    uploaded: self.items.len() as u16,
                })
            }
        }
    }
}

/// A read-back item is the uploaded one: same command, param1 and point.
fn same(r: &MISSION_ITEM_INT_DATA, u: &FenceItem) -> bool {
    r.command == u.command && r.param1 == u.param1 && r.x == u.lat_e7 && r.y == u.lon_e7
}

fn item_msg(t: Target, seq: u16, item: &FenceItem) -> MavMessage {
    MavMessage::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
        param1: item.param1,
        x: item.lat_e7,
        y: item.lon_e7,
        seq,
        command: item.command,
        target_system: t.system,
        target_component: t.component,
        frame: MavFrame::MAV_FRAME_GLOBAL,
        mission_type: fence_type(),
        ..MISSION_ITEM_INT_DATA::default()
    })
}

fn list_msg(t: Target) -> MavMessage {
    MavMessage::MISSION_REQUEST_LIST(MISSION_REQUEST_LIST_DATA {
        target_system: t.system,
        target_component: t.component,
        mission_type: fence_type(),
    })
}

fn request_msg(t: Target, seq: u16) -> MavMessage {
    MavMessage::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
        seq,
        target_system: t.system,
        target_component: t.component,
        mission_type: fence_type(),
    })
}

fn ack_msg(t: Target) -> MavMessage {
    MavMessage::MISSION_ACK(MISSION_ACK_DATA {
        target_system: t.system,
        target_component: t.component,
        mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
        mission_type: fence_type(),
        ..MISSION_ACK_DATA::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: Target = Target {
        system: 1,
        component: 1,
    };

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn items() -> Vec<FenceItem> {
        let origin = GeoOrigin {
            lat_deg: 47.397742,
            lon_deg: 8.545594,
            alt_m: 488.0,
            heading_deg: 90.0,
        };
        let fence = GeofenceSpec {
            polygon: vec![[-50.0, -50.0], [50.0, -50.0], [0.0, 60.0]],
            min_z_m: 0.0,
            max_z_m: 100.0,
        };
        let obstacles = [
            ObstacleSpec {
                name: "tower".into(),
                shape: Shape::Box {
                    min: [10.0, 10.0, 0.0],
                    max: [12.0, 14.0, 30.0],
                },
            },
            ObstacleSpec {
                name: "mast".into(),
                shape: Shape::Cylinder {
                    center: [-20.0, 0.0],
                    radius_m: 2.5,
                    min_z_m: 0.0,
                    max_z_m: 40.0,
                },
            },
        ];
        fence_items(&origin, Some(&fence), &obstacles)
    }

    /// A vehicle that keeps what it is sent (or refuses with `refuse`, or changes item
    /// `corrupt` when it hands it back), answering at once.
    struct Vehicle {
        expected: u16,
        held: Vec<MISSION_ITEM_INT_DATA>,
        refuse: Option<MavMissionResult>,
        corrupt: Option<u16>,
        acks: u32,
    }

    impl Vehicle {
        fn answer(&mut self, m: &MavMessage) -> Vec<MavMessage> {
            let fence = fence_type();
            match m {
                MavMessage::MISSION_COUNT(c) => {
                    if let Some(result) = self.refuse {
                        return vec![MavMessage::MISSION_ACK(MISSION_ACK_DATA {
                            mavtype: result,
                            mission_type: fence,
                            ..MISSION_ACK_DATA::default()
                        })];
                    }
                    (self.expected, self.held) = (c.count, Vec::new());
                    vec![request_msg(T, 0)]
                }
                MavMessage::MISSION_ITEM_INT(i) => {
                    self.held.push(i.clone());
                    if self.held.len() < usize::from(self.expected) {
                        vec![request_msg(T, self.held.len() as u16)]
                    } else {
                        vec![MavMessage::MISSION_ACK(MISSION_ACK_DATA {
                            mission_type: fence,
                            ..MISSION_ACK_DATA::default()
                        })]
                    }
                }
                MavMessage::MISSION_REQUEST_LIST(_) => {
                    vec![MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
                        count: self.held.len() as u16,
                        mission_type: fence,
                        ..MISSION_COUNT_DATA::default()
                    })]
                }
                MavMessage::MISSION_REQUEST_INT(r) => {
                    let mut i = self.held[usize::from(r.seq)].clone();
                    if self.corrupt == Some(r.seq) {
                        i.x += 1;
                    }
                    vec![MavMessage::MISSION_ITEM_INT(i)]
                }
                MavMessage::MISSION_ACK(_) => {
                    self.acks += 1;
                    Vec::new()
                }
                other => panic!("unexpected {other:?}"),
            }
        }
    }

    fn run(v: &mut Vehicle) -> (FenceUpload, Result<(), FenceError>, u64) {
        let mut up = FenceUpload::new(4, items());
        for k in 0..2000u64 {
            let now = ms(20 * k);
            match up.on_tick(now, T) {
                Err(e) => return (up, Err(e), 20 * k),
                Ok(out) => {
                    for m in out {
                        for reply in v.answer(&m) {
                            assert!(up.on_message(T, &reply));
                        }
                    }
                }
            }
            if up.done() {
                // What is left to send (the read-back's MISSION_ACK) goes out at the next tick.
                for m in up.on_tick(ms(20 * k + 20), T).expect("done") {
                    assert!(v.answer(&m).is_empty());
                }
                return (up, Ok(()), 20 * k);
            }
        }
        panic!("neither done nor failed");
    }

    fn vehicle() -> Vehicle {
        Vehicle {
            expected: 0,
            held: Vec::new(),
            refuse: None,
            corrupt: None,
            acks: 0,
        }
    }

    #[test]
    fn the_scenario_becomes_polygons_and_circles() {
        let items = items();
        let kinds: Vec<(MavCmd, f32)> = items.iter().map(|i| (i.command, i.param1)).collect();
        let incl = (MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 3.0);
        let excl = (MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, 4.0);
        let circle = (MavCmd::MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 2.5);
        assert_eq!(
            kinds,
            vec![incl, incl, incl, excl, excl, excl, excl, circle]
        );
        // Heading 90: +y is north, so the third vertex (y = 60) is the northernmost.
        assert!(items[2].lat_e7 > items[0].lat_e7);
        assert_eq!(items[0].lat_e7, items[1].lat_e7);
    }

    #[test]
    fn a_vehicle_that_takes_the_fence_holds_it_read_back() {
        let mut v = vehicle();
        let (up, result, _) = run(&mut v);
        assert_eq!(result, Ok(()));
        assert!(up.done());
        assert_eq!(v.acks, 1, "the read-back is closed with one MISSION_ACK");
        let want = items();
        assert_eq!(v.held.len(), want.len());
        for (h, w) in v.held.iter().zip(&want) {
            assert!(same(h, w), "{h:?} != {w:?}");
            assert_eq!(h.mission_type, fence_type());
        }
    }

    #[test]
    fn a_refusal_a_difference_and_silence_are_named() {
        let mut v = vehicle();
        v.refuse = Some(MavMissionResult::MAV_MISSION_DENIED);
        let (up, result, _) = run(&mut v);
        assert!(!up.done());
        let e = result.unwrap_err();
        assert!(
            e.to_string()
                .starts_with("agent 4: its vehicle refused the fence (MAV_MISSION_DENIED)"),
            "{e}"
        );
        let mut v = vehicle();
        v.corrupt = Some(5);
        let (_, result, _) = run(&mut v);
        assert!(
            matches!(result, Err(FenceError::Differs { seq: 5, .. })),
            "{result:?}"
        );
        // A vehicle that never answers: asked again every FENCE_RETRY, named at the deadline.
        let mut up = FenceUpload::new(4, items());
        let mut counts = 0;
        let mut failed = None;
        for k in 0..2000u64 {
            match up.on_tick(ms(20 * k), T) {
                Ok(out) => counts += out.len(),
                Err(e) => {
                    failed = Some((20 * k, e));
                    break;
                }
            }
        }
        let (at, e) = failed.expect("named");
        assert_eq!(at, FENCE_DEADLINE.as_millis() as u64 + 20);
        assert_eq!(counts, 11, "one MISSION_COUNT every 1.5 s over 15 s");
        assert!(matches!(
            e,
            FenceError::Timeout {
                stage: "upload",
                ..
            }
        ));
    }
}
