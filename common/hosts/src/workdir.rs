//! The daemon's private work directory (`$TMPDIR/cdm-host-<team>-<pid>`, mode 0700), where its
//! members read the team's scenario. A daemon removes it when it exits; one killed with SIGKILL
//! cannot, so each daemon first removes the work directories of dead daemons owned by its user.

use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};

const PREFIX: &str = "cdm-host-";

/// The process id a work directory's name ends with, when it is one of ours.
fn owner_pid(name: &str) -> Option<u32> {
    let rest = name.strip_prefix(PREFIX)?;
    let (team, pid) = rest.rsplit_once('-')?;
    if team.is_empty() {
        return None;
    }
    pid.parse().ok()
}

/// True when `pid` names no running process (kill(2) with signal 0: ESRCH).
fn is_dead(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: kill(2) with signal 0 only checks that the process exists; no pointers.
    let rc = unsafe { libc::kill(pid, 0) };
    rc != 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
}

/// Removes the work directories under `tmp` left by dead daemons of this user (real
/// directories only, never through a symlink); returns how many.
fn sweep(tmp: &Path, dead: impl Fn(u32) -> bool) -> usize {
    // SAFETY: geteuid takes no arguments and cannot fail.
    let me = unsafe { libc::geteuid() };
    let Ok(entries) = std::fs::read_dir(tmp) else {
        return 0;
    };
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name.to_str().and_then(owner_pid) else {
            continue;
        };
        let ours = std::fs::symlink_metadata(e.path()).is_ok_and(|m| m.is_dir() && m.uid() == me);
        if ours && dead(pid) && std::fs::remove_dir_all(e.path()).is_ok() {
            tracing::info!(dir = %e.path().display(), "removed a dead daemon's work directory");
            removed += 1;
        }
    }
    removed
}

/// Removes the work directories of this user's dead daemons (a daemon does it as it starts,
/// before it joins: even one that is refused or finds no orchestrator cleans up).
pub fn sweep_dead() -> usize {
    sweep(&std::env::temp_dir(), is_dead)
}

/// The daemon's work directory cannot be made (the team's fault on this host: exit 3).
#[derive(Debug, thiserror::Error)]
#[error("cannot create {}: {source}", dir.display())]
pub struct WorkDirError {
    dir: PathBuf,
    #[source]
    source: std::io::Error,
}

/// Creates this daemon's work directory (readable by this user only).
pub fn create(team: &str) -> Result<PathBuf, WorkDirError> {
    let tmp = std::env::temp_dir();
    let dir = tmp.join(format!("{PREFIX}{team}-{}", std::process::id()));
    match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
        Ok(()) => Ok(dir),
        Err(source) => Err(WorkDirError { dir, source }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_of_work_directories() {
        assert_eq!(owner_pid("cdm-host-demo-1234"), Some(1234));
        assert_eq!(owner_pid("cdm-host-t1_kdaemon_3-16564"), Some(16564));
        assert_eq!(owner_pid("cdm-host-a-b-77"), Some(77));
        assert_eq!(owner_pid("cdm-host--77"), None);
        assert_eq!(owner_pid("cdm-host-demo"), None);
        assert_eq!(owner_pid("cdm-host-demo-x1"), None);
        assert_eq!(owner_pid("other-demo-12"), None);
    }

    #[test]
    fn only_dead_daemons_directories_are_swept() {
        let tmp = std::env::temp_dir().join(format!("cdm-sweep-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        for d in ["cdm-host-a-10", "cdm-host-b-11", "unrelated-12"] {
            std::fs::create_dir_all(tmp.join(d).join("inner")).unwrap();
        }
        std::fs::write(tmp.join("cdm-host-file-10"), b"not a directory").unwrap();
        let removed = sweep(&tmp, |pid| pid != 11);
        let mut left: Vec<String> = std::fs::read_dir(&tmp)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        std::fs::remove_dir_all(&tmp).unwrap();
        assert_eq!(removed, 1);
        assert_eq!(left, ["cdm-host-b-11", "cdm-host-file-10", "unrelated-12"]);
    }

    #[test]
    fn this_process_is_alive() {
        assert!(!is_dead(std::process::id()));
    }
}
