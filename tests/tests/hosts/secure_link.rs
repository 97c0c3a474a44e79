//! A team's network is its own: mutual TLS between the orchestrator and its daemons, in two
//! network namespaces joined by a veth pair (`support::netns`), as the multi-host tests run.
//!
//! - Over `tls/`, a team flies exactly as `simulate`; a raw packet capture on host A's link
//!   holds none of what crossed in clear over `tcp/` (the team's name, its key expressions);
//!   outsiders (PyPI eclipse-zenoh, the same zenoh version, on host B) receive nothing, get
//!   no answer and see no liveliness token: over plain TCP, with the team's public CA but no
//!   certificate, with another authority's certificate, with a certificate of the team's
//!   authority for a host not in the team; daemons with another authority's keys, over plain
//!   TCP, or of a host not in the team are refused (exit 3) and the orchestrator's log names
//!   each by its address or certificate; every outsider also forges host 1's frames, and the
//!   team is not disturbed.
//! - A frame that does not decode from a peer holding host 1's own certificate stops the team
//!   named as host 1's protocol error, not as a partition or another host.
//! - The control: over `tcp/ --insecure`, both sides warn, the capture holds the team's name in
//!   clear and an outsider on plain TCP receives the team's frames. Without it the checks
//!   above could pass by capturing or peeking nothing.
//! - `keys new` / `keys add-host` write owner-only files and refuse to overwrite; a key file
//!   others can read, a host's keys given to `launch`, `tcp/` without `--insecure` and `tls/`
//!   without `--keys` are refused with exit 2 naming the file or the option.
//!
//! Needs root for the namespaces and the raw socket (CI runs as root); only when namespaces
//! cannot be created does a test skip, printing why.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use integration_tests::{
    bin, describe, python_script, run, spawn, unique_team, venv_python, Running, TempDir,
};
use serde_json::Value;

use integration_tests::support;
use support::netns::{arg, left_on_b, new_keys, Hosts, ENDPOINT, TCP_ENDPOINT};
use support::*;

const RUN_DEADLINE: Duration = integration_tests::deadline::FLIGHT;
const REFUSE_DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// A 10-member team for 20 s of plan: 2,000 lockstep ticks across the link.
const SOURCE: &[&str] = &["--n", "10", "--t-total", "20"];

/// A raw packet capture on host A's end of the link, until `stop` exists.
fn capture(h: &Hosts, dir: &Path, stop: &Path) -> (Running, PathBuf) {
    let (out, ready) = (dir.join("capture.bin"), dir.join("capture.ready"));
    let mut c = h.exec_in(&h.a, &venv_python());
    c.arg(python_script("capture.py"))
        .args(["--iface", "veth0", "--out"])
        .arg(&out)
        .arg("--until")
        .arg(stop)
        .arg("--ready")
        .arg(&ready);
    let mut running = spawn(&mut c);
    let until = Instant::now() + REFUSE_DEADLINE;
    while !ready.exists() {
        assert!(
            Instant::now() < until && !running.has_exited(),
            "the capture did not start: {:?}",
            running.output_so_far()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    (running, out)
}

/// An outsider's zenoh client on host B connecting to `endpoint` with `tls` (`--ca F`,
/// `--cert F --key F`), until `stop` exists.
fn outsider(h: &Hosts, endpoint: &str, tls: &[String], stop: &Path) -> Running {
    forger(h, endpoint, tls, stop, None)
}

/// An outsider that also publishes a frame that does not decode on `put` each round.
fn forger(h: &Hosts, endpoint: &str, tls: &[String], stop: &Path, put: Option<&str>) -> Running {
    let mut c = h.exec_in(&h.b, &venv_python());
    c.arg(python_script("zenoh_peek.py"))
        .args(["--endpoint", endpoint])
        .args(tls)
        .arg("--until")
        .arg(stop);
    if let Some(key) = put {
        c.args(["--put", key]);
    }
    spawn(&mut c)
}

/// What an outsider saw (its JSON line).
fn seen(out: &Output) -> Value {
    assert!(out.status.success(), "zenoh_peek.py: {}", describe(out));
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or_default();
    serde_json::from_str(line).unwrap_or_else(|e| panic!("zenoh_peek.py: {e}: {}", describe(out)))
}

/// `--ca`, `--cert`, `--key` of a keys directory (`cert` false: the CA only).
fn tls_args(dir: &Path, cert: bool) -> Vec<String> {
    let mut v = vec!["--ca".into(), arg(&dir.join("ca.pem"))];
    if cert {
        v.extend(["--cert".into(), arg(&dir.join("cert.pem"))]);
        v.extend(["--key".into(), arg(&dir.join("key.pem"))]);
    }
    v
}

fn launch_args(team: &str, out: &Path, link: &[String]) -> Vec<String> {
    launch_flying(SOURCE, team, out, link)
}

/// `launch SOURCE` over two hosts.
fn launch_flying(source: &[&str], team: &str, out: &Path, link: &[String]) -> Vec<String> {
    let mut v: Vec<String> = source.iter().map(|s| s.to_string()).collect();
    v.insert(0, "launch".into());
    v.extend(
        [
            "--team",
            team,
            "--out",
            &arg(out),
            "--quiet",
            "--hosts",
            "2",
        ]
        .map(String::from),
    );
    v.extend(link.iter().cloned());
    v
}

/// Whether `needle` occurs in `hay`.
fn contains(hay: &[u8], needle: &str) -> bool {
    hay.windows(needle.len()).any(|w| w == needle.as_bytes())
}

/// Mutual TLS: outsiders and foreign daemons get nothing and are named; nothing crosses in
/// clear; the team flies exactly as `simulate`.
#[test]
fn over_tls_outsiders_get_nothing_and_the_team_flies_as_simulate() {
    let Some(h) = Hosts::create("tl") else { return };
    let dir = TempDir::new();
    let team = unique_team("tls");
    let (out, sim) = (dir.path().join("run"), dir.path().join("sim"));
    let stop = dir.path().join("stop");
    // Another team's authority, and a host of this team's authority that is not in the team.
    let other = dir.path().join("other-keys");
    new_keys(&other, 1);
    let added = run(
        Command::new(bin("orchestrator"))
            .args(["keys", "add-host"])
            .arg(&h.keys),
        REFUSE_DEADLINE,
    );
    assert_exit(&added, 0, "keys add-host");
    let (mut cap, cap_file) = capture(&h, dir.path(), &stop);
    let orch = spawn(&mut h.on_a(&launch_args(&team, &out, &h.listen_args())));
    // Each also forges host 1's frames: one that got through would stop the team, blaming
    // host 1 (`an_undecodable_frame_from_an_authenticated_host_is_its_protocol_error`).
    let up = format!("cdm/{team}/host/1/up");
    let forge = |endpoint, tls: &[String]| forger(&h, endpoint, tls, &stop, Some(&up));
    let outsiders = [
        forge(TCP_ENDPOINT, &[]),
        forge(ENDPOINT, &tls_args(&h.keys.join("host-1"), false)),
        forge(ENDPOINT, &tls_args(&other.join("host-1"), true)),
        forge(ENDPOINT, &tls_args(&h.keys.join("host-2"), true)),
    ];
    // Foreign daemons while host 1's slot is free (all three at once).
    let (other_keys, host2_keys) = (arg(&other.join("host-1")), arg(&h.keys.join("host-2")));
    let foreign: Vec<(&str, Running)> = [
        ("another authority's keys", vec!["--keys", &other_keys]),
        ("plain TCP", vec!["--insecure"]),
        ("host 2, not in the team", vec!["--keys", &host2_keys]),
    ]
    .into_iter()
    .map(|(what, keys)| {
        let endpoint = if what == "plain TCP" {
            TCP_ENDPOINT
        } else {
            ENDPOINT
        };
        let mut args = vec!["host", "--connect", endpoint, "--join-timeout", "4"];
        args.extend(keys);
        args.extend(["--team", &team]);
        (what, spawn(&mut h.on_b(&args)))
    })
    .collect();
    for (what, d) in foreign {
        let d = d.finish(REFUSE_DEADLINE);
        assert_exit(&d, 3, &format!("a daemon with {what}"));
        assert_stderr_has(&d, what, &["no orchestrator answered on"]);
    }
    // A daemon's host number is its certificate's.
    let keys1 = arg(&h.keys.join("host-1"));
    let wrong = run(
        &mut h.on_b(&[
            "host",
            "--connect",
            ENDPOINT,
            "--keys",
            &keys1,
            "--host",
            "2",
        ]),
        REFUSE_DEADLINE,
    );
    assert_exit(&wrong, 2, "host --host 2 with host 1's keys");
    assert_stderr_has(&wrong, "host --host 2", &["--host 2", "host 1's"]);

    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    let s = run(&mut simulate(&sim, SOURCE), RUN_DEADLINE);
    assert_exit(&s, 0, "simulate");
    let o = orch.finish(RUN_DEADLINE);
    let d = daemon.finish(RUN_DEADLINE);
    std::fs::write(&stop, "").expect("the stop file");
    assert_exit(&o, 0, "launch --hosts 2 over TLS");
    assert_exit(&d, 0, "orchestrator host over TLS");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    assert_eq!(left_on_b(&d), Vec::<String>::new(), "{}", describe(&d));
    // Each refusal named on the orchestrator's side: refused handshakes by address, a
    // certificate of the team's authority for a host not in the team by its name.
    assert_stderr_has(
        &o,
        "launch over TLS",
        &[
            "TLS handshake from 10.77.0.2:",
            "with certificate \"cdm host 2\" connected: not one of this session's peers",
        ],
    );
    for (i, p) in outsiders.into_iter().enumerate() {
        let v = seen(&p.finish(REFUSE_DEADLINE));
        assert!(
            v["puts"].as_u64() > Some(0),
            "outsider {i} forged nothing: {v:#}"
        );
        assert_eq!(
            (&v["samples"], &v["replies"], &v["tokens"]),
            (&Value::from(0), &Value::from(0), &Value::Array(vec![])),
            "outsider {i}: {v:#}"
        );
    }
    let bytes = cap_file_after(&mut cap, &cap_file);
    assert!(
        bytes.len() > 200_000,
        "the capture holds the flight: {} bytes",
        bytes.len()
    );
    for needle in [team.as_str(), "cdm/", "agent"] {
        assert!(!contains(&bytes, needle), "{needle:?} crossed in clear");
    }
}

/// The capture's bytes once it stopped.
fn cap_file_after(cap: &mut Running, file: &Path) -> Vec<u8> {
    let until = Instant::now() + REFUSE_DEADLINE;
    while !cap.has_exited() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(cap.has_exited(), "the capture did not stop");
    std::fs::read(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()))
}

/// The control: over `tcp/ --insecure` both sides warn, the team's name crosses in clear and
/// an outsider on plain TCP receives the team's frames.
#[test]
fn over_insecure_tcp_both_sides_warn_and_an_outsider_reads_the_team() {
    let Some(h) = Hosts::create("in") else { return };
    let dir = TempDir::new();
    let team = unique_team("insec");
    let out = dir.path().join("run");
    let stop = dir.path().join("stop");
    let (mut cap, cap_file) = capture(&h, dir.path(), &stop);
    let link = Hosts::listen_insecure();
    let orch = spawn(&mut h.on_a(&launch_args(&team, &out, &link)));
    let peek = outsider(&h, TCP_ENDPOINT, &[], &stop);
    std::thread::sleep(Duration::from_secs(1));
    let daemon = spawn(&mut h.insecure_daemon(&team));
    let o = orch.finish(RUN_DEADLINE);
    let d = daemon.finish(RUN_DEADLINE);
    std::fs::write(&stop, "").expect("the stop file");
    assert_exit(&o, 0, "launch --insecure");
    assert_exit(&d, 0, "orchestrator host --insecure");
    let warning = ["warning: --insecure", "is plain TCP"];
    assert_stderr_has(&o, "launch --insecure", &warning);
    assert_stderr_has(&d, "host --insecure", &warning);
    let v = seen(&peek.finish(REFUSE_DEADLINE));
    assert!(v["samples"].as_u64() > Some(0), "the outsider read: {v:#}");
    let bytes = cap_file_after(&mut cap, &cap_file);
    for needle in [team.as_str(), "cdm/"] {
        assert!(contains(&bytes, needle), "{needle:?} not in the capture");
    }
}

/// A frame on host 1's key that does not decode, from a peer with host 1's own certificate
/// (over TLS nobody else can publish there: the forgeries of the test above get nowhere), stops
/// the team named as host 1's protocol error, not as a partition or another host's fault.
#[test]
fn an_undecodable_frame_from_an_authenticated_host_is_its_protocol_error() {
    let Some(h) = Hosts::create("fg") else { return };
    let dir = TempDir::new();
    let team = unique_team("forge");
    let out = dir.path().join("run");
    let stop = dir.path().join("stop");
    // A long strict-lockstep flight: the bad frame ends it.
    let source = ["--n", "10", "--t-total", "600", "--window", "1"];
    let args = launch_flying(&source, &team, &out, &h.listen_args());
    let mut orch = spawn(&mut h.on_a(&args));
    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), 200);
    let up = format!("cdm/{team}/host/1/up");
    let host1 = tls_args(&h.keys.join("host-1"), true);
    let f = forger(&h, ENDPOINT, &host1, &stop, Some(&up));
    let o = orch.finish(RUN_DEADLINE);
    std::fs::write(&stop, "").expect("the stop file");
    let _ = daemon.finish(RUN_DEADLINE);
    let _ = f.finish(REFUSE_DEADLINE);
    assert_exit(&o, 3, "launch with an undecodable frame on host 1's key");
    assert_stderr_has(
        &o,
        "launch",
        &[
            "host 1 lost",
            "the daemon sent a frame that does not decode (its protocol error)",
        ],
    );
}

/// `keys new` and `keys add-host`: owner-only files, never overwritten; what `launch` and
/// `host` refuse before opening any socket.
#[test]
fn keys_are_owner_only_and_bad_security_options_are_refused() {
    let dir = TempDir::new();
    let keys = dir.path().join("keys");
    let o = run(
        Command::new(bin("orchestrator"))
            .args(["keys", "new"])
            .arg(&keys)
            .args(["--daemons", "2"]),
        REFUSE_DEADLINE,
    );
    assert_exit(&o, 0, "keys new --daemons 2");
    let said = String::from_utf8_lossy(&o.stdout);
    for part in ["orchestrator", "host-1", "host-2"] {
        assert!(said.contains(&arg(&keys.join(part))), "{said}");
    }
    let mut files = 0;
    for sub in ["authority", "orchestrator", "host-1", "host-2"] {
        let d = keys.join(sub);
        assert_eq!(mode(&d), 0o700, "{}", d.display());
        for f in std::fs::read_dir(&d).expect("a keys directory").flatten() {
            assert_eq!(mode(&f.path()), 0o600, "{}", f.path().display());
            files += 1;
        }
    }
    assert_eq!(
        files,
        2 + 3 * 3,
        "ca.pem+ca.key, and ca.pem+cert.pem+key.pem per role"
    );
    let again = run(
        Command::new(bin("orchestrator"))
            .args(["keys", "new"])
            .arg(&keys),
        REFUSE_DEADLINE,
    );
    assert_exit(&again, 2, "keys new over existing keys");
    assert_stderr_has(&again, "keys new", &["already exists", "never overwritten"]);
    let add = run(
        Command::new(bin("orchestrator"))
            .args(["keys", "add-host"])
            .arg(&keys),
        REFUSE_DEADLINE,
    );
    assert_exit(&add, 0, "keys add-host");
    assert_eq!(mode(&keys.join("host-3/key.pem")), 0o600);

    let team = unique_team("keysbad");
    let launch_with = |link: &[&str]| {
        let launch = ["launch", "--n", "10", "--team", &team, "--hosts", "2"];
        orchestrator(&[&launch[..], link].concat())
    };
    let (orch_keys, host_keys) = (arg(&keys.join("orchestrator")), arg(&keys.join("host-1")));
    let cases: [(&[&str], &[&str]); 3] = [
        (
            &["--listen", "tcp/127.0.0.1:7447"],
            &["--insecure", "tcp/127.0.0.1:7447"],
        ),
        (&["--listen", "tls/127.0.0.1:7447"], &["--keys"]),
        (
            &["--listen", "tls/127.0.0.1:7447", "--keys", &host_keys],
            &["host 1", "the orchestrator's"],
        ),
    ];
    for (link, needles) in cases {
        let r = launch_with(link);
        assert_exit(&r, 2, &format!("launch {link:?}"));
        assert_stderr_has(&r, "launch", needles);
    }
    let host =
        |extra: &[&str]| orchestrator(&[&["host", "--join-timeout", "1"][..], extra].concat());
    let r = host(&["--connect", "tcp/127.0.0.1:7447"]);
    assert_exit(&r, 2, "host tcp/ without --insecure");
    assert_stderr_has(&r, "host", &["--insecure"]);
    let r = host(&["--connect", "tls/127.0.0.1:7447", "--keys", &orch_keys]);
    assert_exit(&r, 2, "host with the orchestrator's keys");
    assert_stderr_has(&r, "host", &["orchestrator's certificate"]);
    // A key others can read is refused, naming the file.
    let key = keys.join("host-1/key.pem");
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    let r = host(&["--connect", "tls/127.0.0.1:7447", "--keys", &host_keys]);
    assert_exit(&r, 2, "host with a readable key");
    assert_stderr_has(&r, "host", &[&arg(&key), "0644", "chmod 600"]);
}

/// `orchestrator ARGS` on this host, to its end.
fn orchestrator(args: &[&str]) -> Output {
    run(
        Command::new(bin("orchestrator")).args(args),
        REFUSE_DEADLINE,
    )
}

fn mode(p: &Path) -> u32 {
    let m = std::fs::metadata(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    m.permissions().mode() & 0o777
}
