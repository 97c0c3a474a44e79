//! The seam between a host's state machine (the orchestrator's bridge, a host's daemon) and the
//! network: frames out, frames in, a bounded wait, byte counts. zenoh's channel implements it
//! (`ZenohLink`, behind the `hosts` feature); the unit tests fly the bridge and the daemon over
//! [`FakeLink`], whose frames and clock are the test's.

use std::time::Duration;

/// How often a quiet link says it is alive (both ends).
pub const HEARTBEAT: Duration = Duration::from_millis(200);

/// A boxed error with its source chain.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Why a link failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The peer's session closed: its process exited or was killed (a partition closes
    /// nothing; the silence deadline covers it).
    #[error(transparent)]
    PeerGone(BoxError),
    /// A frame from the peer that does not decode: the peer's protocol error (with TLS only
    /// the peer's certificate may send on its key, so nobody else can be blamed).
    #[error(transparent)]
    Protocol(BoxError),
    /// Anything else: a frame that cannot be sent.
    #[error(transparent)]
    Broken(BoxError),
}

/// One host's link: frames of type `In` come from the peer, frames of type `Out` go to it.
pub trait HostLink {
    type In;
    type Out;
    /// Sends one frame.
    fn send(&mut self, frame: &Self::Out) -> Result<(), LinkError>;
    /// The next frame received, if any (never blocks).
    fn try_recv(&mut self) -> Result<Option<Self::In>, LinkError>;
    /// Sleeps until a frame arrives or `timeout` passes.
    fn wait(&mut self, timeout: Duration);
    /// Payload bytes sent and received so far.
    fn bytes(&self) -> (u64, u64);
}

#[cfg(feature = "hosts")]
pub use zenoh_link::ZenohLink;

#[cfg(feature = "hosts")]
mod zenoh_link {
    use std::marker::PhantomData;
    use std::time::Duration;

    use cdm_zenoh::{Channel, NetError};
    use serde::de::DeserializeOwned;
    use serde::Serialize;

    use super::{HostLink, LinkError};

    /// A zenoh channel carrying frames `In` one way and `Out` the other.
    pub struct ZenohLink<In, Out> {
        chan: Channel,
        frames: PhantomData<fn(Out) -> In>,
    }

    impl<In, Out> ZenohLink<In, Out> {
        pub fn new(chan: Channel) -> Self {
            Self {
                chan,
                frames: PhantomData,
            }
        }
    }

    fn link_error(e: NetError) -> LinkError {
        match e {
            e @ NetError::PeerGone { .. } => LinkError::PeerGone(Box::new(e)),
            e @ NetError::Decode { .. } => LinkError::Protocol(Box::new(e)),
            e => LinkError::Broken(Box::new(e)),
        }
    }

    impl<In: DeserializeOwned, Out: Serialize> HostLink for ZenohLink<In, Out> {
        type In = In;
        type Out = Out;
        fn send(&mut self, frame: &Out) -> Result<(), LinkError> {
            self.chan.send(frame).map_err(link_error)
        }
        fn try_recv(&mut self) -> Result<Option<In>, LinkError> {
            self.chan.try_recv().map_err(link_error)
        }
        fn wait(&mut self, timeout: Duration) {
            self.chan.wait(timeout);
        }
        fn bytes(&self) -> (u64, u64) {
            self.chan.bytes()
        }
    }
}

/// A link whose peer is the test: frames to deliver are queued in `incoming` (an `Err` is
/// delivered once, in its turn), frames sent land in `sent`.
#[cfg(test)]
pub struct FakeLink<In, Out> {
    pub incoming: std::collections::VecDeque<Result<In, LinkError>>,
    pub sent: Vec<Out>,
}

#[cfg(test)]
impl<In, Out> Default for FakeLink<In, Out> {
    fn default() -> Self {
        Self {
            incoming: Default::default(),
            sent: Vec::new(),
        }
    }
}

#[cfg(test)]
impl<In, Out: Clone> HostLink for FakeLink<In, Out> {
    type In = In;
    type Out = Out;
    fn send(&mut self, frame: &Out) -> Result<(), LinkError> {
        self.sent.push(frame.clone());
        Ok(())
    }
    fn try_recv(&mut self) -> Result<Option<In>, LinkError> {
        self.incoming.pop_front().transpose()
    }
    fn wait(&mut self, _timeout: Duration) {}
    fn bytes(&self) -> (u64, u64) {
        (self.sent.len() as u64, 0)
    }
}
