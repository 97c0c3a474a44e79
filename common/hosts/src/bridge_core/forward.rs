//! What goes down to a ready host: the crossing states its members read, then the clock
//! messages that let them use those states, with the repairs each loss notice announces carried
//! at this host's relays first; and what a lost host's relays still do for repairs.

use std::time::{Duration, Instant};

use cdm_runtime::messages::{ClockCommand, ClockMsg, LossNotice, SteerNotice};
use cdm_zenoh::{Down, Up};

use super::{Ctx, Remote};
use crate::error::LinkLost;
use crate::handover::{self, warn_hand_over};
use crate::host_link::HostLink;
use crate::links::Note;
use crate::relay::Relay;
use crate::repairs::RepairStep;

/// The clock and the crossing states towards a ready host; true when anything went.
pub(super) fn forward<L: HostLink<In = Up, Out = Down>, R: Relay>(
    r: &mut Remote<L, R>,
    ctx: &Ctx,
    now: Instant,
) -> Result<bool, LinkLost> {
    let mut clocks = vec![];
    let mut batch = vec![];
    for (k, (&g, relay)) in r.relays.iter_mut().enumerate() {
        // Every relay subscribes to the clock: each drains its own, the first one's are kept.
        relay.receive_clock(|c| {
            if k == 0 {
                clocks.push(c);
            }
        })?;
        let forwarder = &r.forwarder;
        relay.receive_neighbors(|m| {
            if forwarder.get(&m.id) == Some(&g) {
                batch.push(m);
            }
        })?;
    }
    let moved = !clocks.is_empty() || !batch.is_empty();
    // States first: a grant must never reach members before the states it lets them use.
    if !batch.is_empty() {
        r.chan.send(&Down::States(batch))?;
        r.last_sent = now;
    }
    for c in worth_sending(&clocks, &mut r.last_notice) {
        // A new loss: the relays carry the repaired links before the daemon's members hear it.
        let step = r.repairs.on_notice(c.loss())?;
        carry_repair(r, ctx, &step, now);
        r.stop_sent |= matches!(c.command(), ClockCommand::Stop(_));
        r.chan.send(&Down::Clock(c))?;
        r.last_sent = now;
    }
    Ok(moved)
}

/// A lost host's relays still stand in for its members' last states: repairs that make a
/// member of this host read one of them are carried (linked, history handed over), as the
/// killed member's own publisher would on one host.
pub(super) fn follow_repairs<L, R: Relay>(r: &mut Remote<L, R>, ctx: &Ctx, now: Instant) {
    let mut clocks = vec![];
    for (k, relay) in r.relays.values_mut().enumerate() {
        let _ = relay.receive_clock(|c| {
            if k == 0 {
                clocks.push(c);
            }
        });
        let _ = relay.receive_neighbors(|_| {});
    }
    for c in worth_sending(&clocks, &mut r.last_notice) {
        match r.repairs.on_notice(c.loss()) {
            Ok(step) => carry_repair(r, ctx, &step, now),
            Err(e) => tracing::warn!("host {}: the repairs its relays carry: {e}", r.host),
        }
    }
    // Nothing more will cross from a lost host: its relays hand over what they hold.
    let wait = Duration::ZERO;
    handover::poll(&mut r.handing, &mut r.relays, wait, now, warn_hand_over);
}

/// The loss and command notices of the last clock message sent.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct SentNotices {
    pub loss: Option<LossNotice>,
    pub steer: Option<SteerNotice>,
}

/// Of the clock messages drained, in order: each whose loss or command notice differs from the
/// one sent before (members must see every loss, every rise of the connected count, and every
/// command notice: a real-time command's proposal, then its decision, and the next one's
/// proposal may follow each other within one drain), and the newest.
pub(super) fn worth_sending(clocks: &[ClockMsg], last: &mut SentNotices) -> Vec<ClockMsg> {
    let mut out = vec![];
    for (k, c) in clocks.iter().enumerate() {
        let notices = SentNotices {
            loss: c.loss(),
            steer: c.steer(),
        };
        if notices != *last || k + 1 == clocks.len() {
            *last = notices;
            out.push(*c);
        }
    }
    out
}

/// A repair's new links at this host's relays: a reader on that host gets its new
/// in-neighbour's states forwarded (one relay subscribes to it here), a reader on this host is
/// woken by the relay of its new in-neighbour there; history goes to new readers once every
/// link is connected. A link that cannot be opened (no room left) is left for the team core's
/// deadline, which names it.
fn carry_repair<L, R: Relay>(r: &mut Remote<L, R>, ctx: &Ctx, step: &RepairStep, now: Instant) {
    for &(reader, writer) in &step.new_links {
        let (hr, hw) = (ctx.regions.host_of(reader), ctx.regions.host_of(writer));
        let opened = if hr == r.host && hw != r.host && !r.forwarder.contains_key(&writer) {
            r.forwarder.insert(writer, reader);
            r.relays.get_mut(&reader).map(|p| p.connect(&[writer], &[]))
        } else if hw == r.host && hr == 0 {
            r.relays.get_mut(&writer).map(|p| p.connect(&[], &[reader]))
        } else {
            None
        };
        if let Some(Err(e)) = opened {
            tracing::warn!(
                host = r.host,
                "cannot carry the repaired link {writer} -> {reader}: {e}"
            );
        }
        if hr != hw && (hr == r.host || hw == r.host) {
            r.notes.push(Note::CrossingAdded(writer, reader));
        }
    }
    if step.hand_over {
        let from = step.needs_from;
        handover::start(&mut r.handing, from, &mut r.relays, now, warn_hand_over);
    }
}
