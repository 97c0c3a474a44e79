//! The flight a host daemon needs to know to start its members, read from `launch`'s options
//! (here, not in cdm-hosts: the daemon crate sits below the launch loop that owns the options).

use cdm_hosts::TeamFlight;

use crate::launch::LaunchOptions;

/// The flight of `launch`'s options.
pub fn flight_of(o: &LaunchOptions) -> TeamFlight {
    TeamFlight {
        window: o.window,
        realtime_stale_after: o.realtime.as_ref().map(|rt| rt.stale_after),
        realtime_priority: o.realtime.as_ref().and_then(|rt| rt.rt_priority),
        repair: o.on_loss == cdm_engine::loss::OnLoss::Repair && o.spawn && o.realtime.is_none(),
        recording: (o.realtime.as_ref())
            .is_some_and(|rt| rt.record)
            .then(|| o.out.join(cdm_recording::DIR)),
    }
}
