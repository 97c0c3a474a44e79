//! Losing no data: a full disk, a symbolic link in a run directory, a
//! closed or full stdout. Real binaries, real files; the full disk is a small tmpfs mounted by
//! the test (CI runs as root; elsewhere the test says "skipped"), and pyarrow reads what a full
//! disk leaves of telemetry.parquet.

use integration_tests::support;

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use integration_tests::{bin, describe, run, unique_team, TempDir};
use support::*;

/// A short flight (paper40, 31 ticks) takes well under a second; this only stops a hang.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

/// A tmpfs of a given size mounted for one test, unmounted on drop.
struct SmallDisk {
    dir: PathBuf,
}

impl SmallDisk {
    fn mount(at: &Path, size: &str) -> Option<Self> {
        fs::create_dir_all(at).ok()?;
        let ok = Command::new("mount")
            .args([
                "-t",
                "tmpfs",
                "-o",
                &format!("size={size},mode=0700"),
                "tmpfs",
            ])
            .arg(at)
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| SmallDisk {
            dir: at.to_path_buf(),
        })
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.dir).status();
    }
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn paper40_ids() -> BTreeSet<u32> {
    (1..=40).collect()
}

/// Item 7: `simulate` into a full file system. telemetry.csv ends on a whole tick, audit.json is
/// written (FAULT, naming the file), no temporary is left, the message names the file and the
/// free space, exit 3. `report` on the same full disk: exit 3, no 0-byte figure, no Rust debug
/// text.
#[test]
fn a_full_disk_keeps_whole_ticks_and_the_audit_and_says_where() {
    let tmp = TempDir::new();
    let Some(disk) = SmallDisk::mount(&tmp.path().join("disk"), "200k") else {
        eprintln!("skipped: cannot mount a tmpfs here (needs root)");
        return;
    };
    let out = disk.dir.join("run");
    let o = run(
        simulate(&out, &["--no-figures"]).arg("--every").arg("1"),
        DEADLINE,
    );
    assert_exit(&o, 3, "simulate into a full disk");
    let all = text(&o);
    let tel = out.join("telemetry.csv");
    assert!(
        all.contains(&tel.display().to_string()) && all.contains("KiB free"),
        "the message names the file and the free space\n{}",
        describe(&o)
    );
    let ticks = complete_ticks(&tel, &paper40_ids());
    assert!(ticks > 0, "no whole tick was kept");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit}");
    let message = audit["fault"]["message"].as_str().unwrap_or_default();
    assert!(message.contains("telemetry.csv"), "{audit}");
    let leftovers: Vec<PathBuf> = files_under(&out)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "tmp"))
        .collect();
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");

    let mut report = Command::new(bin("orchestrator"));
    report.arg("report").arg(&out);
    let o = run(&mut report, DEADLINE);
    assert_exit(&o, 3, "report into a full disk");
    let all = text(&o);
    assert!(all.contains("no space left"), "{}", describe(&o));
    for debug in ["Custom {", "Error(", "kind:"] {
        assert!(!all.contains(debug), "Rust debug text\n{}", describe(&o));
    }
    for f in files_under(&out) {
        let len = fs::metadata(&f).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "{} is empty", f.display());
    }
}

/// `--telemetry parquet` into a full file system: a Parquet file is readable only with its
/// footer, and the footer comes last. The writer keeps one after every row group, so what the
/// disk held is kept: pyarrow reads whole row groups of whole ticks; the message names the file,
/// the free space and what was kept; audit.json says FAULT; exit 3. 200 members write about
/// 3.5 MiB per row group (65,536 rows and up to a tick more, about 55 bytes a row), so a 12 MiB
/// disk holds about three.
#[test]
fn a_full_disk_keeps_a_readable_parquet_file_of_whole_row_groups() {
    const N: usize = 200;
    let tmp = TempDir::new();
    let Some(disk) = SmallDisk::mount(&tmp.path().join("disk"), "12m") else {
        eprintln!("skipped: cannot mount a tmpfs here (needs root)");
        return;
    };
    let out = disk.dir.join("run");
    let n = N.to_string();
    let o = run(
        simulate(&out, &["--n", &n, "--no-figures", "--every", "1"])
            .args(["--telemetry", "parquet"]),
        DEADLINE,
    );
    assert_exit(&o, 3, "simulate --telemetry parquet into a full disk");
    let all = text(&o);
    let file = out.join("telemetry.parquet");
    assert!(
        all.contains(&file.display().to_string()) && all.contains("KiB free"),
        "the message names the file and the free space\n{}",
        describe(&o)
    );
    assert!(
        all.contains("row groups"),
        "says what it kept\n{}",
        describe(&o)
    );
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit}");
    let message = audit["fault"]["message"].as_str().unwrap_or_default();
    assert!(message.contains("telemetry.parquet"), "{audit}");
    // pyarrow, as a pandas or DuckDB user would open it.
    let script = "import json, sys, collections\n\
import pyarrow.parquet as pq\n\
f = pq.ParquetFile(sys.argv[1])\n\
t = f.read(columns=['tick', 'id'])\n\
per_tick = collections.Counter(t.column('tick').to_pylist())\n\
print(json.dumps({'row_groups': f.num_row_groups, 'rows': t.num_rows,\n\
  'ticks': sorted(per_tick), 'sizes': sorted(set(per_tick.values()))}))\n";
    let py = run(
        Command::new(integration_tests::venv_python())
            .args(["-c", script])
            .arg(&file),
        DEADLINE,
    );
    assert_exit(&py, 0, "pyarrow reads what the full disk kept");
    let got: serde_json::Value =
        serde_json::from_slice(&py.stdout).unwrap_or_else(|e| panic!("{e}: {}", describe(&py)));
    let groups = got["row_groups"].as_u64().unwrap_or(0);
    assert!(groups >= 1, "no whole row group kept: {got}");
    assert_eq!(
        got["sizes"],
        serde_json::json!([N]),
        "a tick cut short: {got}"
    );
    let ticks: Vec<u64> = got["ticks"]
        .as_array()
        .map(|t| t.iter().filter_map(|v| v.as_u64()).collect())
        .unwrap_or_default();
    assert!(
        ticks.iter().copied().eq(0..ticks.len() as u64),
        "the kept ticks are not 0, 1, 2, ...: {got}"
    );
    assert!(
        all.contains(&format!("kept {} rows", ticks.len() * N)),
        "the message's count is the file's\n{}",
        describe(&o)
    );
}

/// `--telemetry mcap` into a full file system: the message names the bag's file or the table's
/// and the free space; the bag is ended (summary, footer, metadata.yaml: `rosbags` and Foxglove's
/// `mcap` read it) and ends on the very tick where telemetry.csv ends; nothing but its two files
/// is left in its directory; exit 3. Ten members write about 1 MiB of bag per 200 ticks, and
/// the bag keeps about 2 MiB free to end itself, so a 3 MiB disk is full within the flight.
/// Before the fix the bag had no summary, footer or metadata.yaml and went on 4 s past the
/// table's end.
#[test]
fn a_full_disk_ends_the_bag_where_the_table_ends() {
    const N: u32 = 10;
    let tmp = TempDir::new();
    let Some(disk) = SmallDisk::mount(&tmp.path().join("disk"), "3m") else {
        eprintln!("skipped: cannot mount a tmpfs here (needs root)");
        return;
    };
    let out = disk.dir.join("run");
    let o = run(
        simulate(&out, &["--n", "10", "--t-total", "20", "--no-figures"])
            .args(["--telemetry", "mcap"]),
        DEADLINE,
    );
    assert_exit(&o, 3, "simulate --telemetry mcap into a full disk");
    let all = text(&o);
    let (tel, bag) = (out.join("telemetry.csv"), out.join("rosbag2"));
    assert!(
        [&tel, &bag.join("rosbag2_0.mcap")]
            .iter()
            .any(|f| all.contains(&f.display().to_string()))
            && all.contains("KiB free"),
        "the message names the file and the free space\n{}",
        describe(&o)
    );
    let ticks = complete_ticks(&tel, &(1..=N).collect());
    assert!(ticks > 0, "no whole tick was kept");
    let last_t: f64 = fs::read_to_string(&tel)
        .expect("telemetry.csv")
        .lines()
        .last()
        .and_then(|l| l.split(',').nth(1)?.parse().ok())
        .expect("the last row's time");
    let mut left: Vec<String> = fs::read_dir(&bag)
        .expect("the bag's directory")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        ["metadata.yaml", "rosbag2_0.mcap"],
        "in {}",
        bag.display()
    );
    let script = r#"
import json, sys
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
with open(sys.argv[1] + '/rosbag2_0.mcap', 'rb') as f:
    summary = make_reader(f).get_summary()
with Reader(sys.argv[1]) as r:
    stamps = [t for _, t, _ in r.messages()]
    poses = sum(c.msgcount for c in r.connections if c.topic == '/cdm/agent_1/pose')
print(json.dumps({'summary': summary is not None, 'last_ns': max(stamps), 'poses': poses}))
"#;
    let py = run(
        Command::new(integration_tests::venv_python())
            .args(["-c", script])
            .arg(&bag),
        DEADLINE,
    );
    assert_exit(&py, 0, "rosbags and mcap read the bag the full disk kept");
    let got: serde_json::Value =
        serde_json::from_slice(&py.stdout).unwrap_or_else(|e| panic!("{e}: {}", describe(&py)));
    assert_eq!(got["summary"], true, "{got}");
    let last_s = got["last_ns"].as_f64().unwrap_or(-1.0) * 1e-9;
    assert!(
        (last_s - last_t).abs() < 1e-6,
        "the bag ends at {last_s} s, telemetry.csv at {last_t} s ({ticks} ticks): {got}"
    );
    assert_eq!(
        got["poses"], ticks,
        "one pose of agent 1 per tick kept: {got}"
    );
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit}");
}

/// Item 8: `--force` into a run directory whose telemetry.csv and audit.json are symbolic links:
/// the links are replaced by files, their targets are untouched.
#[test]
fn force_never_writes_through_a_symbolic_link() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let o = run(
        &mut simulate(&out, &["--max-ticks", "5", "--no-figures"]),
        DEADLINE,
    );
    assert_exit(&o, 0, "the first simulate");
    let mut targets = Vec::new();
    for name in [
        "telemetry.csv",
        "audit.json",
        "scenario.toml",
        "audit.json.tmp",
    ] {
        let target = tmp.path().join(format!("precious-{name}"));
        fs::write(&target, "precious").expect("write target");
        let link = out.join(name);
        let _ = fs::remove_file(&link);
        std::os::unix::fs::symlink(&target, &link).expect("symlink");
        targets.push((link, target));
    }
    let o = run(
        &mut simulate(&out, &["--max-ticks", "5", "--force"]),
        DEADLINE,
    );
    assert_exit(&o, 0, "simulate --force");
    for (link, target) in &targets {
        assert_eq!(
            fs::read_to_string(target).expect("target"),
            "precious",
            "{} was written through",
            link.display()
        );
    }
    for name in ["telemetry.csv", "audit.json", "scenario.toml"] {
        let m = fs::symlink_metadata(out.join(name)).expect("written");
        assert!(m.file_type().is_file(), "{name} is not a regular file");
    }
    assert_eq!(
        complete_ticks(&out.join("telemetry.csv"), &paper40_ids()),
        6
    );
}

/// Runs `cmd` with the given stdout (the harness captures stdout, these tests must not), stderr
/// captured, under a deadline (killed and failed past it).
fn run_with_stdout(cmd: &mut Command, stdout: Stdio) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut err = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut v = Vec::new();
        let _ = std::io::Read::read_to_end(&mut err, &mut v);
        v
    });
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            panic!("{cmd:?} still runs after {DEADLINE:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        status,
        stdout: Vec::new(),
        stderr: reader.join().unwrap_or_default(),
    }
}

/// A pipe whose read end is already closed: every write to it fails with EPIPE, as after
/// `| head -1` has read its line.
fn closed_pipe() -> Stdio {
    use std::os::fd::{FromRawFd, OwnedFd};
    let mut fds = [0; 2];
    // SAFETY: pipe(2) fills two descriptors we then own; the read end is closed at once.
    unsafe {
        assert_eq!(libc::pipe(fds.as_mut_ptr()), 0, "pipe");
        libc::close(fds[0]);
        Stdio::from(OwnedFd::from_raw_fd(fds[1]))
    }
}

/// Item 9: a closed stdout (`plan | head -1`, `scenario export | head -1`) and a full one
/// (`launch > /dev/full`): no panic, and the run's files are complete.
#[test]
fn a_closed_or_full_stdout_does_not_panic_and_the_files_are_complete() {
    let tmp = TempDir::new();
    let json = tmp.path().join("certificate.json");
    let plan = [
        "plan",
        "--t-total",
        "60",
        "--json",
        json.to_str().expect("UTF-8"),
    ];
    for args in [&plan[..], &["scenario", "export", "--n", "100"][..]] {
        let o = run_with_stdout(Command::new(bin("orchestrator")).args(args), closed_pipe());
        assert_eq!(o.status.code(), Some(0), "{args:?}\n{}", describe(&o));
        assert!(!text(&o).contains("panicked"), "{args:?}\n{}", describe(&o));
    }
    assert_eq!(read_json(&json)["verdict"], "SAFE");

    let out = tmp.path().join("run");
    let team = unique_team("fullout");
    let full = fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .expect("/dev/full");
    // Not --quiet: the summary goes to the full stdout.
    let mut c = Command::new(bin("orchestrator"));
    c.args([
        "launch",
        "--n",
        "10",
        "--t-total",
        "30",
        "--no-figures",
        "--team",
        &team,
    ])
    .arg("--out")
    .arg(&out);
    let o = run_with_stdout(&mut c, Stdio::from(full));
    assert_exit(&o, 0, "launch > /dev/full");
    assert!(!text(&o).contains("panicked"), "{}", describe(&o));
    assert_eq!(read_json(&out.join("audit.json"))["verdict"], "SAFE");
    let ids: BTreeSet<u32> = (1..=10).collect();
    assert_eq!(complete_ticks(&out.join("telemetry.csv"), &ids), 3001);
    assert_no_team_resources(&team);
}
