//! Who may join: a daemon's request checked against the team (protocol, team, scenario, the host
//! its key or certificate binds it to, a free host), and the share of the team it is given.

use std::collections::BTreeMap;

use cdm_zenoh::{Assignment, JoinRequest, PROTOCOL_VERSION};

use super::{Ctx, Remote};
use crate::error::Refusal;

/// A request asks on its own host's key (`join/k` for `host: Some(k)`): with TLS, access control
/// lets only host k's certificate ask there, so the host number is the certificate's.
pub(super) fn bound(ctx: &Ctx, slot: Option<u32>, host: Option<u32>) -> Result<(), Refusal> {
    match (slot, host) {
        (None, _) if ctx.tls => Err(Refusal::Unbound),
        (s, h) if s != h => Err(Refusal::Slot { slot, host }),
        _ => Ok(()),
    }
}

/// Host `host`'s share of the team, as its daemon needs it.
pub(super) fn assignment(ctx: &Ctx, host: u32) -> Assignment {
    Assignment {
        team: ctx.team.as_str().to_owned(),
        host,
        hosts_of: ctx.regions.pairs(),
        scenario_json: ctx.scenario_json.clone(),
        scenario_hash: ctx.hash,
        window: ctx.flight.window,
        link_timeout_ms: ctx.link_timeout.as_millis() as u64,
        realtime_stale_after_s: ctx.flight.realtime_stale_after.map(|d| d.as_secs_f64()),
        realtime_priority: ctx.flight.realtime_priority,
        repair: ctx.flight.repair,
        record: ctx.flight.recording.is_some(),
    }
}

/// The host a join request may take, or why it is refused (another protocol, team or
/// scenario; a host number out of range or taken; no host left).
pub(super) fn which_host<L, R>(
    ctx: &Ctx,
    remotes: &BTreeMap<u32, Remote<L, R>>,
    q: &JoinRequest,
) -> Result<u32, Refusal> {
    let team = || ctx.team.as_str().to_owned();
    if q.version != PROTOCOL_VERSION {
        return Err(Refusal::Protocol {
            theirs: q.version,
            ours: PROTOCOL_VERSION,
        });
    }
    if let Some(t) = q.team.as_deref().filter(|t| *t != ctx.team.as_str()) {
        let asked = t.to_owned();
        return Err(Refusal::Team {
            asked,
            team: team(),
        });
    }
    if let Some(h) = q.scenario_hash.filter(|&h| h != ctx.hash) {
        let (theirs, ours) = (h, ctx.hash);
        return Err(Refusal::Scenario {
            theirs,
            team: team(),
            ours,
        });
    }
    let hosts = ctx.regions.hosts();
    match q.host {
        Some(host) if host == 0 || host >= hosts => Err(Refusal::NoSuchHost {
            host,
            team: team(),
            last: hosts - 1,
        }),
        Some(host) => match remotes.get(&host) {
            Some(r) => Err(Refusal::Taken {
                host,
                team: team(),
                by: r.who.clone(),
            }),
            None => Ok(host),
        },
        None => (1..hosts)
            .find(|h| !remotes.contains_key(h))
            .ok_or_else(|| Refusal::Full {
                others: hosts - 1,
                team: team(),
            }),
    }
}
