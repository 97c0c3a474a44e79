//! What the host side tells the operator, as values handed to the binary's
//! [`NoticeSink`](cdm_team::notices::NoticeSink) sink; their texts are written here and nowhere else.

use std::fmt;

/// One notice of a team split over hosts.
#[derive(Debug, Clone, PartialEq)]
pub enum HostNotice {
    /// The split, once before the flight: which ids run on which host, and how to start the
    /// daemons.
    Split {
        team: String,
        /// The members of each host, host 0 (this one) first.
        hosts: Vec<Vec<u32>>,
        crossing: usize,
        edges: usize,
        listen: String,
        /// How a daemon secures its link: `--keys DIR/host-K` or `--insecure`.
        how: &'static str,
    },
    /// The bridge admitted a daemon.
    Joined {
        host: u32,
        who: String,
        members: Vec<u32>,
    },
    /// After the flight: what crossing hosts cost on the network.
    Traffic {
        crossing: usize,
        per_tick: f64,
        sent: u64,
        received: u64,
    },
    /// A daemon joined its team.
    DaemonJoined {
        team: String,
        host: u32,
        members: Vec<u32>,
    },
}

impl fmt::Display for HostNotice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HostNotice::Split {
                team,
                hosts,
                crossing,
                edges,
                listen,
                how,
            } => {
                for (host, members) in hosts.iter().enumerate() {
                    let here = if host == 0 { " (this one)" } else { "" };
                    writeln!(f, "host {host}{here}: agents {members:?}")?;
                }
                write!(
                    f,
                    "team {team}: {crossing} of {edges} communication edges cross hosts; start each daemon with:\n  orchestrator host --connect {listen} --team {team} {how}"
                )
            }
            HostNotice::Joined { host, who, members } => {
                write!(f, "host {host} joined: {who} (agents {members:?})")
            }
            HostNotice::Traffic {
                crossing,
                per_tick,
                sent,
                received,
            } => write!(
                f,
                "  hosts: {crossing} crossing edges, {per_tick:.0} bytes per tick on the network ({sent} sent, {received} received)"
            ),
            HostNotice::DaemonJoined {
                team,
                host,
                members,
            } => write!(f, "joined team {team} as host {host}: agents {members:?}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_split_names_each_host_and_the_daemons_command() {
        let n = HostNotice::Split {
            team: "t".into(),
            hosts: vec![vec![0, 1], vec![2]],
            crossing: 1,
            edges: 4,
            listen: "tcp/127.0.0.1:7447".into(),
            how: "--insecure",
        };
        assert_eq!(
            n.to_string(),
            "host 0 (this one): agents [0, 1]\nhost 1: agents [2]\nteam t: 1 of 4 communication edges cross hosts; start each daemon with:\n  orchestrator host --connect tcp/127.0.0.1:7447 --team t --insecure"
        );
    }
}
