//! Exit codes, and the failure (a typed error and its exit code) every command of the front ends
//! ends with. Libraries return their own typed errors; the orchestrator and the Python package
//! decide here which exit code each means.

/// Exit codes of every command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    Safe = 0,
    Unsafe = 1,
    BadInput = 2,
    Fault = 3,
}

/// Any error a command ends with, its source chain kept (see [`Failure::message`]).
type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A failure with its exit code. The error stays typed, with its sources, until `main` prints it.
#[derive(Debug)]
pub struct Failure {
    pub exit: Exit,
    pub error: BoxError,
}

impl Failure {
    pub fn bad_input(error: impl Into<BoxError>) -> Self {
        Failure {
            exit: Exit::BadInput,
            error: error.into(),
        }
    }

    pub fn fault(error: impl Into<BoxError>) -> Self {
        Failure {
            exit: Exit::Fault,
            error: error.into(),
        }
    }

    /// The error and its sources, `"...: caused by ..."`. A source whose text the message
    /// already shows (most of our errors name their source in their own text) is not repeated.
    pub fn message(&self) -> String {
        let mut text = self.error.to_string();
        let mut source = self.error.source();
        while let Some(s) = source {
            let more = s.to_string();
            if !more.is_empty() && !text.contains(&more) {
                text.push_str(": caused by ");
                text.push_str(&more);
            }
            source = s.source();
        }
        text
    }
}

/// A run directory that cannot be used: a full disk is a runtime fault (exit 3), anything else
/// (a file in the way, permissions) bad input.
impl From<cdm_records::rundir::RunDirError> for Failure {
    fn from(e: cdm_records::rundir::RunDirError) -> Self {
        if e.is_disk_full() {
            Failure::fault(e)
        } else {
            Failure::bad_input(e)
        }
    }
}
