//! How a member process ended, as one typed value: the loss it makes (`killed` or `exited`) is
//! decided from the variant, and the wording ("exited with code 1", "was killed by signal 9")
//! is written once, here, for audit.json and the console.

use std::fmt;

use cdm_model::outcome::LossCause;

/// How a member process ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ProcessExit {
    /// It exited by itself with this code.
    Code(i32),
    /// This signal killed it.
    Signal(i32),
    /// It ended with neither a code nor a signal reported.
    Ended,
    /// Its host was lost: the daemon that ran it (`who`) is gone, `why` says how.
    WithHost { host: u32, who: String, why: String },
}

impl ProcessExit {
    /// How the process of `status` ended.
    pub fn of(status: std::process::ExitStatus) -> Self {
        use std::os::unix::process::ExitStatusExt;
        match (status.code(), status.signal()) {
            (_, Some(sig)) => ProcessExit::Signal(sig),
            (Some(code), _) => ProcessExit::Code(code),
            _ => ProcessExit::Ended,
        }
    }

    /// The loss it makes of its member: `killed` by a signal or with its host, else `exited`.
    pub fn loss_cause(&self) -> LossCause {
        match self {
            ProcessExit::Signal(_) | ProcessExit::WithHost { .. } => LossCause::Killed,
            ProcessExit::Code(_) | ProcessExit::Ended => LossCause::Exited,
        }
    }
}

impl fmt::Display for ProcessExit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ProcessExit::Code(code) => write!(f, "exited with code {code}"),
            ProcessExit::Signal(sig) => write!(f, "was killed by signal {sig}"),
            ProcessExit::Ended => write!(f, "exited"),
            ProcessExit::WithHost { host, who, why } => {
                write!(f, "was killed with host {host} ({who}): {why}")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_loss_cause_follows_the_variant_and_the_wording_is_audit_json_s() {
        let host = ProcessExit::WithHost {
            host: 2,
            who: "host-2".into(),
            why: "its link was silent".into(),
        };
        assert_eq!(ProcessExit::Signal(9).loss_cause(), LossCause::Killed);
        assert_eq!(host.loss_cause(), LossCause::Killed);
        assert_eq!(ProcessExit::Code(3).loss_cause(), LossCause::Exited);
        assert_eq!(ProcessExit::Ended.loss_cause(), LossCause::Exited);
        assert_eq!(ProcessExit::Signal(9).to_string(), "was killed by signal 9");
        assert_eq!(ProcessExit::Code(1).to_string(), "exited with code 1");
        assert_eq!(
            host.to_string(),
            "was killed with host 2 (host-2): its link was silent"
        );
    }
}
