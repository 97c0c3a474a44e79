//! Across hosts: the zenoh link between a team's orchestrator and the daemon of each
//! other host. The only library crate that names zenoh; members never see it (a daemon re-publishes
//! what crosses hosts into its host's iceoryx2 services, `common/hosts/src/lib.rs`). Also the
//! zenoh side of live ROS 2 (`rmw.rs`: rmw_zenoh's session, tokens and attachment, for
//! cdm-ros2's `launch --ros2 zenoh`).
//!
//! | key | frames | from -> to |
//! |---|---|---|
//! | `cdm/<team>/join/<k or any>` | [`JoinRequest`] / [`JoinReply`] (a query) | daemon -> orchestrator |
//! | `cdm/<team>/host/<k>/down` | [`Down`]: clock, crossing states, heartbeat | orchestrator -> daemon k |
//! | `cdm/<team>/host/<k>/up` | [`Up`]: ready, every member's state, exits, heartbeat | daemon k -> orchestrator |

pub mod frame;
pub mod link;
pub mod rmw;

pub use frame::{
    decode, encode, Assignment, DecodeError, Down, JoinReply, JoinRequest, NetExit, Up,
    PROTOCOL_VERSION,
};
pub use link::{
    down_key, host_key_exprs, join_key, orchestrator_key_exprs, up_key, Channel, JoinDesk, Net,
    NetError, Peer, PendingJoin, Security,
};
