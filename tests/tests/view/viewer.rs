//! The 3-D viewer in a real browser (headless Chromium, Debian's package; installed by
//! scripts/test-deps.sh): `replay.html` from `file://` with the network disabled, `view --serve`
//! and a live `launch --serve`. The DOM contract (`#cdm-status`: data-agents, data-tick,
//! data-verdict) must match the run, the screenshot must show the agents, and the page must log
//! no error (the page counts window errors, rejections and console.error in data-errors, and
//! Chromium's log is searched for uncaught exceptions).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{
    bin, describe, fenced_paper40, run, spawn, unique_team, write_scenario, Running, TempDir,
};
use serde_json::Value;

/// One headless Chromium page load; the page renders in well under a second on an idle machine.
const BROWSER_DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// A short simulate or a view start.
const RUN_DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// A live team of 100k ticks: ~20 s on two idle cores, far more under load.
const LIVE_DEADLINE: Duration = integration_tests::deadline::LONG;
/// Virtual time the page gets before its snapshot (Chromium's --virtual-time-budget).
const PAGE_BUDGET_MS: &str = "8000";

fn orchestrator(args: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    c
}

fn ok(out: &Output) {
    assert_eq!(out.status.code(), Some(0), "{}", describe(out));
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Headless Chromium on `url`, as root needs it (no sandbox), WebGL by SwiftShader; `action` is
/// `--dump-dom` or `--screenshot=PATH`. `offline` runs it in an empty network namespace.
fn chromium(url: &str, action: &str, profile: &Path, offline: bool) -> Output {
    let args = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--no-first-run",
        "--window-size=1200,800",
        "--enable-logging=stderr",
        "--v=0",
    ];
    let mut c = if offline {
        let mut c = Command::new("unshare");
        c.args(["--net", "--", "chromium"]);
        c
    } else {
        Command::new("chromium")
    };
    c.args(args)
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--virtual-time-budget={PAGE_BUDGET_MS}"))
        .arg(action)
        .arg(url);
    let out = run(&mut c, BROWSER_DEADLINE);
    assert_eq!(
        out.status.code(),
        Some(0),
        "chromium {url}: {}",
        describe(&out)
    );
    out
}

/// The page's `#cdm-status` attributes, read from Chromium's DOM dump; asserts no page error.
fn status(url: &str, dir: &Path, offline: bool) -> Status {
    let out = chromium(url, "--dump-dom", &dir.join("profile"), offline);
    let dom = String::from_utf8_lossy(&out.stdout);
    let log = String::from_utf8_lossy(&out.stderr);
    for bad in ["Uncaught", "ERROR:CONSOLE"] {
        assert!(
            !log.contains(bad),
            "{url}: `{bad}` in Chromium's log:\n{log}"
        );
    }
    let start = dom
        .find("<div id=\"cdm-status\"")
        .unwrap_or_else(|| panic!("{url}: no #cdm-status in the page:\n{dom}"));
    let tag = &dom[start..start + dom[start..].find('>').unwrap_or(0)];
    let attr = |name: &str| {
        let key = format!("{name}=\"");
        let at = tag
            .find(&key)
            .unwrap_or_else(|| panic!("{url}: no {name} in {tag}"));
        let rest = &tag[at + key.len()..];
        rest[..rest.find('"').unwrap_or(0)].to_owned()
    };
    let num = |name: &str| {
        attr(name)
            .parse::<i64>()
            .unwrap_or_else(|e| panic!("{url}: {name} in {tag}: {e}"))
    };
    assert_eq!(attr("data-errors"), "0", "{url}: page errors: {tag}\n{log}");
    Status {
        agents: num("data-agents"),
        tick: num("data-tick"),
        first_tick: tag
            .contains("data-first-tick")
            .then(|| num("data-first-tick")),
        verdict: attr("data-verdict"),
        lost: num("data-lost"),
        commands: (num("data-commands-accepted"), num("data-commands-refused")),
        airspace: attr("data-airspace").replace("&quot;", "\""),
    }
}

#[derive(Debug)]
struct Status {
    agents: i64,
    tick: i64,
    first_tick: Option<i64>,
    verdict: String,
    /// Members lost by the shown tick.
    lost: i64,
    /// Commands switched by the shown tick: (accepted, refused).
    commands: (i64, i64),
    /// What the page drew of the airspace: the fence's sides and the obstacles' names (JSON).
    airspace: String,
}

/// Takes a screenshot and asserts it is not blank: several colours, and the agents drawn (many
/// pixels of the followers' blue in the middle of the view, where the camera keeps the team).
fn screenshot(url: &str, dir: &Path, offline: bool) -> PathBuf {
    let path = dir.join("shot.png");
    chromium(
        url,
        &format!("--screenshot={}", path.display()),
        &dir.join("profile"),
        offline,
    );
    let file = std::fs::File::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let channels = info.color_type.samples();
    let (w, h) = (info.width as usize, info.height as usize);
    let px = |x: usize, y: usize| {
        let i = (y * w + x) * channels;
        (buf[i], buf[i + 1], buf[i + 2])
    };
    let mut colours = std::collections::BTreeSet::new();
    let mut blue = 0usize;
    for y in 0..h {
        for x in 0..w {
            let (r, g, b) = px(x, y);
            colours.insert((r >> 4, g >> 4, b >> 4));
            let middle = (w / 4..3 * w / 4).contains(&x) && (h / 4..3 * h / 4).contains(&y);
            if middle && b > 120 && b as u32 > r as u32 + 60 {
                blue += 1;
            }
        }
    }
    assert!(
        colours.len() >= 8,
        "{}: only {} colours",
        path.display(),
        colours.len()
    );
    assert!(
        blue >= 300,
        "{}: only {blue} follower-blue pixels in the middle: agents not drawn",
        path.display()
    );
    path
}

/// A finished paper40 run (2,000 ticks) in a fresh directory; `extra` are more simulate flags.
fn paper40_run(tmp: &TempDir, extra: &[&str]) -> (PathBuf, Value) {
    let out = tmp.path().join("run");
    let o = out.to_str().unwrap_or_default();
    let mut args = vec![
        "simulate",
        "--out",
        o,
        "--no-figures",
        "--max-ticks",
        "2000",
    ];
    args.extend_from_slice(extra);
    ok(&run(&mut orchestrator(&args), RUN_DEADLINE));
    let audit = read_json(&out.join("audit.json"));
    (out, audit)
}

fn file_url(path: &Path) -> String {
    let abs = std::fs::canonicalize(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    format!("file://{}", abs.display())
}

/// paper40 inside its fence, beside a tower and a mast: all three are drawn.
#[test]
fn replay_html_works_from_file_with_the_network_disabled() {
    let tmp = TempDir::new();
    let fenced = write_scenario(tmp.path(), "fenced.toml", &fenced_paper40());
    let (out, audit) = paper40_run(&tmp, &["--scenario", fenced.to_str().unwrap()]);
    let replay = out.join("replay.html");
    let page = std::fs::read_to_string(&replay).unwrap_or_else(|e| panic!("{e}"));
    // Self-contained: nothing is loaded from anywhere else.
    for remote in ["src=\"http", "href=\"http", "import('http", "from 'http"] {
        assert!(!page.contains(remote), "replay.html refers to {remote}");
    }
    let s = status(&file_url(&replay), tmp.path(), true);
    assert_eq!(s.agents, 40, "{s:?}");
    // The replay opens on the run's last tick.
    assert_eq!(s.tick, 2000, "{s:?}");
    assert_eq!(s.verdict, audit["verdict"].as_str().unwrap_or("?"), "{s:?}");
    assert_eq!(s.lost, 0, "{s:?}");
    assert_eq!(s.commands, (0, 0), "{s:?}");
    assert_eq!(
        s.airspace, r#"{"fence":4,"obstacles":["tower","mast"]}"#,
        "{s:?}"
    );
    screenshot(&file_url(&replay), tmp.path(), true);
}

/// A commanded run (`simulate --commands`): held at 5 s, refused a 1 s goto at 10 s (eq. 34).
/// Its replay, on its last tick, counts one accepted and one refused command; a run without
/// commands counts none (`replay_html_works_from_file_with_the_network_disabled`).
#[test]
fn replay_html_counts_the_accepted_and_refused_commands() {
    let tmp = TempDir::new();
    let file = tmp.path().join("commands.json");
    std::fs::write(
        &file,
        r#"[{"at_s": 5, "command": "hold"},
            {"at_s": 10, "command": "goto", "travel_s": 1,
             "goals": [[300, 500, 600], [300, 300, 600], [400, 300, 600]]}]"#,
    )
    .unwrap();
    let (out, _) = paper40_run(&tmp, &["--commands", file.to_str().unwrap()]);
    let s = status(&file_url(&out.join("replay.html")), tmp.path(), true);
    assert_eq!((s.tick, s.commands), (2000, (1, 1)), "{s:?}");
}

/// The served run lost follower 20 at t = 5 s: the page shows it lost, with the repaired graph
/// drawn (`?graph=1`), and no page error.
#[test]
fn view_serves_the_replay_of_a_finished_run() {
    let tmp = TempDir::new();
    let (out, audit) = paper40_run(&tmp, &["--lose", "20@5"]);
    assert_eq!(audit["losses"][0]["id"], 20, "{audit}");
    std::fs::remove_file(out.join("replay.html")).unwrap_or_else(|e| panic!("{e}"));
    let o = out.to_str().unwrap_or_default();
    let mut view = spawn(&mut orchestrator(&["view", o, "--serve", "127.0.0.1:0"]));
    view.wait_for_output("serving http://", RUN_DEADLINE);
    let url = served_url(&mut view, "serving ");
    assert!(
        out.join("replay.html").is_file(),
        "view rewrites replay.html"
    );
    let s = status(&format!("{url}?graph=1"), tmp.path(), false);
    assert_eq!(
        (s.agents, s.tick, s.verdict.as_str(), s.lost),
        (40, 2000, audit["verdict"].as_str().unwrap_or("?"), 1),
        "{s:?}"
    );
    let done = view.kill();
    assert!(done.status.signal_or_code_known(), "{}", describe(&done));
}

/// A client that asks for the page and never reads it (a stalled browser, or someone on the
/// port on purpose) holds only its own answer: every other client is served at once. Three such
/// clients, each with a 4 KiB receive buffer against a page of MBs, are being answered (their
/// first bytes read) before the fourth asks; it must get the whole page within the deadline.
#[test]
fn clients_that_never_read_do_not_block_the_others() {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::os::fd::AsRawFd;

    let tmp = TempDir::new();
    let (out, _) = paper40_run(&tmp, &[]);
    let page = std::fs::metadata(out.join("replay.html")).map_or(0, |m| m.len()) as usize;
    assert!(
        page > 1 << 20,
        "the page ({page} bytes) outgrows the sockets' buffers"
    );
    let o = out.to_str().unwrap_or_default();
    let mut view = spawn(&mut orchestrator(&["view", o, "--serve", "127.0.0.1:0"]));
    view.wait_for_output("serving http://", RUN_DEADLINE);
    let url = served_url(&mut view, "serving ");
    let addr = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_owned();
    let get = b"GET / HTTP/1.1\r\nHost: viewer\r\nConnection: close\r\n\r\n";
    let connect = || {
        let s = TcpStream::connect(&addr).unwrap_or_else(|e| panic!("connect {addr}: {e}"));
        s.set_read_timeout(Some(RUN_DEADLINE))
            .unwrap_or_else(|e| panic!("{e}"));
        s
    };
    let stalled: Vec<TcpStream> = (0..3)
        .map(|k| {
            let mut s = connect();
            let small: libc::c_int = 4096;
            // SAFETY: setsockopt(2) reads one c_int from a live local for a socket we own.
            let rc = unsafe {
                libc::setsockopt(
                    s.as_raw_fd(),
                    libc::SOL_SOCKET,
                    libc::SO_RCVBUF,
                    (&small as *const libc::c_int).cast(),
                    std::mem::size_of::<libc::c_int>() as libc::socklen_t,
                )
            };
            assert_eq!(rc, 0, "SO_RCVBUF: {}", std::io::Error::last_os_error());
            s.write_all(get).unwrap_or_else(|e| panic!("{e}"));
            let mut head = [0u8; 12];
            s.read_exact(&mut head)
                .unwrap_or_else(|e| panic!("stalled client {k} got no answer: {e}"));
            assert_eq!(&head, b"HTTP/1.1 200", "stalled client {k}");
            s
        })
        .collect();
    let mut other = connect();
    other.write_all(get).unwrap_or_else(|e| panic!("{e}"));
    let mut body = Vec::new();
    if let Err(e) = other.read_to_end(&mut body) {
        panic!(
            "with {} clients not reading, another got {} of {page} bytes: {e}",
            stalled.len(),
            body.len()
        );
    }
    assert!(
        body.starts_with(b"HTTP/1.1 200") && body.len() > page,
        "{} bytes",
        body.len()
    );
    drop(stalled);
    let done = view.kill();
    assert!(done.status.signal_or_code_known(), "{}", describe(&done));
}

/// The `http://HOST:PORT/` the command printed after `prefix`.
fn served_url(child: &mut Running, prefix: &str) -> String {
    let (stdout, _) = child.output_so_far();
    let line = stdout
        .lines()
        .find(|l| l.starts_with(prefix))
        .unwrap_or_else(|| panic!("no `{prefix}` line in:\n{stdout}"));
    let at = line.find("http://").unwrap_or(0);
    line[at..]
        .split_whitespace()
        .next()
        .unwrap_or("")
        .to_owned()
}

trait Known {
    fn signal_or_code_known(&self) -> bool;
}

impl Known for std::process::ExitStatus {
    fn signal_or_code_known(&self) -> bool {
        use std::os::unix::process::ExitStatusExt;
        self.code().is_some() || self.signal().is_some()
    }
}

#[test]
fn a_live_launch_is_served_and_its_tick_advances() {
    let tmp = TempDir::new();
    let out = tmp.path().join("live");
    let team = unique_team("viewer");
    // 1,000,001 ticks (about a minute here, telemetry every 1000th): the team is sure to be
    // flying while Chromium, slow to start on a loaded machine, looks at it twice; then SIGINT
    // lands it. (A plan of 100,001 ticks could end before the first look, and the page then
    // showed one final tick: a flaky "the tick advances".)
    let mut orch = spawn(integration_tests::launch_loud(&team, &out, &[]).args([
        "--no-figures",
        "--t-total",
        "10000",
        "--every",
        "1000",
        "--serve",
        "127.0.0.1:0",
    ]));
    orch.wait_for_output("live view: http://", RUN_DEADLINE);
    let base = served_url(&mut orch, "live view: ");
    // `?frames=5`: the page closes its stream after five frames, so Chromium can take its snapshot.
    let url = format!("{base}?frames=5");
    let first = status(&url, tmp.path(), false);
    let second = status(&url, tmp.path(), false);
    let shot_url = format!("{base}?frames=5&graph=1");
    let shot = screenshot(&shot_url, tmp.path(), false);
    if let Some(keep) = std::env::var_os("CDM_VIEWER_SCREENSHOT") {
        // The book's picture (docs/src/guide/viewer.md) comes from here: CDM_VIEWER_SCREENSHOT=docs/src/figures/viewer-live.png.
        std::fs::copy(&shot, &keep)
            .unwrap_or_else(|e| panic!("{}: {e}", Path::new(&keep).display()));
    }
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(orch.id() as i32, libc::SIGINT) };
    let done = orch.finish(LIVE_DEADLINE);
    assert_eq!(done.status.code(), Some(3), "{}", describe(&done));
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["fault"]["kind"], "interrupted", "{audit:#}");
    let last = audit["ticks"].as_i64().unwrap_or(0) - 1;
    for s in [&first, &second] {
        assert_eq!(s.agents, 40, "{s:?}");
        let f = s.first_tick.unwrap_or(i64::MAX);
        assert!(f < s.tick, "the tick advances within one page: {s:?}");
        assert!(s.tick <= last, "{s:?} beyond the last tick {last}");
        // The team was flying at both looks.
        assert_eq!(s.verdict, "RUNNING", "{s:?}");
    }
    assert!(
        first.tick < second.tick,
        "a later page shows a later tick: {first:?} then {second:?}"
    );
}

/// `launch --realtime --serve`: the page's event stream carries frames while the team flies
/// (no more than the view's 10 Hz: far fewer than the 300 audited instants), their ticks rising
/// within the plan, then the verdict.
#[test]
fn a_real_time_launch_streams_frames_as_it_flies() {
    use std::io::{BufRead, BufReader, Write};
    use std::net::TcpStream;

    let tmp = TempDir::new();
    let out = tmp.path().join("rt");
    let team = unique_team("viewer-rt");
    let mut orch = spawn(
        integration_tests::launch_loud(&team, &out, &["--n", "10"]).args([
            "--realtime",
            "--no-figures",
            "--max-ticks",
            "300",
            "--serve",
            "127.0.0.1:0",
        ]),
    );
    orch.wait_for_output("live view: http://", RUN_DEADLINE);
    let base = served_url(&mut orch, "live view: ");
    let addr = base.trim_start_matches("http://").trim_end_matches('/');
    let mut events = TcpStream::connect(addr).unwrap_or_else(|e| panic!("connect {addr}: {e}"));
    events
        .set_read_timeout(Some(RUN_DEADLINE))
        .unwrap_or_else(|e| panic!("{e}"));
    events
        .write_all(b"GET /events HTTP/1.1\r\nHost: viewer\r\n\r\n")
        .unwrap_or_else(|e| panic!("{e}"));
    let (mut ticks, mut kind, mut end) = (Vec::new(), String::new(), None);
    for line in BufReader::new(events).lines() {
        let line = line.unwrap_or_else(|e| panic!("the stream after {} frames: {e}", ticks.len()));
        if let Some(k) = line.strip_prefix("event: ") {
            kind = k.to_owned();
        } else if let Some(data) = line.strip_prefix("data: ") {
            let v: Value = serde_json::from_str(data).unwrap_or_default();
            if kind == "end" {
                end = Some(v);
                break;
            }
            ticks.push(v["frame"]["tick"].as_u64().unwrap_or(u64::MAX));
        }
    }
    let done = orch.finish(RUN_DEADLINE);
    assert_eq!(done.status.code(), Some(0), "{}", describe(&done));
    let end = end.unwrap_or_else(|| panic!("no end event after frames {ticks:?}"));
    assert_eq!(end["verdict"], "SAFE", "{end}");
    assert!(
        ticks.len() >= 5,
        "frames while flying about 3 s in real time: {ticks:?}"
    );
    assert!(
        ticks.len() <= 40,
        "at most 10 frames a second: {} frames",
        ticks.len()
    );
    assert!(
        ticks.windows(2).all(|w| w[0] < w[1]) && ticks.iter().all(|&t| t <= 300),
        "rising ticks within the plan: {ticks:?}"
    );
}

#[test]
fn replay_of_a_thousand_agents_stays_within_its_budget() {
    let tmp = TempDir::new();
    let out = tmp.path().join("n1000");
    let o = out.to_str().unwrap_or_default();
    ok(&run(
        &mut orchestrator(&[
            "simulate",
            "--n",
            "1000",
            "--out",
            o,
            "--no-figures",
            "--max-ticks",
            "1500",
        ]),
        RUN_DEADLINE,
    ));
    let size = std::fs::metadata(out.join("replay.html"))
        .unwrap_or_else(|e| panic!("{e}"))
        .len();
    // The budget of common/viewer/src/lib.rs (REPLAY_BUDGET_BYTES).
    assert!(size <= 20 << 20, "replay.html is {size} bytes at N = 1000");
    let s = status(&file_url(&out.join("replay.html")), tmp.path(), true);
    assert_eq!((s.agents, s.tick), (1000, 1500), "{s:?}");
}

#[test]
fn bad_serve_addresses_and_run_directories_are_refused() {
    let tmp = TempDir::new();
    let out = tmp.path().join("never");
    let o = out.to_str().unwrap_or_default();
    let bad = run(
        &mut orchestrator(&["launch", "--out", o, "--serve", "nowhere"]),
        RUN_DEADLINE,
    );
    assert_eq!(bad.status.code(), Some(2), "{}", describe(&bad));
    assert!(
        String::from_utf8_lossy(&bad.stderr).contains("--serve nowhere"),
        "{}",
        describe(&bad)
    );
    // A port that is taken: refused before any process or file of the team exists.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let addr = taken
        .local_addr()
        .unwrap_or_else(|e| panic!("{e}"))
        .to_string();
    let team = unique_team("busyport");
    let busy = run(
        integration_tests::launch_loud(&team, &out, &[]).args(["--serve", &addr]),
        RUN_DEADLINE,
    );
    assert_eq!(busy.status.code(), Some(2), "{}", describe(&busy));
    assert!(
        String::from_utf8_lossy(&busy.stderr).contains("cannot listen"),
        "{}",
        describe(&busy)
    );
    assert!(!out.exists(), "a refused launch created {}", out.display());
    // `view` of a directory that is not a run names the file it misses.
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap_or_else(|e| panic!("{e}"));
    let view = run(
        &mut orchestrator(&["view", empty.to_str().unwrap_or_default()]),
        RUN_DEADLINE,
    );
    assert_eq!(view.status.code(), Some(2), "{}", describe(&view));
    assert!(
        String::from_utf8_lossy(&view.stderr).contains("scenario.toml"),
        "{}",
        describe(&view)
    );
}
