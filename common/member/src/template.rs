//! The member template: one process that reads the team's scenario once and forks every member
//! of a launch from itself, instead of a thousand processes each started from its binary.
//!
//! Why: at N = 1000 each member spent about 5.3 ms of CPU from `exec` to its first port (the
//! kernel's `exec`, the dynamic loader, reading and validating the 1000-member scenario and
//! hashing it), most of a launch's start-up on two cores. A forked member starts with all of it
//! done ([`crate::member::Loaded`]) and runs the very same `main` with the very same arguments,
//! so it flies exactly as a started one.
//!
//! How to run: the orchestrator starts `agent --template FILE ROOM` (cdm-team's
//! `template.rs`) with pipes on its standard input and output. Each request on stdin is one
//! [`ForkRequest`]: the binary a member would have been started as and its arguments; the
//! template answers each with one [`ForkReply`], the member's pid, once the member is the
//! orchestrator's child (`cdm_process::fork`). Frames are postcard with COBS, ended by a zero
//! byte. The template ends at the end of its input. Its loop is the member binaries' (the
//! cdm-member-cli crate's `template.rs`); this file is the protocol both sides share. ROOM is ignored: its length is the room
//! the forked members have for their own command lines (`cdm_process::fork::set_cmdline`).
//! A member started by hand is started from its binary, as always.

use serde::{Deserialize, Serialize};

/// The first argument that makes a member binary the template.
pub const FLAG: &str = "--template";

/// Fork one member.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ForkRequest {
    /// The binary it would have been started as: `leader` (true) or `agent`.
    pub leader: bool,
    /// Its arguments, after the program's name (raw bytes: a path need not be UTF-8).
    pub args: Vec<Vec<u8>>,
}

/// The answer to a [`ForkRequest`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum ForkReply {
    /// The member's pid (the requester's child by now).
    Forked(u32),
    /// It could not be forked: the OS error number when the OS refused (`EAGAIN` at the
    /// process limit), and why.
    Failed { errno: Option<i32>, why: String },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_and_replies_survive_their_frames() {
        let r = ForkRequest {
            leader: true,
            args: vec![b"--scenario".to_vec(), vec![0, 1, 255, b'/'], Vec::new()],
        };
        let mut b = postcard::to_stdvec_cobs(&r).unwrap();
        assert_eq!(
            b.iter().filter(|&&x| x == 0).count(),
            1,
            "one zero: the end"
        );
        assert_eq!(postcard::from_bytes_cobs::<ForkRequest>(&mut b).unwrap(), r);
        let mut b = postcard::to_stdvec_cobs(&ForkReply::Forked(4242)).unwrap();
        assert_eq!(
            postcard::from_bytes_cobs::<ForkReply>(&mut b).unwrap(),
            ForkReply::Forked(4242)
        );
    }
}
