//! A team's keys for mutual TLS across hosts: one certificate authority, one certificate for the
//! orchestrator and one per host daemon, each in a directory of its own that goes to that
//! machine (`orchestrator keys new DIR`, `keys add-host DIR`).
//!
//! ```text
//! DIR/authority/    ca.pem ca.key           stays with whoever adds hosts; never copied out
//! DIR/orchestrator/ ca.pem cert.pem key.pem the orchestrator's machine (`launch --keys`)
//! DIR/host-K/       ca.pem cert.pem key.pem host K's machine (`host --keys`)
//! ```
//!
//! Every directory is 0700 and every file 0600. A certificate's common name says who it is
//! (`cdm orchestrator`, `cdm host K`): zenoh's access control matches on it, which is how a
//! daemon is bound to its host number. The orchestrator's certificate is for server
//! authentication only and a host's for client authentication only, so a host's key cannot
//! pose as the orchestrator.

mod files;

use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, DnValue, ExtendedKeyUsagePurpose, IsCa, Issuer,
    KeyPair, KeyUsagePurpose,
};

pub use files::KeyDirError;
use files::{make_dir, read, write_new};

/// Who a certificate speaks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Holder {
    Orchestrator,
    /// A host daemon, by its host number (1..; the orchestrator's host is 0).
    Host(u32),
}

impl Holder {
    /// The certificate's common name, which zenoh's access control matches on.
    pub fn common_name(self) -> String {
        match self {
            Holder::Orchestrator => "cdm orchestrator".to_owned(),
            Holder::Host(k) => format!("cdm host {k}"),
        }
    }

    /// The role a common name stands for, if it is one of ours.
    pub fn from_common_name(cn: &str) -> Option<Self> {
        if cn == "cdm orchestrator" {
            return Some(Holder::Orchestrator);
        }
        let k: u32 = cn.strip_prefix("cdm host ")?.parse().ok()?;
        (k >= 1 && cn == Holder::Host(k).common_name()).then_some(Holder::Host(k))
    }

    /// The directory `keys new` writes this role's files into.
    pub fn dir_name(self) -> String {
        match self {
            Holder::Orchestrator => "orchestrator".to_owned(),
            Holder::Host(k) => format!("host-{k}"),
        }
    }
}

impl std::fmt::Display for Holder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Holder::Orchestrator => f.write_str("the orchestrator"),
            Holder::Host(k) => write!(f, "host {k}"),
        }
    }
}

/// The common name of a team's authority.
const AUTHORITY_CN: &str = "cdm team authority";

/// One machine's key directory, checked: the directory and its three files are ours and ours
/// only (no other user can read, write or own them), and its certificate names a role.
#[derive(Debug, Clone)]
pub struct KeyDir {
    pub role: Holder,
    /// The team's authority certificate (checks the peer).
    pub ca: PathBuf,
    /// This machine's certificate (shown to the peer).
    pub cert: PathBuf,
    /// This machine's private key.
    pub key: PathBuf,
}

impl KeyDir {
    /// Opens `dir` as written by `keys new` / `keys add-host`.
    pub fn open(dir: &Path) -> Result<Self, KeyDirError> {
        let (ca, cert, key) = (
            dir.join("ca.pem"),
            dir.join("cert.pem"),
            dir.join("key.pem"),
        );
        for p in [dir, &ca, &cert, &key] {
            files::check_private(p)?;
        }
        let pem = read(&cert)?;
        let cn = common_name_of(&pem).map_err(|e| KeyDirError::Certificate {
            path: cert.clone(),
            detail: e.to_string(),
        })?;
        let role = Holder::from_common_name(&cn).ok_or_else(|| KeyDirError::Certificate {
            path: cert.clone(),
            detail: format!(
                "common name {cn:?} is neither \"cdm orchestrator\" nor \"cdm host K\""
            ),
        })?;
        Ok(Self {
            role,
            ca,
            cert,
            key,
        })
    }
}

/// Why a certificate's common name could not be read (x509-parser's errors, as their text).
#[derive(Debug, thiserror::Error)]
enum CommonNameError {
    #[error("not PEM: {0}")]
    NotPem(String),
    #[error("not X.509: {0}")]
    NotX509(String),
    #[error("no common name")]
    Missing,
    #[error("common name: {0}")]
    NotText(String),
}

/// The subject common name of the first certificate in `pem`.
fn common_name_of(pem: &[u8]) -> Result<String, CommonNameError> {
    let (_, p) = x509_parser::pem::parse_x509_pem(pem)
        .map_err(|e| CommonNameError::NotPem(e.to_string()))?;
    let x = p
        .parse_x509()
        .map_err(|e| CommonNameError::NotX509(e.to_string()))?;
    let cn = x.subject().iter_common_name().next();
    let cn = cn.ok_or(CommonNameError::Missing)?;
    cn.as_str()
        .map(str::to_owned)
        .map_err(|e| CommonNameError::NotText(e.to_string()))
}

/// Creates a team's keys in `dir` (which must not exist or be empty): the authority, the
/// orchestrator's and hosts 1..=`daemons`. Returns the directories written, in order.
pub fn new_team(dir: &Path, daemons: u32) -> Result<Vec<PathBuf>, KeyDirError> {
    files::new_empty_dir(dir)?;
    let ca_key = KeyPair::generate().map_err(KeyDirError::rcgen("an authority key"))?;
    let mut params =
        CertificateParams::new(Vec::new()).map_err(KeyDirError::rcgen("parameters"))?;
    params
        .distinguished_name
        .push(DnType::CommonName, AUTHORITY_CN);
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    let ca_cert = params
        .self_signed(&ca_key)
        .map_err(KeyDirError::rcgen("the authority certificate"))?;
    let authority = dir.join("authority");
    make_dir(&authority)?;
    write_new(&authority.join("ca.pem"), ca_cert.pem().as_bytes())?;
    write_new(&authority.join("ca.key"), ca_key.serialize_pem().as_bytes())?;
    let issuer = Issuer::new(params, ca_key);
    let ca_pem = ca_cert.pem();
    let mut out = Vec::new();
    for role in std::iter::once(Holder::Orchestrator).chain((1..=daemons).map(Holder::Host)) {
        out.push(issue(dir, role, &issuer, &ca_pem)?);
    }
    Ok(out)
}

/// Adds the next host to the team whose keys are in `dir`; returns its number and directory.
pub fn add_host(dir: &Path) -> Result<(u32, PathBuf), KeyDirError> {
    let authority = dir.join("authority");
    let (ca_path, key_path) = (authority.join("ca.pem"), authority.join("ca.key"));
    files::check_private(&key_path)?;
    let ca_pem = String::from_utf8_lossy(&read(&ca_path)?).into_owned();
    let key_pem = String::from_utf8_lossy(&read(&key_path)?).into_owned();
    let bad = |path: &Path, detail: String| KeyDirError::Certificate {
        path: path.to_owned(),
        detail,
    };
    let ca_key = KeyPair::from_pem(&key_pem).map_err(|e| bad(&key_path, e.to_string()))?;
    let issuer =
        Issuer::from_ca_cert_pem(&ca_pem, ca_key).map_err(|e| bad(&ca_path, e.to_string()))?;
    let next = (1..)
        .find(|k| !dir.join(Holder::Host(*k).dir_name()).exists())
        .unwrap_or(1);
    let written = issue(dir, Holder::Host(next), &issuer, &ca_pem)?;
    Ok((next, written))
}

/// Writes `role`'s directory: the authority's certificate, its own, and its key.
fn issue(
    dir: &Path,
    role: Holder,
    issuer: &Issuer<'_, KeyPair>,
    ca_pem: &str,
) -> Result<PathBuf, KeyDirError> {
    let key = KeyPair::generate().map_err(KeyDirError::rcgen("a key"))?;
    // The subject alternative name repeats the role; peers are not checked by address (daemons
    // reach the orchestrator by whatever address the field network gives it) but by the
    // authority and the common name.
    let san = role.common_name().replace(' ', "-");
    let mut params = CertificateParams::new(vec![san]).map_err(KeyDirError::rcgen("parameters"))?;
    params
        .distinguished_name
        .push(DnType::CommonName, DnValue::Utf8String(role.common_name()));
    params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    params.extended_key_usages = vec![match role {
        Holder::Orchestrator => ExtendedKeyUsagePurpose::ServerAuth,
        Holder::Host(_) => ExtendedKeyUsagePurpose::ClientAuth,
    }];
    let cert = params
        .signed_by(&key, issuer)
        .map_err(KeyDirError::rcgen("a certificate"))?;
    let out = dir.join(role.dir_name());
    make_dir(&out)?;
    write_new(&out.join("ca.pem"), ca_pem.as_bytes())?;
    write_new(&out.join("cert.pem"), cert.pem().as_bytes())?;
    write_new(&out.join("key.pem"), key.serialize_pem().as_bytes())?;
    Ok(out)
}

#[cfg(test)]
mod tests;
