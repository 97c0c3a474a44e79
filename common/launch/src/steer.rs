//! Commands to a launched team: the orchestrator certifies each (the same code as `simulate`,
//! `cdm_certificates::command_certificate`), and announces each accepted one to every member
//! with its switch tick on the clock channel (`cdm_runtime::team_core`), where each member makes
//! the same new plan of it (`cdm_runtime::member_steer`).

use std::sync::Arc;

use cdm_certificates::command_certificate::{decide, CommandRecord};
use cdm_model::steer::Steering;
use cdm_model::step::tick_time;
use cdm_records::audit::{CommandSummary, SafetyNumbers};
use cdm_records::rundir::{RunDir, RunDirError};
use cdm_runtime::messages::SteerNotice;
use cdm_scenario::{CommandSpec, Scenario, TimedCommand};

use crate::channel::{Answered, CommandAnswer, CommandRequest};

/// A file's commands, decided before the flight: what became of each, and the notices of the
/// accepted ones.
#[derive(Debug, Clone)]
pub struct FileCommands {
    pub records: Vec<CommandRecord>,
    pub notices: Vec<SteerNotice>,
    /// The steering once they are applied (live commands go on from it).
    pub steering: Steering,
    /// The safety numbers the team was launched with (every command is certified to them).
    pub numbers: SafetyNumbers,
}

impl FileCommands {
    /// `list` certified in order for the team of `s`: the scenario to audit (its plan the
    /// commanded one, the same before every switch) and the commands.
    pub fn decide(s: &Scenario, list: &[TimedCommand]) -> (Scenario, Self) {
        let numbers = SafetyNumbers::of(s);
        let mut steering = s.steering();
        let records: Vec<CommandRecord> = (list.iter())
            .map(|c| decide(&mut steering, s, &numbers, c))
            .collect();
        let mut flown = s.clone();
        flown.plan = steering.plan().clone();
        let notices = (list.iter().zip(&records))
            .filter(|(_, r)| r.accepted)
            .enumerate()
            .map(|(k, (c, r))| SteerNotice::decided(k as u32 + 1, r.switch_tick, c.command))
            .collect();
        let file = FileCommands {
            records,
            notices,
            steering,
            numbers,
        };
        (flown, file)
    }

    /// What audit.json lists.
    pub fn summaries(&self) -> Vec<CommandSummary> {
        self.records.iter().map(CommandRecord::summary).collect()
    }
}

/// Why commands.json could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteCommandsError {
    /// The records did not serialise.
    #[error("commands.json: {0}")]
    Json(#[from] serde_json::Error),
    /// The file could not be written.
    #[error(transparent)]
    Write(#[from] RunDirError),
}

/// The run's commands.json: every command and what became of it.
pub fn write_commands(dir: &RunDir, records: &[CommandRecord]) -> Result<(), WriteCommandsError> {
    let text = serde_json::to_string_pretty(records)?;
    let path = dir.path().join("commands.json");
    Ok(cdm_records::rundir::write_atomic(&path, text.as_bytes())?)
}

/// The commands a running team takes (`orchestrator command`), after its file's: each is
/// certified at its switch tick against the plan as commanded so far, with the code of a file's
/// (`decide`), so `simulate --commands RUN/commands.json` flies the same run.
#[derive(Debug, Clone)]
pub struct LiveSteer {
    steering: Steering,
    numbers: SafetyNumbers,
    /// The plan flown so far (the commanded one): the same before every switch.
    flown: Arc<Scenario>,
    /// Every command so far, the file's first.
    records: Vec<CommandRecord>,
    /// Accepted commands announced so far.
    announced: u32,
    /// No switch at or before this tick: the latest command's, the file's included.
    after: Option<u64>,
}

/// A team's commands: the channel (`orchestrator command`), what became of each so far, and
/// the run directory their commands.json is written to.
pub(crate) struct Steer<'a> {
    pub(crate) channel: Option<&'a crate::channel::CommandChannel>,
    pub(crate) live: &'a mut LiveSteer,
    pub(crate) dir: &'a RunDir,
}

impl<'a> Steer<'a> {
    pub(crate) fn new(
        channel: Option<&'a crate::channel::CommandChannel>,
        live: &'a mut LiveSteer,
        dir: &'a RunDir,
    ) -> Self {
        Steer { channel, live, dir }
    }
}

/// Where the flight is when a command arrives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlightAt {
    /// The first tick no member may have stepped into yet (one past the highest granted).
    pub first_free: u64,
    /// The latest complete tick (when the command arrived).
    pub complete: u64,
    /// The flight's last tick as commanded so far.
    pub last: u64,
}

/// A live command decided.
#[derive(Debug, Clone)]
pub struct LiveDecision {
    pub answer: CommandAnswer,
    /// Accepted: its notice, the plan flown from now on and the flight's new last tick.
    pub accepted: Option<(SteerNotice, Arc<Scenario>, u64)>,
    /// Whether commands.json changed (a command recorded).
    pub recorded: bool,
}

impl LiveSteer {
    /// The team of `flown` (its plan the file's commanded one, `file` the file's commands).
    pub fn new(flown: &Scenario, file: Option<&FileCommands>) -> Self {
        let (steering, numbers, records) = match file {
            Some(f) => (f.steering.clone(), f.numbers, f.records.clone()),
            None => (flown.steering(), SafetyNumbers::of(flown), Vec::new()),
        };
        LiveSteer {
            after: records.last().map(|r| r.switch_tick),
            announced: file.map_or(0, |f| f.notices.len() as u32),
            steering,
            numbers,
            flown: Arc::new(flown.clone()),
            records,
        }
    }

    /// The plan flown.
    pub fn flown(&self) -> &Arc<Scenario> {
        &self.flown
    }

    /// Every command so far and what became of it.
    pub fn records(&self) -> &[CommandRecord] {
        &self.records
    }

    /// (accepted, refused) so far.
    pub fn counts(&self) -> (usize, usize) {
        let accepted = self.records.iter().filter(|r| r.accepted).count();
        (accepted, self.records.len() - accepted)
    }

    /// [`Self::decide`] without changing anything yet (real time: a command accepted by its
    /// certificate becomes final only once every leader acknowledged it): the decision, and
    /// this steering as it is once the command is final ([`Self::adopt`]).
    pub fn tentatively(&self, request: CommandRequest, at: FlightAt) -> (LiveDecision, LiveSteer) {
        let mut next = self.clone();
        let decision = next.decide(request, at);
        (decision, next)
    }

    /// The steering [`Self::tentatively`] made, now that its command is final (or was refused
    /// by its certificate, which is recorded too).
    pub fn adopt(&mut self, next: LiveSteer) {
        *self = next;
    }

    /// A proposed command was withdrawn (real time): nothing changed, but the members spent
    /// its notice number.
    pub fn spend_notice(&mut self) {
        self.announced += 1;
    }

    /// Decide `request` arriving with the flight at `at`: it switches at the first tick no
    /// member flew yet (and after the latest command's), certified there.
    pub fn decide(&mut self, request: CommandRequest, at: FlightAt) -> LiveDecision {
        let switch = at.first_free.max(self.after.map_or(0, |a| a + 1));
        let dt = self.flown.dt_s();
        let not_recorded = |answer| LiveDecision {
            answer,
            accepted: None,
            recorded: false,
        };
        if switch > at.last {
            let text = format!(
                "the flight ends at tick {} (t = {:.2} s): no tick is left to switch at",
                at.last,
                tick_time(at.last, dt)
            );
            return not_recorded(CommandAnswer::without_switch(Answered::Unavailable, text));
        }
        let spec = CommandSpec {
            at_s: tick_time(switch, dt),
            command: request.command,
            goals: request.goals,
            travel_s: request.travel_s,
        };
        let mut c = match cdm_scenario::check_command(spec, &self.flown, "command") {
            Ok(c) => c,
            Err(e) => {
                return not_recorded(CommandAnswer::without_switch(
                    Answered::BadInput,
                    e.to_string(),
                ))
            }
        };
        // at_s is the switch's own time: it maps back to the same tick.
        c.switch_tick = switch;
        c.arrived_s = Some(tick_time(at.complete.min(switch), dt));
        self.decide_timed(&c)
    }

    /// [`Self::tentatively`] for a command file's command (`launch --realtime --commands`):
    /// decided at its own switch tick, as [`FileCommands::decide`] decides it before a
    /// lockstep flight, so its record is the one `simulate --commands` writes.
    pub fn tentatively_timed(&self, c: &TimedCommand) -> (LiveDecision, LiveSteer) {
        let mut next = self.clone();
        let decision = next.decide_timed(c);
        (decision, next)
    }

    /// Decide `c` at its switch tick (after every command so far).
    fn decide_timed(&mut self, c: &TimedCommand) -> LiveDecision {
        let (switch, dt) = (c.switch_tick, self.flown.dt_s());
        let record = decide(&mut self.steering, &self.flown, &self.numbers, c);
        self.after = Some(switch);
        let mut accepted = None;
        if record.accepted {
            self.announced += 1;
            let notice = SteerNotice::decided(self.announced, switch, c.command);
            let mut flown = (*self.flown).clone();
            flown.plan = self.steering.plan().clone();
            let last = flown.last_tick();
            self.flown = Arc::new(flown);
            accepted = Some((notice, Arc::clone(&self.flown), last));
        }
        let answer = answer_of(&record, dt);
        self.records.push(record);
        LiveDecision {
            answer,
            accepted,
            recorded: true,
        }
    }
}

/// The answer a command gets: the switch and the certificate's summary, or why not.
fn answer_of(r: &CommandRecord, dt_s: f64) -> CommandAnswer {
    let t = tick_time(r.switch_tick, dt_s);
    let what = &r.spec.command;
    let (answer, text) = match (&r.certificate, r.accepted) {
        (Some(c), true) => {
            let lambda = (c.phases.iter())
                .map(|p| p.lambda1_min)
                .fold(f64::INFINITY, f64::min);
            // "At least" a bound the search stopped at; past an hour it is no bound at all.
            let delay = match c.max_link_delay_ms {
                Some(d) if c.max_link_delay_at_least && d > 3.6e6 => "any".into(),
                Some(d) if c.max_link_delay_at_least => format!("at least {d:.1} ms"),
                Some(d) => format!("{d:.1} ms"),
                None => "none".into(),
            };
            let text = format!(
                "{what} accepted: switch at tick {} (t = {t:.2} s); certificate SAFE: {} new phase(s), lambda_1 min {lambda:.4} >= lambda_CD,min {:.4}, max follower deviation {:.4} m <= delta {:.4} m, link delay tolerated {delay}",
                r.switch_tick,
                c.phases.len(),
                c.lambda_cd_min,
                c.max_follower_deviation_m,
                c.delta_m
            );
            (Answered::Accepted, text)
        }
        (Some(c), false) => {
            let mut text = format!(
                "{what} refused: UNSAFE at tick {} (t = {t:.2} s), nothing changed:",
                r.switch_tick
            );
            for reason in &c.reasons {
                text.push_str("\n  ");
                text.push_str(reason);
            }
            (Answered::Unsafe, text)
        }
        (None, _) => {
            let why = r.why.as_deref().unwrap_or("it does not apply");
            let text = format!(
                "{what} refused at tick {} (t = {t:.2} s), nothing changed: {why}",
                r.switch_tick
            );
            (Answered::BadInput, text)
        }
    };
    CommandAnswer {
        answer,
        switch_tick: Some(r.switch_tick),
        t_switch_s: Some(t),
        text,
        decided_ms: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(command: &str, goals: Option<Vec<[f64; 3]>>) -> CommandRequest {
        CommandRequest {
            command: command.into(),
            goals,
            travel_s: None,
        }
    }

    fn at(first_free: u64, last: u64) -> FlightAt {
        FlightAt {
            first_free,
            complete: first_free.saturating_sub(3),
            last,
        }
    }

    const SAFE: [[f64; 3]; 3] = [
        [224.0, 434.0, 600.0],
        [126.0, 224.0, 600.0],
        [322.0, 224.0, 600.0],
    ];
    const SQUEEZED: [[f64; 3]; 3] = [
        [224.0, 434.0, 600.0],
        [220.0, 224.0, 600.0],
        [228.0, 224.0, 600.0],
    ];

    #[test]
    fn commands_switch_at_the_first_free_tick_after_the_last_one_and_replay_as_a_file() {
        let s = Scenario::builtin("paper40").unwrap();
        let last = s.last_tick();
        let mut live = LiveSteer::new(&s, None);
        let hold = live.decide(request("hold", None), at(3000, last));
        assert_eq!(hold.answer.answer, Answered::Accepted, "{:?}", hold.answer);
        assert_eq!(hold.answer.switch_tick, Some(3000));
        let (notice, flown, new_last) = hold.accepted.expect("accepted");
        assert_eq!((notice.seq, notice.tick), (1, 3000));
        assert!(
            new_last >= last,
            "a held team hovers to the launched end at least"
        );
        // Refused, at the next tick: the grants have not moved, the hold's switch is taken.
        let squeezed = live.decide(request("goto", Some(SQUEEZED.to_vec())), at(3000, new_last));
        assert_eq!(squeezed.answer.answer, Answered::Unsafe);
        assert_eq!(squeezed.answer.switch_tick, Some(3001));
        assert!(
            squeezed.answer.text.contains("lambda_1"),
            "{}",
            squeezed.answer.text
        );
        assert!(squeezed.accepted.is_none() && squeezed.recorded);
        assert_eq!(
            live.flown().plan,
            flown.plan,
            "a refused command changes nothing"
        );
        let goto = live.decide(request("goto", Some(SAFE.to_vec())), at(3100, new_last));
        assert_eq!(goto.answer.answer, Answered::Accepted, "{:?}", goto.answer);
        assert_eq!(goto.accepted.as_ref().map(|a| a.0.seq), Some(2));
        // Malformed: not recorded, nothing changed.
        let bad = live.decide(request("goto", Some(vec![[0.0; 3]])), at(3200, new_last));
        assert_eq!(bad.answer.answer, Answered::BadInput);
        assert!(!bad.recorded);
        assert_eq!(live.counts(), (2, 1));
        // commands.json read back as a file flies the same plan.
        let text = serde_json::to_string(live.records()).unwrap();
        let list = cdm_scenario::parse_commands(&text, &s).unwrap();
        let (replayed, records) = cdm_certificates::command_certificate::apply_commands(&s, &list);
        assert_eq!(replayed.plan, live.flown().plan);
        // As JSON: a hold's stop has no T_threshold (NaN, which equals nothing).
        assert_eq!(serde_json::to_string(&records).unwrap(), text);
    }

    #[test]
    fn a_goto_before_the_take_off_is_bad_input_and_no_tick_left_is_unavailable() {
        let s = Scenario::builtin("paper40-mission").unwrap();
        let last = s.last_tick();
        let mut live = LiveSteer::new(&s, None);
        let early = live.decide(request("goto", Some(SAFE.to_vec())), at(10, last));
        assert_eq!(
            early.answer.answer,
            Answered::BadInput,
            "{:?}",
            early.answer
        );
        assert!(early.recorded, "a command that does not apply is recorded");
        let late = live.decide(request("hold", None), at(last + 1, last));
        assert_eq!(late.answer.answer, Answered::Unavailable);
        assert!(!late.recorded);
    }
}
