//! Which member a parse error is about. The parsers report a line and column; in a file of a
//! thousand `[[agents]]` a person also needs the member's id (or its index when the id itself is
//! missing or malformed). Only run on the error path.

use serde::Deserialize;

use super::AgentSpec;

/// The member at fault: its position in `agents` and its id when it has a readable one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Who {
    pub index: usize,
    pub id: Option<i64>,
}

impl std::fmt::Display for Who {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.id {
            Some(id) => write!(f, "agent {id} (agents[{}])", self.index),
            None => write!(f, "agent agents[{}] (no readable id)", self.index),
        }
    }
}

/// A parse error's text with the member in front, when one is known.
pub fn named(who: Option<Who>, error: String) -> String {
    match who {
        Some(w) => format!("{w}: {error}"),
        None => error,
    }
}

/// The first member of a JSON scenario that does not deserialise.
pub fn json_agent(text: &str) -> Option<Who> {
    let doc: serde_json::Value = serde_json::from_str(text).ok()?;
    doc.get("agents")?
        .as_array()?
        .iter()
        .enumerate()
        .find(|(_, a)| AgentSpec::deserialize(*a).is_err())
        .map(|(index, a)| Who {
            index,
            id: a.get("id").and_then(serde_json::Value::as_i64),
        })
}

/// The member of a TOML scenario that an error is about: the first one that does not
/// deserialise when the document itself parses, or else the `[[agents]]` section holding the
/// error's byte offset.
pub fn toml_agent(text: &str, offset: Option<usize>) -> Option<Who> {
    match toml::from_str::<toml::Table>(text) {
        Ok(doc) => doc
            .get("agents")?
            .as_array()?
            .iter()
            .enumerate()
            .find(|(_, a)| AgentSpec::deserialize((*a).clone()).is_err())
            .map(|(index, a)| Who {
                index,
                id: a.get("id").and_then(toml::Value::as_integer),
            }),
        Err(_) => section_at(text, offset?),
    }
}

/// The `[[agents]]` section that contains byte `offset`, and the `id = N` line in it.
fn section_at(text: &str, offset: usize) -> Option<Who> {
    let mut who: Option<Who> = None;
    let mut sections = 0usize;
    let mut at = 0usize;
    for line in text.split_inclusive('\n') {
        if at > offset && who.is_some_and(|w| w.id.is_some()) {
            break;
        }
        let t = line.trim();
        if t.starts_with('[') {
            if at > offset {
                break;
            }
            let agents =
                t.starts_with("[[") && t.trim_start_matches('[').trim_start().starts_with("agents");
            who = agents.then_some(Who {
                index: sections,
                id: None,
            });
            sections += usize::from(agents);
        } else if let Some(w) = who.as_mut() {
            if let Some(v) = t.strip_prefix("id").map(str::trim_start) {
                if let Some(v) = v.strip_prefix('=') {
                    w.id = v.split('#').next().and_then(|n| n.trim().parse().ok());
                }
            }
        }
        at += line.len();
    }
    who
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_syntax_error_is_placed_in_its_section() {
        let text = "name = \"x\"\n[[agents]]\nid = 4\nrole = \"follower\"\n[[agents]]\nid = 9\nposition = [1, 2,,]\n";
        let off = text.find(",,").unwrap();
        assert_eq!(
            section_at(text, off),
            Some(Who {
                index: 1,
                id: Some(9)
            })
        );
        assert_eq!(section_at(text, 3), None);
    }
}
