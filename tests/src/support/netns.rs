//! Two "hosts" for the multi-host tests: two network namespaces joined by a veth pair
//! (10.77.0.1/24 on A, 10.77.0.2/24 on B), host B with its own /dev/shm (a tmpfs in a private
//! mount namespace), and the team's keys (`orchestrator keys new`) for mutual TLS.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::{bin, describe, run, TempDir};

/// The orchestrator's endpoint on host A: mutual TLS, as a user runs it.
pub const ENDPOINT: &str = "tls/10.77.0.1:7447";
/// The same address in plain TCP (only with `--insecure`).
pub const TCP_ENDPOINT: &str = "tcp/10.77.0.1:7447";

/// Two network namespaces joined by a veth pair, and a team's keys; deleted on drop (processes
/// inside were killed by their own guards first: fields drop after the test body's guards).
pub struct Hosts {
    pub a: String,
    pub b: String,
    /// `keys new` of this pair's team, with one host.
    pub keys: PathBuf,
    _dir: TempDir,
}

pub fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {}: {e}", args.join(" ")))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// `orchestrator keys new DIR --daemons N`, checked.
pub fn new_keys(dir: &Path, daemons: u32) {
    let out = run(
        Command::new(bin("orchestrator"))
            .args(["keys", "new"])
            .arg(dir)
            .args(["--daemons", &daemons.to_string()]),
        crate::deadline::REFUSE,
    );
    assert!(out.status.success(), "keys new: {}", describe(&out));
}

/// A path as a command-line argument.
pub fn arg(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

impl Hosts {
    /// The pair, or `None` (printed) when this machine cannot create namespaces.
    pub fn create(tag: &str) -> Option<Self> {
        let stem = format!("cdm{tag}{}", std::process::id());
        let dir = TempDir::new();
        let keys = dir.path().join("keys");
        let h = Self {
            a: format!("{stem}a"),
            b: format!("{stem}b"),
            keys,
            _dir: dir,
        };
        if let Err(e) = ip(&["netns", "add", &h.a]) {
            eprintln!("SKIPPED: cannot create network namespaces here (needs root): {e}");
            return None;
        }
        let setup = || -> Result<(), String> {
            ip(&["netns", "add", &h.b])?;
            let (a, b) = (h.a.as_str(), h.b.as_str());
            ip(&[
                "-n", a, "link", "add", "veth0", "type", "veth", "peer", "name", "veth1", "netns",
                b,
            ])?;
            ip(&["-n", a, "addr", "add", "10.77.0.1/24", "dev", "veth0"])?;
            ip(&["-n", b, "addr", "add", "10.77.0.2/24", "dev", "veth1"])?;
            for (ns, dev) in [(a, "veth0"), (b, "veth1"), (a, "lo"), (b, "lo")] {
                ip(&["-n", ns, "link", "set", dev, "up"])?;
            }
            Ok(())
        };
        // Once one namespace exists, failing to build the rest is a failure, not a skip.
        setup().unwrap_or_else(|e| panic!("network namespaces: {e}"));
        new_keys(&h.keys, 1);
        Some(h)
    }

    /// `--listen ENDPOINT --keys DIR/orchestrator`: the orchestrator's side of the link.
    pub fn listen_args(&self) -> Vec<String> {
        let keys = arg(&self.keys.join("orchestrator"));
        ["--listen", ENDPOINT, "--keys", &keys]
            .map(str::to_owned)
            .to_vec()
    }

    /// `--listen TCP_ENDPOINT --insecure`: plain TCP, for the controls.
    pub fn listen_insecure() -> Vec<String> {
        ["--listen", TCP_ENDPOINT, "--insecure"]
            .map(str::to_owned)
            .to_vec()
    }

    /// `orchestrator ARGS` on host A.
    pub fn on_a<S: AsRef<std::ffi::OsStr>>(&self, args: &[S]) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.a])
            .arg(bin("orchestrator"))
            .args(args);
        c
    }

    /// `orchestrator ARGS` on host B, with B's own /dev/shm; once the daemon exits, the shell
    /// lists what is left in that /dev/shm after `LEFT:` (files only).
    pub fn on_b<S: AsRef<std::ffi::OsStr>>(&self, args: &[S]) -> Command {
        let script = r#"mount -t tmpfs -o mode=1777 tmpfs /dev/shm || exit 97
"$0" "$@"; rc=$?
echo "LEFT:$(find /dev/shm -type f | tr '\n' ' ')"
exit $rc"#;
        let mut c = Command::new("ip");
        c.args([
            "netns", "exec", &self.b, "unshare", "--mount", "sh", "-c", script,
        ])
        .arg(bin("orchestrator"))
        .args(args);
        c
    }

    /// `orchestrator host --connect ENDPOINT --keys DIR/host-1 EXTRA` on host B: the team's
    /// own daemon.
    pub fn daemon(&self, extra: &[&str]) -> Command {
        let keys = arg(&self.keys.join("host-1"));
        let mut args = vec!["host", "--connect", ENDPOINT, "--keys", &keys];
        args.extend_from_slice(extra);
        self.on_b(&args)
    }

    /// `orchestrator host --connect TCP_ENDPOINT --insecure --team TEAM` on host B.
    pub fn insecure_daemon(&self, team: &str) -> Command {
        self.on_b(&[
            "host",
            "--connect",
            TCP_ENDPOINT,
            "--insecure",
            "--team",
            team,
        ])
    }

    /// A program (not the orchestrator) run inside namespace `ns`.
    pub fn exec_in(&self, ns: &str, program: &Path) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", ns]).arg(program);
        c
    }

    /// The veth link down: a partition.
    pub fn cut(&self) {
        ip(&["-n", &self.a, "link", "set", "veth0", "down"]).expect("cut the link");
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        let _ = ip(&["netns", "del", &self.a]);
        let _ = ip(&["netns", "del", &self.b]);
    }
}

/// B's files left in its private /dev/shm, from the wrapper's `LEFT:` line. iceoryx2's global
/// management segment (`<prefix>..._node.0_10_0.global_mgmt`) is per user, not per team: it stays.
pub fn left_on_b(out: &Output) -> Vec<String> {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix("LEFT:"))
        .unwrap_or_else(|| panic!("host B's wrapper printed no LEFT: line\n{}", describe(out)));
    line.split_whitespace()
        .filter(|f| !f.ends_with(".global_mgmt"))
        .map(str::to_owned)
        .collect()
}
