//! A run's `commands.json` read back (written by `simulate --commands` and `launch`): the
//! commands the figures, the bag, the ROS 2 feed and the viewer mark at their switch ticks.

use std::path::{Path, PathBuf};

use crate::audit::CommandSummary;

/// The file's name in a run directory.
pub const COMMANDS_FILE: &str = "commands.json";

/// Why a run's `commands.json` cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum RunCommandsError {
    /// The file exists but cannot be read.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The file is not a list of commands with their outcomes.
    #[error("{}: not a run's command list: {source}", path.display())]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
}

/// Every command of the run in `dir`, in file order (switch tick order); none when the run was
/// not commanded (no file).
pub fn read_commands(dir: &Path) -> Result<Vec<CommandSummary>, RunCommandsError> {
    let path = dir.join(COMMANDS_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(source) => return Err(RunCommandsError::Io { path, source }),
    };
    serde_json::from_str(&text).map_err(|source| RunCommandsError::Json { path, source })
}

/// A command as one line: `goto accepted at tick 2000` or `goto refused at tick 2000: why`.
pub fn describe(c: &CommandSummary) -> String {
    match (&c.why, c.accepted) {
        (_, true) => format!("{} accepted at tick {}", c.command, c.switch_tick),
        (Some(why), false) => format!("{} refused at tick {}: {why}", c.command, c.switch_tick),
        (None, false) => format!("{} refused at tick {}", c.command, c.switch_tick),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_without_commands_has_none_and_a_bad_file_is_named() {
        let dir = std::env::temp_dir().join(format!("cdm-commands-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert!(read_commands(&dir).unwrap().is_empty());
        std::fs::write(
            dir.join(COMMANDS_FILE),
            r#"[{"at_s": 10, "command": "goto", "goals": [[0,0,1],[1,0,1],[0,1,1]],
                "arrived_s": 10, "switch_tick": 1000, "verdict": "UNSAFE", "accepted": false,
                "why": "too quick", "certificate": {"verdict": "UNSAFE"}}]"#,
        )
        .unwrap();
        let c = read_commands(&dir).unwrap();
        assert_eq!(c.len(), 1);
        assert_eq!(describe(&c[0]), "goto refused at tick 1000: too quick");
        std::fs::write(dir.join(COMMANDS_FILE), "{}").unwrap();
        let e = read_commands(&dir).unwrap_err().to_string();
        assert!(e.contains("commands.json"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
