//! What a member does with its vehicle between joining and the real-time core, and how the core
//! is flown with it. The model has nothing to do. A MAVLink plant answers the team's arm order
//! (cdm-mavlink `team_arm`: the orchestrator orders the arming once every vehicle is ready) and
//! publishes its vehicle report beside each pacing report (cdm-mavlink `report`).

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use cdm_mavlink::{before_start, LinkFigures, MavlinkPlant, Reporting};
use cdm_runtime::member_core::Finished;
use cdm_runtime::member_loop::{fly as fly_core, LoopError};
use cdm_runtime::realtime::RealtimeCore;
use cdm_runtime::realtime_loop::unix_now_ns;
use cdm_runtime::seams::{Clock, ModelVehicle, MonotonicClock, Vehicle};

use crate::member_error::MemberError;
use cdm_iox::{MemberPorts, TransportError};
use cdm_runtime::messages::ClockMsg;

/// A vehicle's part before the start, and its report during the flight.
pub(crate) trait BeforeStart: Vehicle + Sized {
    /// Called once the member has joined: returns the first clock message of the core's, if
    /// it read one. `join` bounds the waits.
    fn before_start(
        &self,
        ports: &mut MemberPorts,
        hash: u64,
        waits: (&MonotonicClock, Duration),
        interrupted: &AtomicBool,
    ) -> Result<Option<ClockMsg>, MemberError>;

    /// The link whose figures go beside each pacing report, if any.
    fn link(&self) -> Option<LinkFigures>;
}

impl BeforeStart for ModelVehicle<'_> {
    fn before_start(
        &self,
        _: &mut MemberPorts,
        _: u64,
        _: (&MonotonicClock, Duration),
        _: &AtomicBool,
    ) -> Result<Option<ClockMsg>, MemberError> {
        Ok(None)
    }

    fn link(&self) -> Option<LinkFigures> {
        None
    }
}

impl BeforeStart for MavlinkPlant<'_> {
    fn before_start(
        &self,
        ports: &mut MemberPorts,
        hash: u64,
        (clock, join): (&MonotonicClock, Duration),
        interrupted: &AtomicBool,
    ) -> Result<Option<ClockMsg>, MemberError> {
        Ok(Some(before_start(
            self,
            hash,
            ports,
            clock,
            join,
            interrupted,
        )?))
    }

    fn link(&self) -> Option<LinkFigures> {
        Some(self.figures())
    }
}

/// Flies `core` in real time: first the clock message [`BeforeStart::before_start`] read (the
/// start, or a stop), then the loop, over a transport that adds the vehicle's report.
pub(crate) fn fly<V: Vehicle>(
    core: &mut RealtimeCore<V>,
    ports: &mut MemberPorts,
    (first, link): (Option<ClockMsg>, Option<LinkFigures>),
    clock: &MonotonicClock,
    interrupted: &AtomicBool,
) -> Result<Finished, LoopError<TransportError>> {
    if let Some(c) = first {
        let done = core.on_clock(&c, clock.now(), unix_now_ns());
        if let Some(done) = done.map_err(LoopError::Fault)? {
            return Ok(done);
        }
    }
    match link {
        Some(link) => {
            let (id, hash) = (core.id(), core.hash());
            let mut reporting = Reporting::new(ports, link, id, hash);
            fly_core(core, &mut reporting, clock, interrupted, None)
        }
        None => fly_core(core, ports, clock, interrupted, None),
    }
}
