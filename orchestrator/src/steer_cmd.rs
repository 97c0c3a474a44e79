//! `orchestrator command TEAM ...`: one command to a running team over its channel
//! (`cdm_launch::channel`), its answer printed and mapped to the exit code.

use std::time::Duration;

use cdm_exit::{Exit, Failure};
use cdm_iox::TeamName;
use cdm_launch::channel::{send, Answered, CommandRequest};

/// What `orchestrator command` takes.
#[derive(Debug, clap::Args)]
pub struct SteerArgs {
    /// The team's name (`launch --team`).
    pub team: String,
    /// What the team does: hold (come to rest and hover), resume (back to the route it left),
    /// land (every member straight down to the mission's ground), goto (the goals that follow).
    #[arg(value_enum)]
    pub action: SteerAction,
    /// goto: the three primary leaders' goals, X,Y,Z each, in ascending id order.
    #[arg(value_name = "X,Y,Z", allow_negative_numbers = true)]
    pub goals: Vec<String>,
    /// goto: the travel time in seconds (default: the fastest leader's peak acceleration the
    /// largest the launched plan reaches).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub travel_s: Option<f64>,
    /// How long to wait for the team's answer, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0)]
    pub within_s: f64,
}

/// The commands a team takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SteerAction {
    Hold,
    Resume,
    Land,
    Goto,
}

impl SteerAction {
    fn name(self) -> &'static str {
        match self {
            SteerAction::Hold => "hold",
            SteerAction::Resume => "resume",
            SteerAction::Land => "land",
            SteerAction::Goto => "goto",
        }
    }
}

/// Sends the command and prints the answer: exit 0 accepted, 1 refused UNSAFE; bad input (2)
/// and no answer (3) are failures.
pub fn run(a: &SteerArgs) -> Result<Exit, Failure> {
    let team = TeamName::new(&a.team).map_err(Failure::bad_input)?;
    let request = request_of(a)?;
    if !(a.within_s.is_finite() && a.within_s > 0.0 && a.within_s <= 3600.0) {
        return Err(Failure::bad_input(format!(
            "--within-s must be in (0, 3600] seconds, got {}",
            a.within_s
        )));
    }
    let answer =
        send(&team, &request, Duration::from_secs_f64(a.within_s)).map_err(Failure::fault)?;
    match answer.answer {
        Answered::Accepted => {
            out!("{}", answer.text);
            out!("decided in {:.1} ms", answer.decided_ms);
            Ok(Exit::Safe)
        }
        Answered::Unsafe => {
            out!("{}", answer.text);
            out!("decided in {:.1} ms", answer.decided_ms);
            Ok(Exit::Unsafe)
        }
        Answered::BadInput => Err(Failure::bad_input(answer.text)),
        Answered::Unavailable => Err(Failure::fault(answer.text)),
    }
}

/// The request of the arguments: goals only for goto, three finite points.
fn request_of(a: &SteerArgs) -> Result<CommandRequest, Failure> {
    let goto = a.action == SteerAction::Goto;
    if !goto && (!a.goals.is_empty() || a.travel_s.is_some()) {
        return Err(Failure::bad_input(format!(
            "only goto takes goals and --travel-s, not {}",
            a.action.name()
        )));
    }
    if goto && a.goals.len() != 3 {
        return Err(Failure::bad_input(format!(
            "goto needs the 3 primary leaders' goals X,Y,Z (ascending id), got {}",
            a.goals.len()
        )));
    }
    let goals = (a.goals.iter().enumerate())
        .map(|(k, g)| goal(k, g))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(t) = a.travel_s {
        if !(t.is_finite() && t > 0.0) {
            return Err(Failure::bad_input(format!(
                "--travel-s must be a positive number of seconds, got {t}"
            )));
        }
    }
    Ok(CommandRequest {
        command: a.action.name().to_string(),
        goals: goto.then_some(goals),
        travel_s: a.travel_s,
    })
}

/// Goal `k` as `X,Y,Z`, finite.
fn goal(k: usize, text: &str) -> Result<[f64; 3], Failure> {
    let bad = |why: String| Failure::bad_input(format!("goal {} `{text}`: {why}", k + 1));
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(bad(format!("expected X,Y,Z, got {} numbers", parts.len())));
    }
    let mut g = [0.0; 3];
    for (c, p) in parts.iter().enumerate() {
        let v: f64 = p
            .parse()
            .map_err(|_| bad(format!("`{p}` is not a number")))?;
        if !v.is_finite() {
            return Err(bad(format!("{p} is not a finite coordinate")));
        }
        g[c] = v;
    }
    Ok(g)
}
