//! Shared harness for the workspace's integration tests: the real binaries, built fresh and of
//! the same profile as the test; a temporary directory and a unique team name per test; running
//! a process under a watchdog deadline so that no test can hang; writing scenario files.
//!
//! Every child is started in its own process group and killed as a group (SIGKILL), so that a
//! process that spawned helpers (the orchestrator starts agents) leaves nothing behind when a
//! deadline passes or a guard is dropped.
//!
//! This is test support: it panics, with a message naming the command, file or deadline at
//! fault, instead of returning errors.

use std::ffi::OsStr;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread;
use std::time::{Duration, Instant};

use common::scenario::ScenarioFile;

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

/// The cargo arguments that select the profile whose output directory is `dir_name`
/// (`debug` is the `dev` profile; any other directory is named after its profile).
fn profile_args(dir_name: &str) -> Vec<String> {
    match dir_name {
        "debug" => vec!["--profile".into(), "dev".into()],
        "release" => vec!["--release".into()],
        other => vec!["--profile".into(), other.into()],
    }
}

/// Build every binary of the workspace once per test process, with the running test's profile
/// and target directory, so that `bin` never returns a stale binary.
fn ensure_built() {
    static BUILT: OnceLock<()> = OnceLock::new();
    BUILT.get_or_init(|| {
        let dir = profile_dir();
        let profile = dir
            .file_name()
            .and_then(OsStr::to_str)
            .unwrap_or_else(|| panic!("harness: profile directory {} has no name", dir.display()))
            .to_string();
        let target_dir = dir.parent().unwrap_or_else(|| {
            panic!("harness: profile directory {} has no parent", dir.display())
        });
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.toml");
        let mut cmd = Command::new(&cargo);
        cmd.arg("build")
            .arg("--bins")
            .arg("--workspace")
            .args(profile_args(&profile))
            .arg("--manifest-path")
            .arg(&manifest)
            .arg("--target-dir")
            .arg(target_dir)
            .stdin(Stdio::null());
        // Cargo's own output goes to the test's stderr (shown on failure or with --nocapture).
        let status = cmd.status().unwrap_or_else(|e| {
            panic!(
                "harness: cannot start `{}` to build the workspace binaries: {e}",
                cargo.to_string_lossy()
            )
        });
        assert!(
            status.success(),
            "harness: building the workspace binaries failed ({status}): {cmd:?}"
        );
    });
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

    /// The directory (absolute).
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

/// Kill a child's whole process group (it is its group's leader: see `prepare`).
fn kill_group(child: &mut Child) {
    if let Ok(pid) = libc::pid_t::try_from(child.id()) {
        // SAFETY: kill(2) with a negative pid signals a process group; no memory is involved.
        // The group id is the child's pid, which stays reserved until we reap the child.
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

/// Start a thread that appends everything `src` yields to `buf` and signals `done` at EOF.
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
    eof: [Receiver<()>; 2],
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
            program,
        }
    }

    fn snapshot(&self) -> (Vec<u8>, Vec<u8>) {
        let get = |b: &Arc<Mutex<Vec<u8>>>| b.lock().unwrap_or_else(|p| p.into_inner()).clone();
        (get(&self.stdout), get(&self.stderr))
    }

    /// Wait for exit and for both pipes to close, until `until`. On time-out the group is killed
    /// and `Err` carries what was collected so far.
    fn wait_until(&mut self, until: Instant) -> Result<Output, Output> {
        let status: Option<ExitStatus> = loop {
            match self.child.try_wait() {
                Ok(Some(s)) => break Some(s),
                Ok(None) if Instant::now() >= until => break None,
                Ok(None) => thread::sleep(POLL),
                Err(e) => panic!("harness: waiting for {}: {e}", self.program),
            }
        };
        // A helper the child left behind may still hold the pipes open: give them until the
        // deadline too, then kill the group.
        let mut closed = status.is_some();
        for rx in &self.eof {
            if closed {
                let left = until.saturating_duration_since(Instant::now());
                closed = rx.recv_timeout(left).is_ok();
            }
        }
        if !closed {
            kill_group(&mut self.child);
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
    let mut c = Captured::start(cmd);
    match c.wait_until(Instant::now() + deadline) {
        Ok(out) => out,
        Err(out) => panic!(
            "harness: {} did not finish within {deadline:?}; killed.\n{}",
            c.program,
            describe(&out)
        ),
    }
}

/// Start a command in the background (stdin null, output captured continuously). The returned
/// guard kills the child's process group with SIGKILL when dropped, so a failing test leaves no
/// process behind.
pub fn spawn(cmd: &mut Command) -> Running {
    Running {
        inner: Some(Captured::start(cmd)),
    }
}

/// A background child started by `spawn`; killed (with its process group) on drop.
pub struct Running {
    inner: Option<Captured>,
}

impl Running {
    fn captured(&self) -> &Captured {
        self.inner
            .as_ref()
            .unwrap_or_else(|| panic!("harness: child already finished"))
    }

    /// The child's process id (also its process group id).
    pub fn id(&self) -> u32 {
        self.captured().child.id()
    }

    /// The command line, for messages.
    pub fn program(&self) -> &str {
        &self.captured().program
    }

    /// Everything written to stdout and stderr so far (lossy UTF-8).
    pub fn output_so_far(&self) -> (String, String) {
        let (o, e) = self.captured().snapshot();
        (
            String::from_utf8_lossy(&o).into_owned(),
            String::from_utf8_lossy(&e).into_owned(),
        )
    }

    /// Whether the child has exited (its status is kept for `finish`).
    pub fn has_exited(&mut self) -> bool {
        match self.inner.as_mut() {
            Some(c) => matches!(c.child.try_wait(), Ok(Some(_))),
            None => true,
        }
    }

    /// Wait until stdout or stderr contains `needle`; panics (killing the child) if the deadline
    /// passes or the child exits first without having written it.
    pub fn wait_for_output(&mut self, needle: &str, deadline: Duration) {
        let until = Instant::now() + deadline;
        loop {
            let (o, e) = self.output_so_far();
            if o.contains(needle) || e.contains(needle) {
                return;
            }
            let exited = self.has_exited();
            if exited || Instant::now() >= until {
                let why = if exited {
                    "exited".to_string()
                } else {
                    format!("was still running after {deadline:?}")
                };
                let program = self.program().to_string();
                let out = self.kill();
                panic!(
                    "harness: {program} {why} without writing {needle:?}.\n{}",
                    describe(&out)
                );
            }
            thread::sleep(POLL);
        }
    }

    /// Wait for the child to exit on its own and return its output; panics (killing its group)
    /// if it is still running after `deadline`.
    pub fn finish(mut self, deadline: Duration) -> Output {
        let mut c = self
            .inner
            .take()
            .unwrap_or_else(|| panic!("harness: child already finished"));
        match c.wait_until(Instant::now() + deadline) {
            Ok(out) => out,
            Err(out) => panic!(
                "harness: {} did not finish within {deadline:?}; killed.\n{}",
                c.program,
                describe(&out)
            ),
        }
    }

    /// Kill the child's process group now (SIGKILL) and return what it wrote.
    pub fn kill(&mut self) -> Output {
        let mut c = self
            .inner
            .take()
            .unwrap_or_else(|| panic!("harness: child already finished"));
        kill_group(&mut c.child);
        // The pipes close once the group is dead; a short grace period for the pumps.
        match c.wait_until(Instant::now() + Duration::from_secs(5)) {
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

/// The paper's 40-agent scenario (`common::scenario::paper40()`): 3 primary leaders (ids 1-3,
/// with goals), 3 secondary leaders (ids 4-6), 34 followers (ids 7-40).
pub fn paper40() -> ScenarioFile {
    common::scenario::paper40()
}
