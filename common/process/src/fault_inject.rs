//! Test-only fault injection: corrupt one member's published state at one tick, so the fault
//! tests (`tests/tests/launch/faults.rs`) can check that receivers report a bad neighbour state with
//! both ids instead of flying on it.
//!
//! Set `CDM_FAULT_INJECT=<id>:<kind>@<tick>` in the environment of a member (or of the
//! orchestrator, whose children inherit it); only member `<id>` acts on it:
//!
//! | kind | what member `<id>` publishes at tick `<tick>` |
//! |---|---|
//! | `nan` | its state with x = NaN |
//! | `tick` | its state labelled tick `<tick> + 1` (a state from the wrong step) |
//! | `kill` | nothing: it kills itself with SIGKILL instead (a crash at a chosen tick) |
//! | `stop` | nothing: it stops itself with SIGSTOP instead (a hang at a chosen tick) |
//! | `pause` | its true state, [`PAUSE`] late (a process slow to start, or starved by a loaded machine) |
//!
//! Nothing else changes: the member's own integration goes on with its true state. Never set
//! this variable outside tests; a member that acts on it says so with a warning.

/// The environment variable read by members.
pub const ENV: &str = "CDM_FAULT_INJECT";

/// How long `pause` holds the state back: longer than any grace the orchestrator could wait
/// by the wall clock, far shorter than the silence deadline.
pub const PAUSE: std::time::Duration = std::time::Duration::from_millis(1500);

/// What to corrupt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Publish a non-finite position.
    Nan,
    /// Publish the state with the next tick's number.
    WrongTick,
    /// Die by SIGKILL instead of publishing.
    Kill,
    /// Hang (SIGSTOP) instead of publishing.
    Stop,
    /// Publish the true state, [`PAUSE`] late.
    Pause,
}

/// One injected fault for this process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Injection {
    /// What to corrupt.
    pub kind: Kind,
    /// The tick whose published state is corrupted.
    pub tick: u64,
}

/// Parses `<id>:<kind>@<tick>`; `None` when it is malformed or aimed at another member.
pub fn parse(spec: &str, my_id: u32) -> Option<Injection> {
    let (id, rest) = spec.split_once(':')?;
    let (kind, tick) = rest.split_once('@')?;
    if id.trim().parse::<u32>().ok()? != my_id {
        return None;
    }
    let kind = match kind.trim() {
        "nan" => Kind::Nan,
        "tick" => Kind::WrongTick,
        "kill" => Kind::Kill,
        "stop" => Kind::Stop,
        "pause" => Kind::Pause,
        _ => return None,
    };
    Some(Injection {
        kind,
        tick: tick.trim().parse().ok()?,
    })
}

/// The injection for member `my_id` from the environment, if any (logged as a warning).
pub fn from_env(my_id: u32) -> Option<Injection> {
    let spec = std::env::var(ENV).ok()?;
    let found = parse(&spec, my_id);
    if let Some(i) = found {
        tracing::warn!(
            ?i,
            "{ENV} is set: this member will publish a corrupted state (test only)"
        );
    }
    found
}

impl Injection {
    /// Applies the injection to the state about to be published (or, for `kill`, ends the
    /// process): the member loop's before-publish hook.
    pub fn apply(&self, msg: &mut cdm_runtime::messages::StateMsg) {
        let tick = msg.tick;
        if tick != self.tick {
            return;
        }
        match self.kind {
            Kind::Nan => msg.state[0] = f64::NAN,
            Kind::WrongTick => msg.tick = tick + 1,
            Kind::Kill => {
                // SAFETY: raise(2) takes no pointers; this process ends here, as a crash would.
                unsafe {
                    libc::raise(libc::SIGKILL);
                }
            }
            Kind::Stop => {
                // SAFETY: raise(2) takes no pointers; the process hangs here until SIGCONT.
                unsafe {
                    libc::raise(libc::SIGSTOP);
                }
            }
            Kind::Pause => std::thread::sleep(PAUSE),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_only_well_formed_specs_for_this_agent() {
        assert_eq!(
            parse("7:nan@50", 7),
            Some(Injection {
                kind: Kind::Nan,
                tick: 50
            })
        );
        assert_eq!(parse("7:tick@3", 7).map(|i| i.kind), Some(Kind::WrongTick));
        assert_eq!(parse("1:kill@9", 1).map(|i| i.kind), Some(Kind::Kill));
        assert_eq!(parse("1:stop@9", 1).map(|i| i.kind), Some(Kind::Stop));
        assert_eq!(parse("2:pause@0", 2).map(|i| i.kind), Some(Kind::Pause));
        for bad in ["7:nan@50", "7:nan", "x:nan@1", "7:inf@1", "7:nan@-1", ""] {
            assert_eq!(parse(bad, 8), None, "{bad}");
        }
    }
}
