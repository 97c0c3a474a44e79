//! The seam between a host's state machine and this host's shared memory: a relay stands in for
//! a member of another host (its states published here, its readers woken, the clock and its
//! in-neighbours' states read for it). iceoryx2's relay ports implement it
//! (`MemberPorts::open_relay`); the unit tests fly the bridge over [`FakeRelay`].

use cdm_iox::{MemberPorts, TeamName, TransportError};
use cdm_runtime::messages::{ClockMsg, StateMsg};

/// One relay's ports, as the bridge and the daemon use them.
pub trait Relay: Sized {
    /// Opens the relay of member `id` of host `host`: it reads `ins` here (their states are
    /// forwarded to its host) and wakes `outs` here (its states come from its host).
    fn open(
        team: &TeamName,
        host: u32,
        id: u32,
        scenario_hash: u64,
        ins: &[u32],
        outs: &[u32],
    ) -> Result<Self, TransportError>;
    /// Publishes a state (or fault report) of the member, and wakes its readers.
    fn publish(&mut self, msg: StateMsg) -> Result<(), TransportError>;
    /// Publishes a state of the member without waking its readers yet.
    fn publish_quietly(&mut self, msg: StateMsg) -> Result<(), TransportError>;
    /// Wakes the member's readers.
    fn notify_readers(&mut self) -> Result<(), TransportError>;
    /// Every clock message received since the last call, in order.
    fn receive_clock(&mut self, f: impl FnMut(ClockMsg)) -> Result<(), TransportError>;
    /// Every in-neighbour state received since the last call, in order.
    fn receive_neighbors(&mut self, f: impl FnMut(StateMsg)) -> Result<(), TransportError>;
    /// Also reads `subscribe` and wakes `notify` (a repair's new links).
    fn connect(&mut self, subscribe: &[u32], notify: &[u32]) -> Result<(), TransportError>;
    /// True when the history kept for new readers reaches back to `tick`.
    fn history_reaches(&self, tick: u64) -> bool;
    /// Hands the history to the readers connected since.
    fn hand_over(&mut self) -> Result<(), TransportError>;
}

impl Relay for MemberPorts {
    fn open(
        team: &TeamName,
        host: u32,
        id: u32,
        scenario_hash: u64,
        ins: &[u32],
        outs: &[u32],
    ) -> Result<Self, TransportError> {
        MemberPorts::open_relay(team, host, id, scenario_hash, ins, outs)
    }
    fn publish(&mut self, msg: StateMsg) -> Result<(), TransportError> {
        MemberPorts::publish(self, msg).map(drop)
    }
    fn publish_quietly(&mut self, msg: StateMsg) -> Result<(), TransportError> {
        MemberPorts::publish_quietly(self, msg).map(drop)
    }
    fn notify_readers(&mut self) -> Result<(), TransportError> {
        MemberPorts::notify_readers(self)
    }
    fn receive_clock(&mut self, f: impl FnMut(ClockMsg)) -> Result<(), TransportError> {
        MemberPorts::receive_clock(self, f).map(drop)
    }
    fn receive_neighbors(&mut self, f: impl FnMut(StateMsg)) -> Result<(), TransportError> {
        MemberPorts::receive_neighbors(self, f).map(drop)
    }
    fn connect(&mut self, subscribe: &[u32], notify: &[u32]) -> Result<(), TransportError> {
        MemberPorts::connect(self, subscribe, notify)
    }
    fn history_reaches(&self, tick: u64) -> bool {
        MemberPorts::history_reaches(self, tick)
    }
    fn hand_over(&mut self) -> Result<(), TransportError> {
        MemberPorts::hand_over(self)
    }
}

/// A relay whose shared memory is the test's: what it should receive is queued, what it
/// published, woke, connected and handed over is recorded.
#[cfg(test)]
#[derive(Debug, Default)]
pub struct FakeRelay {
    pub ins: Vec<u32>,
    pub outs: Vec<u32>,
    pub clock: std::collections::VecDeque<ClockMsg>,
    pub neighbors: std::collections::VecDeque<StateMsg>,
    pub published: Vec<StateMsg>,
    pub woken: usize,
    pub connected: Vec<(Vec<u32>, Vec<u32>)>,
    /// The oldest tick of the history kept (`None`: nothing kept).
    pub history_from: Option<u64>,
    pub handed_over: usize,
}

#[cfg(test)]
impl Relay for FakeRelay {
    fn open(
        _team: &TeamName,
        _host: u32,
        _id: u32,
        _scenario_hash: u64,
        ins: &[u32],
        outs: &[u32],
    ) -> Result<Self, TransportError> {
        Ok(FakeRelay {
            ins: ins.to_vec(),
            outs: outs.to_vec(),
            ..FakeRelay::default()
        })
    }
    fn publish(&mut self, msg: StateMsg) -> Result<(), TransportError> {
        self.publish_quietly(msg)?;
        self.notify_readers()
    }
    fn publish_quietly(&mut self, msg: StateMsg) -> Result<(), TransportError> {
        self.published.push(msg);
        Ok(())
    }
    fn notify_readers(&mut self) -> Result<(), TransportError> {
        self.woken += 1;
        Ok(())
    }
    fn receive_clock(&mut self, f: impl FnMut(ClockMsg)) -> Result<(), TransportError> {
        self.clock.drain(..).for_each(f);
        Ok(())
    }
    fn receive_neighbors(&mut self, f: impl FnMut(StateMsg)) -> Result<(), TransportError> {
        self.neighbors.drain(..).for_each(f);
        Ok(())
    }
    fn connect(&mut self, subscribe: &[u32], notify: &[u32]) -> Result<(), TransportError> {
        self.connected.push((subscribe.to_vec(), notify.to_vec()));
        Ok(())
    }
    fn history_reaches(&self, tick: u64) -> bool {
        self.history_from.is_some_and(|from| from <= tick)
    }
    fn hand_over(&mut self) -> Result<(), TransportError> {
        self.handed_over += 1;
        Ok(())
    }
}
