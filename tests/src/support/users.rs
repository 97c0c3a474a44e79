//! Users created for a test (`useradd`; removed with their files at the end), who run the
//! binaries with `setpriv`. Needs root (CI runs as root); a test is skipped with a note
//! elsewhere.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::{bin, describe, run};

use super::{files_under, SHM};

/// `useradd`, `id` and `userdel` take well under a second; the rest is slack.
const DEADLINE: Duration = crate::deadline::REFUSE;

/// A user created for one test, removed (with every file it owns in /dev/shm) when dropped.
pub struct TestUser {
    pub name: String,
    pub uid: u32,
    pub gid: u32,
}

impl TestUser {
    /// Creates a user; `None` (the test is skipped) when this process may not.
    pub fn create(tag: &str) -> Option<Self> {
        // SAFETY: geteuid(2) cannot fail.
        if unsafe { libc::geteuid() } != 0 {
            eprintln!("skipped: creating users needs root");
            return None;
        }
        let name = format!("cdm{tag}{}", std::process::id() % 100_000);
        // useradd takes a lock on /etc/passwd: another test may hold it for a moment.
        let mut created = false;
        for _ in 0..50 {
            let o = run(
                Command::new("useradd").args(["-M", "-N", "-s", "/usr/sbin/nologin", &name]),
                DEADLINE,
            );
            if o.status.success() {
                created = true;
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        assert!(created, "useradd {name} failed");
        let id = |flag: &str| -> u32 {
            let o = run(Command::new("id").args([flag, &name]), DEADLINE);
            String::from_utf8_lossy(&o.stdout)
                .trim()
                .parse()
                .unwrap_or_else(|e| panic!("id {flag} {name}: {e}: {}", describe(&o)))
        };
        Some(TestUser {
            uid: id("-u"),
            gid: id("-g"),
            name,
        })
    }

    /// `program args` run as this user.
    pub fn command(&self, program: &Path) -> Command {
        let mut c = Command::new("setpriv");
        c.arg(format!("--reuid={}", self.uid))
            .arg(format!("--regid={}", self.gid))
            .arg("--clear-groups")
            .arg(program);
        c
    }

    /// The files this user owns directly in /dev/shm.
    pub fn shm_files(&self) -> Vec<(PathBuf, u32)> {
        files_under(Path::new(SHM))
            .into_iter()
            .filter_map(|p| {
                let m = std::fs::symlink_metadata(&p).ok()?;
                (m.uid() == self.uid).then(|| (p, m.mode() & 0o7777))
            })
            .collect()
    }

    pub fn iox2_root(&self) -> PathBuf {
        PathBuf::from(format!("{SHM}/cdm-iceoryx2-{}", self.uid))
    }
}

impl Drop for TestUser {
    fn drop(&mut self) {
        for (p, _) in self.shm_files() {
            if p.is_dir() {
                let _ = std::fs::remove_dir_all(&p);
            } else {
                let _ = std::fs::remove_file(&p);
            }
        }
        let _ = Command::new("userdel").arg(&self.name).output();
    }
}

/// The three binaries copied into `dir` (readable and executable by everyone), so that a test
/// user can run them whatever the permissions of the build directory.
pub fn binaries_for_everyone(dir: &Path) -> PathBuf {
    let bins = dir.join("bin");
    std::fs::create_dir_all(&bins).expect("create bin dir");
    for name in ["orchestrator", "leader", "agent"] {
        let to = bins.join(name);
        std::fs::copy(bin(name), &to).unwrap_or_else(|e| panic!("copy {name}: {e}"));
        std::fs::set_permissions(&to, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    }
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    std::fs::set_permissions(&bins, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    bins.join("orchestrator")
}
