//! The zenoh session's security from the checked options: the keys of this machine's role, and
//! who may speak to it on which keys (each host on its own; a daemon with the orchestrator only).

use cdm_keys::{Holder, KeyDir};
use cdm_team::Failure;
use cdm_zenoh::{host_key_exprs, orchestrator_key_exprs, Peer, Security};

use crate::{HostOptions, Transport};

/// The listener's security: the orchestrator's keys; host k's certificate on host k's keys.
pub(crate) fn listener(h: &HostOptions) -> Result<Security, Failure> {
    let Transport::Tls(dir) = &h.transport else {
        return Ok(Security::Insecure);
    };
    let keys = open(dir, "--keys")?;
    if keys.role != Holder::Orchestrator {
        return Err(Failure::bad_input(format!(
            "--keys {}: this is {}'s certificate; launch needs the orchestrator's (DIR/orchestrator of `keys new`)",
            dir.display(),
            keys.role
        )));
    }
    let peers = (1..h.hosts)
        .map(|k| Peer {
            common_name: Holder::Host(k).common_name(),
            key_exprs: host_key_exprs(k),
        })
        .collect();
    Ok(tls(keys, peers))
}

/// A daemon's security and the host number its certificate binds it to (`None`: insecure).
pub(crate) fn daemon(t: &Transport) -> Result<(Security, Option<u32>), Failure> {
    let Transport::Tls(dir) = t else {
        return Ok((Security::Insecure, None));
    };
    let keys = open(dir, "--keys")?;
    let Holder::Host(k) = keys.role else {
        return Err(Failure::bad_input(format!(
            "--keys {}: this is the orchestrator's certificate; a daemon needs its host's (DIR/host-K of `keys new`)",
            dir.display()
        )));
    };
    let peers = vec![Peer {
        common_name: Holder::Orchestrator.common_name(),
        key_exprs: orchestrator_key_exprs(),
    }];
    Ok((tls(keys, peers), Some(k)))
}

fn open(dir: &std::path::Path, option: &str) -> Result<KeyDir, Failure> {
    KeyDir::open(dir).map_err(|e| Failure::bad_input(format!("{option}: {e}")))
}

fn tls(k: KeyDir, peers: Vec<Peer>) -> Security {
    Security::Tls {
        ca: k.ca,
        cert: k.cert,
        key: k.key,
        peers,
    }
}
