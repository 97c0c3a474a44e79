//! The orchestrator's own failures, each keeping the library error it wraps as its `source`
//! (`main` prints the chain). Their text is what the messages said before they were typed, so
//! scripts and tests that match it still do.

use cdm_iox::TransportError;

/// A failure of a command that no library error describes alone.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// A command-line option the transport refused (`--team`).
    #[error("{option}: {source}")]
    Option {
        option: &'static str,
        #[source]
        source: TransportError,
    },
}

impl CommandError {
    /// `--team` (and the like) refused by the transport.
    pub fn option(option: &'static str) -> impl FnOnce(TransportError) -> Self {
        move |source| CommandError::Option { option, source }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_exit::Failure;

    #[test]
    fn the_printed_chain_keeps_every_source_once() {
        // The wrapper names its source: printed once.
        let team = cdm_iox::TeamName::new("a/b").unwrap_err();
        let f = Failure::bad_input(CommandError::option("--team")(team));
        assert!(f.message().starts_with("--team: invalid team name \"a/b\""));
        assert!(!f.message().contains("caused by"), "{}", f.message());
        // A wrapper that does not show its source gets it appended.
        #[derive(Debug, thiserror::Error)]
        #[error("cannot draw the figures")]
        struct Outer(#[source] Locate);
        #[derive(Debug, thiserror::Error)]
        #[error("cannot locate the orchestrator binary: {0}")]
        struct Locate(#[source] std::io::Error);
        let io = std::io::Error::new(std::io::ErrorKind::PermissionDenied, "denied");
        let f = Failure::fault(Outer(Locate(io)));
        assert_eq!(
            f.message(),
            "cannot draw the figures: caused by cannot locate the orchestrator binary: denied"
        );
        assert!(f.error.source().is_some());
    }
}
