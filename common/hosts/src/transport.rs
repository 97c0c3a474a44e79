//! How the team's link is secured, decided from the command line before anything opens: a
//! `tls/` endpoint needs `--keys DIR`, a `tcp/` one needs an explicit `--insecure`.

use std::path::{Path, PathBuf};

use crate::error::{EndpointError, EndpointProblem};

/// The link's transport, as the options asked for it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Transport {
    /// Mutual TLS with the keys in this directory (`orchestrator keys new`).
    Tls(PathBuf),
    /// Plain TCP, unauthenticated: `--insecure`.
    Insecure,
}

impl Transport {
    /// Checks `endpoint` (the value of `option`) against `--keys` and `--insecure`.
    pub fn choose(
        option: &str,
        endpoint: &str,
        keys: Option<&Path>,
        insecure: bool,
    ) -> Result<Self, EndpointError> {
        use EndpointProblem::*;
        let problem = match (endpoint.split_once('/').map(|(p, _)| p), keys, insecure) {
            (Some("tls"), Some(dir), false) => return Ok(Transport::Tls(dir.to_owned())),
            (Some("tcp"), None, true) => return Ok(Transport::Insecure),
            (Some("tls"), None, _) => TlsWithoutKeys,
            (Some("tls"), Some(_), true) => TlsInsecure,
            (Some("tcp"), Some(_), _) => TcpWithKeys,
            (Some("tcp"), None, false) => TcpNotInsecure,
            _ => Form,
        };
        Err(EndpointError {
            option: option.to_owned(),
            endpoint: endpoint.to_owned(),
            problem,
        })
    }

    /// The warning `--insecure` prints once, naming the endpoint.
    pub fn warning(&self, endpoint: &str) -> Option<String> {
        (*self == Transport::Insecure).then(|| {
            format!(
                "warning: --insecure: {endpoint} is plain TCP; anyone who reaches it can join the team, read every member's state and send it frames"
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn choose(e: &str, keys: bool, insecure: bool) -> Result<Transport, EndpointError> {
        let k = keys.then(|| Path::new("/k"));
        Transport::choose("--listen", e, k, insecure)
    }

    #[test]
    fn tls_needs_keys_and_tcp_needs_insecure() {
        assert_eq!(
            choose("tls/10.0.0.1:7447", true, false),
            Ok(Transport::Tls("/k".into()))
        );
        assert_eq!(
            choose("tcp/10.0.0.1:7447", false, true),
            Ok(Transport::Insecure)
        );
        let e = choose("tcp/10.0.0.1:7447", false, false).unwrap_err();
        assert_eq!(e.problem, EndpointProblem::TcpNotInsecure);
        let e = e.to_string();
        assert!(
            e.contains("--insecure") && e.contains("tcp/10.0.0.1:7447"),
            "{e}"
        );
        assert!(choose("tls/10.0.0.1:7447", false, false)
            .unwrap_err()
            .to_string()
            .contains("--keys"));
        assert!(choose("tls/a:1", true, true).is_err());
        assert!(choose("tcp/a:1", true, true).is_err());
        assert!(choose("udp/a:1", false, true).is_err());
        assert!(choose("nothing", false, true).is_err());
    }

    #[test]
    fn only_insecure_warns() {
        assert!(Transport::Insecure
            .warning("tcp/a:1")
            .unwrap()
            .contains("tcp/a:1"));
        assert!(Transport::Tls("/k".into()).warning("tls/a:1").is_none());
    }
}
