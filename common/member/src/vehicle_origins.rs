//! `--vehicle-origins FILE`: each vehicle's own NED origin. PX4's multi-vehicle SITL (and any
//! fleet whose vehicles start their EKF where they stand) gives every vehicle its own local
//! frame, centred on its spawn point; the member must subtract that vehicle's origin, not one
//! shared by the team. The file lists, for every member of the scenario, the scenario point
//! (ENU, m) of its vehicle's NED origin:
//!
//! ```toml
//! [[vehicle]]
//! id = 1
//! origin = [0.0, 0.0, 0.0]
//! ```
//!
//! Errors name the file, the line and the member.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use cdm_math::Vec3;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct OriginsFile {
    vehicle: Vec<toml::Spanned<Entry>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    id: u32,
    origin: [f64; 3],
}

/// Why the file was refused (every variant names the file; those about one entry its line and
/// member).
#[derive(Debug, thiserror::Error)]
pub enum OriginsError {
    #[error("--vehicle-origins {path}: cannot read it")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("--vehicle-origins {path}: {source}")]
    Parse {
        path: PathBuf,
        #[source]
        source: toml::de::Error,
    },
    #[error("--vehicle-origins {path} line {line}: agent {id} is not in the scenario")]
    Unknown { path: PathBuf, line: usize, id: u32 },
    #[error("--vehicle-origins {path} line {line}: agent {id} is listed twice")]
    Duplicate { path: PathBuf, line: usize, id: u32 },
    #[error("--vehicle-origins {path} line {line}: agent {id}: origin {origin:?} is not three finite numbers (m)")]
    NonFinite {
        path: PathBuf,
        line: usize,
        id: u32,
        origin: [f64; 3],
    },
    #[error("--vehicle-origins {path}: agent {id} has no [[vehicle]] entry (every member needs its vehicle's origin)")]
    Missing { path: PathBuf, id: u32 },
}

/// Every member's vehicle origin, by member id.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleOrigins(BTreeMap<u32, Vec3>);

impl VehicleOrigins {
    /// Reads `path` and checks it against the scenario's members `ids`.
    pub fn load(path: &Path, ids: &[u32]) -> Result<Self, OriginsError> {
        let text = std::fs::read_to_string(path).map_err(|source| OriginsError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path, ids)
    }

    /// The file's `text` (read from `path`, named in errors), checked against `ids`.
    pub fn parse(text: &str, path: &Path, ids: &[u32]) -> Result<Self, OriginsError> {
        let file: OriginsFile = toml::from_str(text).map_err(|source| OriginsError::Parse {
            path: path.to_owned(),
            source,
        })?;
        let mut by_id = BTreeMap::new();
        for e in &file.vehicle {
            // 1-based line of the entry's table.
            let line = text[..e.span().start.min(text.len())].matches('\n').count() + 1;
            let (id, origin) = (e.get_ref().id, e.get_ref().origin);
            let path = path.to_owned();
            if !ids.contains(&id) {
                return Err(OriginsError::Unknown { path, line, id });
            }
            if !origin.iter().all(|v| v.is_finite()) {
                return Err(OriginsError::NonFinite {
                    path,
                    line,
                    id,
                    origin,
                });
            }
            if by_id
                .insert(id, Vec3::new(origin[0], origin[1], origin[2]))
                .is_some()
            {
                return Err(OriginsError::Duplicate { path, line, id });
            }
        }
        if let Some(&id) = ids.iter().find(|id| !by_id.contains_key(id)) {
            let path = path.to_owned();
            return Err(OriginsError::Missing { path, id });
        }
        Ok(VehicleOrigins(by_id))
    }

    /// Member `id`'s vehicle origin (every member has one once loaded).
    pub fn of(&self, id: u32) -> Option<Vec3> {
        self.0.get(&id).copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<VehicleOrigins, OriginsError> {
        VehicleOrigins::parse(text, Path::new("o.toml"), &[1, 2])
    }

    #[test]
    fn every_member_gets_its_origin() {
        let o = parse(
            "[[vehicle]]\nid = 1\norigin = [0, 0, 0]\n\n[[vehicle]]\nid = 2\norigin = [3.5, -1, 0]\n",
        );
        let o = o.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(o.of(2), Some(Vec3::new(3.5, -1.0, 0.0)));
        assert_eq!(o.of(3), None);
    }

    #[test]
    fn bad_files_name_the_file_the_line_and_the_member() {
        let one = "[[vehicle]]\nid = 1\norigin = [0, 0, 0]\n";
        let cases = [
            (
                format!("{one}[[vehicle]]\nid = 7\norigin = [0, 0, 0]\n"),
                "o.toml line 4: agent 7 is not in the scenario",
            ),
            (
                format!("{one}[[vehicle]]\nid = 1\norigin = [0, 0, 0]\n"),
                "o.toml line 4: agent 1 is listed twice",
            ),
            (
                format!("{one}[[vehicle]]\nid = 2\norigin = [0, nan, 0]\n"),
                "o.toml line 4: agent 2: origin",
            ),
            (one.to_string(), "o.toml: agent 2 has no [[vehicle]] entry"),
            (
                format!("{one}[[vehicle]]\nid = 2\norigin = [0, 0]\n"),
                "line 6",
            ),
            (
                "[[vehicle]]\nid = 2\norign = [0, 0, 0]\n".to_string(),
                "unknown field `orign`",
            ),
        ];
        for (text, want) in cases {
            let e = parse(&text).unwrap_err().to_string();
            assert!(e.contains(want), "{want:?} not in {e:?}");
            assert!(e.starts_with("--vehicle-origins o.toml"), "{e}");
        }
    }
}
