//! The zenoh session's security from the checked options: the keys of this machine's role, and
//! who may speak to it on which keys (each host on its own; a daemon with the orchestrator only).

use std::path::{Path, PathBuf};

use cdm_keys::{Holder, KeyDir, KeyDirError};
use cdm_zenoh::{host_key_exprs, orchestrator_key_exprs, Peer, Security};

use crate::{HostOptions, Transport};

/// Why the keys given cannot secure the link: the operator's input (exit 2).
#[derive(Debug, thiserror::Error)]
pub enum SecurityError {
    #[error(
        "--keys {}: this is {role}'s certificate; launch needs the orchestrator's \
         (DIR/orchestrator of `keys new`)",
        dir.display()
    )]
    NotOrchestrator { dir: PathBuf, role: Holder },
    #[error(
        "--keys {}: this is the orchestrator's certificate; a daemon needs its host's \
         (DIR/host-K of `keys new`)",
        dir.display()
    )]
    NotHost { dir: PathBuf },
    #[error("{option}: {source}")]
    Keys {
        option: &'static str,
        #[source]
        source: KeyDirError,
    },
}

/// The listener's security: the orchestrator's keys; host k's certificate on host k's keys.
pub(crate) fn listener(h: &HostOptions) -> Result<Security, SecurityError> {
    let Transport::Tls(dir) = &h.transport else {
        return Ok(Security::Insecure);
    };
    let keys = open(dir, "--keys")?;
    if keys.role != Holder::Orchestrator {
        let (dir, role) = (dir.clone(), keys.role);
        return Err(SecurityError::NotOrchestrator { dir, role });
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
pub(crate) fn daemon(t: &Transport) -> Result<(Security, Option<u32>), SecurityError> {
    let Transport::Tls(dir) = t else {
        return Ok((Security::Insecure, None));
    };
    let keys = open(dir, "--keys")?;
    let Holder::Host(k) = keys.role else {
        let dir = dir.clone();
        return Err(SecurityError::NotHost { dir });
    };
    let peers = vec![Peer {
        common_name: Holder::Orchestrator.common_name(),
        key_exprs: orchestrator_key_exprs(),
    }];
    Ok((tls(keys, peers), Some(k)))
}

fn open(dir: &Path, option: &'static str) -> Result<KeyDir, SecurityError> {
    KeyDir::open(dir).map_err(|source| SecurityError::Keys { option, source })
}

fn tls(k: KeyDir, peers: Vec<Peer>) -> Security {
    Security::Tls {
        ca: k.ca,
        cert: k.cert,
        key: k.key,
        peers,
    }
}
