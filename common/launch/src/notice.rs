//! What a launch tells its operator as it goes, as values: each goes to the run's `NoticeSink`
//! (cdm-team), which the binary implements by printing its text (or drops under `--quiet`).

use std::fmt;
use std::net::SocketAddr;
use std::path::PathBuf;

use cdm_model::outcome::LossCause;

/// One notice of a launch.
#[derive(Debug, Clone, PartialEq)]
pub enum LaunchNotice {
    /// `--serve`: where the live view is served.
    LiveView { addr: String },
    /// `--foxglove`: where the Foxglove server listens.
    Foxglove { addr: SocketAddr },
    /// After the flight: what the Foxglove server published.
    FoxgloveDone(cdm_foxglove::FoxgloveSummary),
    /// After the flight: what the live ROS 2 topics published.
    Ros2Done(cdm_ros2::Summary),
    /// `--arm`: every vehicle is heard; the team orders them armed.
    Arming { vehicles: usize },
    /// Real time: a member lost, and the readers that fly the repaired graph.
    Lost {
        id: u32,
        cause: LossCause,
        /// Its newest tick heard (0 when none).
        last_tick: u64,
        /// Its readers, which switch their links.
        readers: Vec<u32>,
        /// The tick they fly the repaired graph from.
        repair_tick: u64,
    },
    /// `--no-spawn`: how to start each member by hand.
    StartByHand {
        team: String,
        members: usize,
        scenario: PathBuf,
        /// The flags every member needs besides its id (real time, vehicles).
        flags: Vec<String>,
        leaders: Vec<u32>,
        followers: Vec<u32>,
    },
}

impl fmt::Display for LaunchNotice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LaunchNotice::LiveView { addr } => write!(f, "live view: http://{addr}/"),
            LaunchNotice::Foxglove { addr } => write!(f, "foxglove: ws://{addr}"),
            LaunchNotice::FoxgloveDone(s) => write!(
                f,
                "  foxglove (ws://{}): {} ticks published, {} dropped (queue full){}",
                s.addr,
                s.ticks,
                s.dropped,
                unfinished(s.unfinished)
            ),
            LaunchNotice::Ros2Done(s) => {
                write!(
                    f,
                    "  ros2 ({}): {} ticks published, {} dropped (queue full)",
                    s.backend, s.ticks, s.dropped
                )?;
                if let Some(e) = &s.first_error {
                    write!(f, ", {} messages refused (first: {e})", s.failed)?;
                }
                f.write_str(unfinished(s.unfinished))
            }
            LaunchNotice::Arming { vehicles } => write!(
                f,
                "all {vehicles} vehicles ready: ordering OFFBOARD/GUIDED and arming"
            ),
            LaunchNotice::Lost {
                id,
                cause,
                last_tick,
                readers,
                repair_tick,
            } => write!(
                f,
                "agent {id} lost ({cause}) after its tick {last_tick}: its readers {readers:?} fly the repaired graph from their tick {repair_tick}"
            ),
            LaunchNotice::StartByHand {
                team,
                members,
                scenario,
                flags,
                leaders,
                followers,
            } => {
                let flags: String = flags.iter().map(|f| format!(" {f}")).collect();
                let scenario = scenario.display();
                write!(
                    f,
                    "team {team} waits for {members} processes; start each with:\n  leader --scenario {scenario} --team {team} --id ID{flags}   (ids {leaders:?})\n  agent  --scenario {scenario} --team {team} --id ID{flags}   (ids {followers:?})"
                )
            }
        }
    }
}

/// The end of a feed's summary line when it was still publishing as the launch ended.
fn unfinished(still_publishing: bool) -> &'static str {
    if still_publishing {
        "; still publishing when the launch ended"
    } else {
        ""
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hand_start_names_each_binary_its_flags_and_ids() {
        let n = LaunchNotice::StartByHand {
            team: "t".into(),
            members: 3,
            scenario: PathBuf::from("run/scenario.toml"),
            flags: vec!["--realtime".into()],
            leaders: vec![1],
            followers: vec![2, 3],
        };
        assert_eq!(
            n.to_string(),
            "team t waits for 3 processes; start each with:\n  leader --scenario run/scenario.toml --team t --id ID --realtime   (ids [1])\n  agent  --scenario run/scenario.toml --team t --id ID --realtime   (ids [2, 3])"
        );
    }

    #[test]
    fn a_loss_names_the_member_its_cause_and_its_readers() {
        let n = LaunchNotice::Lost {
            id: 7,
            cause: LossCause::Killed,
            last_tick: 40,
            readers: vec![8, 9],
            repair_tick: 45,
        };
        let text = n.to_string();
        assert!(text.starts_with("agent 7 lost ("), "{text}");
        assert!(
            text.ends_with(
                "after its tick 40: its readers [8, 9] fly the repaired graph from their tick 45"
            ),
            "{text}"
        );
    }
}
