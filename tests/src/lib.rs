//! Shared harness for the workspace's integration tests: the real binaries, built fresh and of
//! the same profile as the test; a temporary directory and a unique team name per test; running
//! a process under a watchdog deadline so that no test can hang; writing scenario files.
//!
//! Every child is started in its own process group and killed as a group (SIGKILL), so that a
//! process that spawned helpers (the orchestrator starts agents) leaves nothing behind when a
//! deadline passes or a guard is dropped.
//!
//! This is test support: it panics, with a message naming the command, file or deadline at
//! fault, instead of returning errors. Unix only (process groups, SIGKILL). `support` holds the
//! helpers the test files share (`tests/tests/`: a directory per command or feature, each
//! directory one test binary).

pub mod support;

use std::collections::BTreeMap;
use std::ffi::OsStr;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use cdm_scenario::ScenarioFile;

/// How often `run` and `Running` poll a child for exit or output.
const POLL: Duration = Duration::from_millis(10);

/// The build directory of the running test: `<target>/<profile>` (the test executable lives in
/// `<target>/<profile>/deps/`).
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe()
        .unwrap_or_else(|e| panic!("harness: cannot find the test executable's path: {e}"));
    let deps = exe.parent().unwrap_or_else(|| {
        panic!(
            "harness: test executable {} has no parent directory",
            exe.display()
        )
    });
    // Test executables live in `deps/`; examples or benches run directly from the profile dir.
    let dir = if deps.file_name() == Some(OsStr::new("deps")) {
        deps.parent()
    } else {
        Some(deps)
    };
    dir.unwrap_or_else(|| {
        panic!(
            "harness: cannot derive the profile directory from {}",
            exe.display()
        )
    })
    .to_path_buf()
}

/// The cargo arguments that select the profile of a test whose output directory is `dir_name`:
/// a test in `debug` runs under the `test` profile (the workspace gives it opt-level 1, which
/// keeps full plans affordable); any other directory is named after its profile.
fn profile_args(dir_name: &str) -> Vec<String> {
    match dir_name {
        "debug" => vec!["--profile".into(), "test".into()],
        "release" => vec!["--release".into()],
        other => vec!["--profile".into(), other.into()],
    }
}

/// The `cargo build` of `what` (e.g. `--bins --workspace`) into `profile_dir`: the same profile,
/// target directory and (for `<target>/<triple>/<profile>`) target triple as the running test.
fn build_command(profile_dir: &Path, what: &[&str]) -> Command {
    let name = |p: &Path| {
        p.file_name()
            .and_then(OsStr::to_str)
            .map(str::to_string)
            .unwrap_or_else(|| panic!("harness: directory {} has no name", p.display()))
    };
    let parent = |p: &Path| {
        p.parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| panic!("harness: directory {} has no parent", p.display()))
    };
    let profile = name(profile_dir);
    let mut target_dir = parent(profile_dir);
    let mut triple = None;
    // Cargo marks the root of a target directory with CACHEDIR.TAG; a cross build puts the
    // profile directory one level further down, under the target triple.
    if !target_dir.join("CACHEDIR.TAG").exists()
        && parent(&target_dir).join("CACHEDIR.TAG").exists()
    {
        triple = Some(name(&target_dir));
        target_dir = parent(&target_dir);
    }
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.arg("build")
        .args(what)
        .args(profile_args(&profile))
        .arg("--manifest-path")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.toml"))
        .arg("--target-dir")
        .arg(target_dir);
    if let Some(t) = triple {
        cmd.arg("--target").arg(t);
    }
    without_test_variables(&mut cmd);
    cmd.stdin(Stdio::null());
    cmd
}

/// Removes the variables cargo gives a running test (CARGO_MANIFEST_DIR, CARGO_PKG_*...) from a
/// command that runs cargo (directly, or through pip and maturin).
pub fn without_test_variables(cmd: &mut Command) {
    // Cargo gives a running test its package's variables (CARGO_MANIFEST_DIR, CARGO_PKG_*...).
    // Passed on, they make this build differ from the developer's `cargo test`: ring's build
    // script asks to rerun when CARGO_MANIFEST_DIR changes, so each of the two builds would
    // compile ring and everything above it again (4 minutes per run here).
    for (k, _) in std::env::vars_os() {
        let k = k.to_string_lossy();
        let per_test = [
            "CARGO_MANIFEST_",
            "CARGO_PKG_",
            "CARGO_BIN_",
            "CARGO_CRATE_NAME",
        ]
        .iter()
        .any(|p| k.starts_with(p))
            || k == "CARGO_PRIMARY_PACKAGE"
            || k == "CARGO_TARGET_TMPDIR";
        if per_test {
            cmd.env_remove(k.as_ref());
        }
    }
}

/// Run `cargo build <what>` once per test process and `what`, with the running test's profile
/// and target directory, so that nothing the tests run is stale. The outcome is kept: after a
/// failed build every later call fails with the same message instead of building again.
fn build_once(what: &[&str]) {
    static BUILT: Mutex<BTreeMap<Vec<String>, Result<(), String>>> = Mutex::new(BTreeMap::new());
    let key: Vec<String> = what.iter().map(|s| s.to_string()).collect();
    // Held across the build: two tests asking for the same thing build it once.
    let mut built = BUILT.lock().unwrap_or_else(|p| p.into_inner());
    let outcome = built.entry(key).or_insert_with(|| {
        let mut cmd = build_command(&profile_dir(), what);
        match cmd.output() {
            Err(e) => Err(format!("cannot start {cmd:?}: {e}")),
            Ok(out) if !out.status.success() => Err(format!(
                "{cmd:?} failed ({}):\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            )),
            Ok(_) => Ok(()),
        }
    });
    if let Err(e) = outcome {
        panic!("harness: building {what:?} failed: {e}");
    }
}

/// What the tests run, built by one `cargo build`: every binary and every example of the
/// workspace. Examples take the dev-dependencies, so this resolves the features `cargo test
/// --workspace` resolves and finds its build fresh; a narrower request (`--package P --example
/// E`, or `--bins` alone) would resolve other features and compile the workspace again.
const EVERYTHING: &[&str] = &["--workspace", "--bins", "--examples"];

fn ensure_built() {
    build_once(EVERYTHING);
}

/// The path of example `name` of workspace package `package`, of the same profile as the
/// running test (built on first use, like [`bin`]).
pub fn example(package: &str, name: &str) -> PathBuf {
    build_once(EVERYTHING);
    let path = profile_dir()
        .join("examples")
        .join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(
        path.is_file(),
        "harness: example `{name}` of `{package}` not found at {} after building it",
        path.display()
    );
    path
}

/// The path of a workspace binary (`orchestrator`, `agent`, `leader`) of the same profile as the
/// running test. The first call in a test process runs `cargo build --bins --workspace` with
/// that profile (`--release` for release), so the binary is never stale; panics if the build
/// fails or the binary is not there afterwards.
pub fn bin(name: &str) -> PathBuf {
    ensure_built();
    let path = profile_dir().join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(
        path.is_file(),
        "harness: binary `{name}` not found at {} after building the workspace",
        path.display()
    );
    path
}

/// A test peer or reader script of `tests/python/`.
pub fn python_script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("python")
        .join(name)
}

/// The Python of the test virtual environment (`.venv` at the workspace root, made by
/// `scripts/test-deps.sh` with the pinned readers of `python/requirements-test.txt`). Panics,
/// naming the script to run, when it is missing: tests that need a reader never skip.
///
/// It builds the workspace first, as [`bin`] does: a test that starts a Python peer (a vehicle
/// with `--max-s`, a subscriber) before its first `bin` call would otherwise have the build run
/// while the peer's clock does, and a slow build outlasts the peer.
pub fn venv_python() -> PathBuf {
    ensure_built();
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(".venv")
        .join("bin")
        .join("python");
    assert!(
        path.is_file(),
        "harness: {} is missing; run scripts/test-deps.sh first (the README's test command does)",
        path.display()
    );
    path
}

/// Every deadline of the integration tests, from one scale. A deadline is the limit for a wait
/// that would otherwise never end (a hung process), never the expected duration of anything:
/// tests wait for an event (an exit, a line, a file) and pass as soon as it happens, so a longer
/// deadline only makes a hung test fail later. The harness's waits ([`run`], [`Running::finish`],
/// [`Running::wait_for_output`]) multiply each by `CDM_TEST_DEADLINE_SCALE` (default 1), for a
/// machine slower than two loaded cores.
pub mod deadline {
    use std::time::Duration;

    /// A command that refuses its input, or a short helper (a Python reader, a browser page).
    pub const REFUSE: Duration = Duration::from_secs(30);
    /// A small team or a short plan, start to exit.
    pub const SHORT: Duration = Duration::from_secs(60);
    /// A full flight: paper40 as 40 processes, a team across hosts, a browser over a live run.
    pub const FLIGHT: Duration = Duration::from_secs(180);
    /// The largest: a thousand members, or a run that writes gigabytes.
    pub const LONG: Duration = Duration::from_secs(600);

    /// `d` times `CDM_TEST_DEADLINE_SCALE` (a positive number; anything else counts as 1).
    pub fn scaled(d: Duration) -> Duration {
        let scale = std::env::var("CDM_TEST_DEADLINE_SCALE")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|k| k.is_finite() && *k > 0.0)
            .unwrap_or(1.0);
        d.mul_f64(scale)
    }
}

/// A base port with `n` free UDP ports from it, on 127.0.0.1, below the kernel's ephemeral range
/// (`net.ipv4.ip_local_port_range`): no socket that another process opens without choosing a port
/// (a Python vehicle's sending socket, a zenoh link, a browser) can take one of them between this
/// check and the member's bind, as one from the ephemeral range could. Blocks never repeat within
/// a test process; where they start depends on the process id, so two test processes rarely meet.
pub fn free_udp_ports(n: u16) -> u16 {
    const LOWEST: u32 = 10_000;
    let ephemeral_low = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse::<u32>().ok())
        .unwrap_or(32_768);
    let top = ephemeral_low.max(LOWEST + 1_000);
    let span = top - LOWEST - u32::from(n);
    static CURSOR: Mutex<Option<u32>> = Mutex::new(None);
    let mut cursor = CURSOR.lock().unwrap_or_else(|p| p.into_inner());
    let mut next = cursor.unwrap_or_else(|| std::process::id().wrapping_mul(7_919) % span);
    for _ in 0..200 {
        let base = LOWEST + next % span;
        next = (next + u32::from(n)) % span;
        let held: Vec<_> = (base..base + u32::from(n))
            .map_while(|p| std::net::UdpSocket::bind(("127.0.0.1", p as u16)).ok())
            .collect();
        if held.len() == usize::from(n) {
            *cursor = Some(next);
            return base as u16;
        }
    }
    panic!("harness: no {n} consecutive free UDP ports in {LOWEST}..{top}");
}

/// Counter shared by `TempDir` and `unique_team` so names never repeat within a process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A fresh directory `cdm-test-<pid>-<n>` under `std::env::temp_dir()`, removed (with its
/// contents) on drop.
#[derive(Debug)]
pub struct TempDir {
    path: PathBuf,
}

impl TempDir {
    /// Create a new, empty directory. A leftover of the same name (a recycled pid) is removed.
    pub fn new() -> Self {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("cdm-test-{}-{n}", std::process::id()));
        if path.exists() {
            let _ = std::fs::remove_dir_all(&path);
        }
        std::fs::create_dir_all(&path).unwrap_or_else(|e| {
            panic!(
                "harness: cannot create temporary directory {}: {e}",
                path.display()
            )
        });
        TempDir { path }
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Default for TempDir {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// Longest name `unique_team` returns.
pub const MAX_TEAM_LEN: usize = 48;

/// A team name no other test (in this process or a concurrent one) uses:
/// `t<pid>_<tag>_<n>`, only `[A-Za-z0-9_-]` (other characters of `tag` become `_`), at most
/// `MAX_TEAM_LEN` characters (the tag is shortened, never the pid or the counter).
pub fn unique_team(tag: &str) -> String {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let pid = std::process::id();
    let fixed = format!("t{pid}__{n}").len();
    let room = MAX_TEAM_LEN.saturating_sub(fixed);
    let tag: String = tag
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .take(room)
        .collect();
    format!("t{pid}_{tag}_{n}")
}

/// How long the output pumps get to drain once a child has exited or been killed.
const DRAIN_GRACE: Duration = Duration::from_millis(500);

/// Kill a child's whole process group with SIGKILL (the child leads its group: see `prepare`).
fn kill_group(child: &mut Child) {
    if let Ok(pid) = libc::pid_t::try_from(child.id()) {
        // SAFETY: kill(2) takes no pointers. A negative pid signals the process group `pid`.
        // Linux keeps a pid number in use while it names a live process group, so even after the
        // leader has been reaped this can only reach helpers the child left in its group.
        unsafe {
            libc::kill(-pid, libc::SIGKILL);
        }
    }
    let _ = child.kill();
}

/// Common set-up: stdin null, output captured, own process group.
fn prepare(cmd: &mut Command) {
    cmd.stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0);
}

/// Start a thread that appends everything `src` yields to `buf`; the receiver hears at EOF.
fn pump(mut src: impl Read + Send + 'static, buf: Arc<Mutex<Vec<u8>>>) -> Receiver<()> {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let mut chunk = [0u8; 8192];
        loop {
            match src.read(&mut chunk) {
                Ok(0) | Err(_) => break,
                Ok(k) => buf
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .extend_from_slice(&chunk[..k]),
            }
        }
        let _ = tx.send(());
    });
    rx
}

/// A running child with its output being collected.
struct Captured {
    child: Child,
    stdout: Arc<Mutex<Vec<u8>>>,
    stderr: Arc<Mutex<Vec<u8>>>,
    /// EOF notices of the stdout and stderr pumps, and whether each has arrived.
    eof: [Receiver<()>; 2],
    eof_seen: [bool; 2],
    program: String,
}

impl Captured {
    fn start(cmd: &mut Command) -> Self {
        prepare(cmd);
        let program = format!("{cmd:?}");
        let mut child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("harness: cannot start {program}: {e}"));
        let stdout = Arc::new(Mutex::new(Vec::new()));
        let stderr = Arc::new(Mutex::new(Vec::new()));
        let (Some(out), Some(err)) = (child.stdout.take(), child.stderr.take()) else {
            panic!("harness: {program}: stdout/stderr were not captured");
        };
        let eof = [pump(out, stdout.clone()), pump(err, stderr.clone())];
        Captured {
            child,
            stdout,
            stderr,
            eof,
            eof_seen: [false; 2],
            program,
        }
    }

    fn snapshot(&self) -> (Vec<u8>, Vec<u8>) {
        let get = |b: &Arc<Mutex<Vec<u8>>>| b.lock().unwrap_or_else(|p| p.into_inner()).clone();
        (get(&self.stdout), get(&self.stderr))
    }

    /// Wait until both pipes have reached EOF (everything written has been collected), or
    /// `until`; true when they have.
    fn pipes_closed(&mut self, until: Instant) -> bool {
        for (rx, seen) in self.eof.iter().zip(self.eof_seen.iter_mut()) {
            if !*seen {
                let left = until.saturating_duration_since(Instant::now());
                *seen = rx.recv_timeout(left).is_ok();
            }
        }
        self.eof_seen.iter().all(|s| *s)
    }

    /// [`Self::wait_until`] `deadline` from now; past it (group killed) panics naming the command
    /// and the deadline, with the output so far.
    fn finish_or_panic(&mut self, deadline: Duration) -> Output {
        let deadline = deadline::scaled(deadline);
        match self.wait_until(Instant::now() + deadline) {
            Ok(out) => out,
            Err(out) => panic!(
                "harness: {} did not finish within {deadline:?}; killed.\n{}",
                self.program,
                describe(&out)
            ),
        }
    }

    /// Wait for exit and for both pipes to close, until `until` (plus a short grace for the
    /// pipes). Otherwise the group is killed and `Err` carries what was collected.
    fn wait_until(&mut self, until: Instant) -> Result<Output, Output> {
        let status: Option<ExitStatus> = loop {
            match self.child.try_wait() {
                Ok(Some(s)) => break Some(s),
                Ok(None) if Instant::now() >= until => break None,
                Ok(None) => thread::sleep(POLL),
                Err(e) => panic!("harness: waiting for {}: {e}", self.program),
            }
        };
        // A helper the child left behind may still hold the pipes open: it gets until the
        // deadline too, then the group is killed.
        let closed = status.is_some() && self.pipes_closed(until.max(Instant::now() + DRAIN_GRACE));
        if !closed {
            kill_group(&mut self.child);
            self.pipes_closed(Instant::now() + DRAIN_GRACE);
        }
        let status = match status {
            Some(s) => s,
            None => self
                .child
                .wait()
                .unwrap_or_else(|e| panic!("harness: reaping {}: {e}", self.program)),
        };
        let (stdout, stderr) = self.snapshot();
        let out = Output {
            status,
            stdout,
            stderr,
        };
        if closed {
            Ok(out)
        } else {
            Err(out)
        }
    }
}

/// Run a command to completion with stdin null and stdout/stderr captured. If it (or a helper
/// it left holding its output) is still running after `deadline`, its process group is killed
/// with SIGKILL and this panics naming the command and the deadline, with the output so far.
pub fn run(cmd: &mut Command, deadline: Duration) -> Output {
    Captured::start(cmd).finish_or_panic(deadline)
}

/// Start a command in the background (stdin null, its own process group, stdout and stderr
/// collected continuously). The returned guard kills the child's process group with SIGKILL
/// when dropped, so a failing test leaves no process behind.
pub fn spawn(cmd: &mut Command) -> Running {
    Running {
        inner: Some(Captured::start(cmd)),
    }
}

/// A background child started by `spawn`; its process group is killed on drop.
pub struct Running {
    /// `None` once `finish` or `kill` has taken the child.
    inner: Option<Captured>,
}

impl Running {
    fn captured(&mut self) -> &mut Captured {
        self.inner
            .as_mut()
            .unwrap_or_else(|| panic!("harness: the child was already finished or killed"))
    }

    /// The child's process id (also its process group id).
    pub fn id(&mut self) -> u32 {
        self.captured().child.id()
    }

    /// The command line, for messages.
    pub fn program(&mut self) -> String {
        self.captured().program.clone()
    }

    /// Everything written to stdout and stderr so far (lossy UTF-8).
    pub fn output_so_far(&mut self) -> (String, String) {
        let (o, e) = self.captured().snapshot();
        (
            String::from_utf8_lossy(&o).into_owned(),
            String::from_utf8_lossy(&e).into_owned(),
        )
    }

    /// Whether the child has exited (its status is kept for `finish`).
    pub fn has_exited(&mut self) -> bool {
        matches!(self.captured().child.try_wait(), Ok(Some(_)))
    }

    /// Wait until stdout or stderr contains `needle`. Panics, killing the child's group, if the
    /// deadline passes or the child exits without having written it.
    pub fn wait_for_output(&mut self, needle: &str, deadline: Duration) {
        let deadline = deadline::scaled(deadline);
        let until = Instant::now() + deadline;
        loop {
            let exited = self.has_exited();
            if exited {
                // Let the pumps collect the last bytes before deciding.
                self.captured().pipes_closed(Instant::now() + DRAIN_GRACE);
            }
            let (o, e) = self.output_so_far();
            if o.contains(needle) || e.contains(needle) {
                return;
            }
            if exited || Instant::now() >= until {
                let why = if exited {
                    "exited".to_string()
                } else {
                    format!("was still running after {deadline:?}")
                };
                let program = self.program();
                let out = self.kill();
                panic!(
                    "harness: {program} {why} without writing {needle:?}.\n{}",
                    describe(&out)
                );
            }
            thread::sleep(POLL);
        }
    }

    /// Wait for the child to exit on its own and return its output. Panics, killing its group,
    /// if it (or a helper holding its output) is still running after `deadline`.
    pub fn finish(mut self, deadline: Duration) -> Output {
        let mut c = self
            .inner
            .take()
            .unwrap_or_else(|| panic!("harness: the child was already finished or killed"));
        c.finish_or_panic(deadline)
    }

    /// Kill the child's process group now (SIGKILL) and return what it wrote.
    pub fn kill(&mut self) -> Output {
        let mut c = self
            .inner
            .take()
            .unwrap_or_else(|| panic!("harness: the child was already finished or killed"));
        kill_group(&mut c.child);
        match c.wait_until(Instant::now()) {
            Ok(out) | Err(out) => out,
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if let Some(c) = self.inner.as_mut() {
            kill_group(&mut c.child);
            let _ = c.child.wait();
        }
    }
}

// The one launch builder of the integration tests: every test that starts `orchestrator launch`
// starts it from here (and adds its own flags), so a flag every launch needs is added once.

/// `orchestrator launch SOURCE --team TEAM --out OUT --quiet`.
pub fn launch(team: &str, out: &Path, source: &[&str]) -> Command {
    let mut c = launch_loud(team, out, source);
    c.arg("--quiet");
    c
}

/// `orchestrator launch SOURCE --team TEAM --out OUT`, for a test that reads what `launch`
/// prints (the command lines of a `--no-spawn` team, the summary).
pub fn launch_loud(team: &str, out: &Path, source: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.arg("launch")
        .args(source)
        .arg("--team")
        .arg(team)
        .arg("--out")
        .arg(out);
    c
}

/// `orchestrator simulate SOURCE --out OUT --quiet`.
pub fn simulate(out: &Path, source: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.arg("simulate")
        .args(source)
        .arg("--out")
        .arg(out)
        .arg("--quiet");
    c
}

/// A readable account of a finished process (exit status, stdout, stderr) for assertion
/// messages.
pub fn describe(out: &Output) -> String {
    format!(
        "status: {}\n--- stdout ---\n{}\n--- stderr ---\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Write `text` to `dir/name` and return the path.
pub fn write_text(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text)
        .unwrap_or_else(|e| panic!("harness: cannot write {}: {e}", path.display()));
    path
}

/// Serialise a scenario to TOML (the `toml` crate, as the tools read it).
pub fn scenario_toml(file: &ScenarioFile) -> String {
    toml::to_string(file)
        .unwrap_or_else(|e| panic!("harness: cannot serialise scenario `{}`: {e}", file.name))
}

/// Write a scenario as TOML to `dir/name` (`name` is the file name, e.g. `dup.toml`) and return
/// the path.
pub fn write_scenario(dir: &Path, name: &str, file: &ScenarioFile) -> PathBuf {
    write_text(dir, name, &scenario_toml(file))
}

/// The paper's 40-agent scenario (`cdm_scenario::paper40()`): 3 primary leaders (ids 1-3,
/// with goals), 3 secondary leaders (ids 4-6), 34 followers (ids 7-40).
pub fn paper40() -> ScenarioFile {
    cdm_scenario::paper40()
}

/// paper40 inside a geofence, with a box ("tower") and a vertical cylinder ("mast") well aside
/// of its path: SAFE, and every airspace table has something in it.
pub fn fenced_paper40() -> ScenarioFile {
    use cdm_model::airspace::Shape;
    use cdm_scenario::{GeofenceSpec, ObstacleSpec};
    let mut f = paper40();
    f.geofence = Some(GeofenceSpec {
        polygon: vec![
            [-400.0, -300.0],
            [600.0, -300.0],
            [600.0, 700.0],
            [-400.0, 700.0],
        ],
        min_z_m: 400.0,
        max_z_m: 1400.0,
    });
    let tower = Shape::Box {
        min: [450.0, -250.0, 400.0],
        max: [550.0, -150.0, 1300.0],
    };
    let mast = Shape::Cylinder {
        center: [-300.0, 600.0],
        radius_m: 30.0,
        min_z_m: 400.0,
        max_z_m: 1000.0,
    };
    for (name, shape) in [("tower", tower), ("mast", mast)] {
        f.obstacles.push(ObstacleSpec {
            name: name.into(),
            shape,
        });
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sh(script: &str) -> Command {
        let mut c = Command::new("sh");
        c.arg("-c").arg(script);
        c
    }

    #[test]
    fn run_captures_status_and_output() {
        let out = run(
            &mut sh("echo out; echo err >&2; exit 3"),
            Duration::from_secs(30),
        );
        assert_eq!(out.status.code(), Some(3), "{}", describe(&out));
        assert_eq!(out.stdout, b"out\n");
        assert_eq!(out.stderr, b"err\n");
    }

    #[test]
    #[should_panic(expected = "did not finish within")]
    fn run_kills_a_child_past_its_deadline() {
        run(&mut sh("sleep 30"), Duration::from_millis(200));
    }

    #[test]
    #[should_panic(expected = "did not finish within")]
    fn run_kills_a_helper_left_holding_the_output() {
        run(
            &mut sh("sleep 30 & echo started"),
            Duration::from_millis(300),
        );
    }

    #[test]
    fn dropping_a_spawned_child_kills_it() {
        let mut child = spawn(&mut sh("echo ready; sleep 30"));
        child.wait_for_output("ready", Duration::from_secs(30));
        let pid = libc::pid_t::try_from(child.id()).expect("pid fits pid_t");
        drop(child);
        // SAFETY: signal 0 only checks whether the process exists.
        let alive = unsafe { libc::kill(pid, 0) } == 0;
        assert!(!alive, "process {pid} survived its guard");
    }

    #[test]
    #[should_panic(expected = "exited without writing")]
    fn waiting_for_output_a_child_never_writes_fails() {
        spawn(&mut sh("echo something else")).wait_for_output("ready", Duration::from_secs(30));
    }

    #[test]
    fn finish_returns_the_output_of_a_spawned_child() {
        let out = spawn(&mut sh("echo done")).finish(Duration::from_secs(30));
        assert!(out.status.success(), "{}", describe(&out));
        assert_eq!(out.stdout, b"done\n");
    }

    #[test]
    fn team_names_are_unique_short_and_plain() {
        let a = unique_team("a tag/with:odd chars and a very long tail that goes on and on");
        let b = unique_team("a tag/with:odd chars and a very long tail that goes on and on");
        assert_ne!(a, b);
        for t in [&a, &b] {
            assert!(t.len() <= MAX_TEAM_LEN, "{t} is too long");
            assert!(
                t.chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-'),
                "{t} has other characters"
            );
            assert!(t.starts_with(&format!("t{}_", std::process::id())), "{t}");
        }
    }

    #[test]
    fn temp_dir_is_removed_on_drop() {
        let dir = TempDir::new();
        let path = dir.path().to_path_buf();
        write_text(&path, "x.toml", "x = 1\n");
        assert!(path.join("x.toml").is_file());
        drop(dir);
        assert!(!path.exists(), "{} survived its guard", path.display());
    }

    #[test]
    fn paper40_round_trips_through_a_written_file() {
        let dir = TempDir::new();
        let path = write_scenario(dir.path(), "paper40.toml", &paper40());
        let text = std::fs::read_to_string(&path).expect("read back");
        let back: ScenarioFile = toml::from_str(&text).expect("parse back");
        assert_eq!(back, paper40());
    }
}
