//! The replay's side: a recording read back and checked against the run it claims to be of.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use cdm_records::run_record::RunRecord;
use cdm_runtime::realtime_journal::{Switch, Switched};

use crate::{file_name, Ages, Header, SwitchMsg, AGES_TOPIC, FORMAT, MEMBER_TOPIC, SWITCH_TOPIC};

/// A recording is at most this large (about 1 KB per member-second: days of flight).
const MAX_BYTES: u64 = 1 << 30;

/// A member flies on no state more than this many ticks ahead of its own (it would be that
/// late, far beyond any stale bound).
const MAX_AHEAD: i64 = 1 << 20;

/// Why a recording cannot be replayed: each names the file, and a bad one its first bad record
/// (1-based, counting the file's messages).
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file is missing or cannot be read.
    #[error(transparent)]
    Read(#[from] cdm_files::FileError),
    /// A record is malformed, or belongs to another member, scenario or flight.
    #[error("{path}: record {record}: {reason}")]
    Bad {
        path: PathBuf,
        record: usize,
        reason: String,
    },
}

/// A member's recording as read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub header: Header,
    /// For each tick flown from tick 0, the tick of the state each in-neighbour slot flew on.
    pub used: Vec<[Option<u64>; 3]>,
    /// The switches applied (repaired links, commands), in the order applied.
    pub switches: Vec<Switch>,
    /// The file has no end: the member stopped writing it before the flight ended (a crash, a
    /// kill, a full disk); `used` holds every tick before that.
    pub cut_short: bool,
}

/// Reads member `id`'s recording at `path`, which must be of the scenario with content hash
/// `hash`.
pub fn read(path: &Path, id: u32, hash: u64) -> Result<Recording, RecordingError> {
    let f = cdm_files::open_input(path)?;
    let mut bytes = Vec::new();
    use std::io::Read;
    f.take(MAX_BYTES)
        .read_to_end(&mut bytes)
        .map_err(|e| bad(path, 0, format!("cannot be read: {e}")))?;
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(bad(path, 1, "not MCAP: no MCAP magic at its start".into()));
    }
    let ended = bytes.len() > mcap::MAGIC.len() && bytes.ends_with(mcap::MAGIC);
    let stream =
        mcap::MessageStream::new(&bytes).map_err(|e| bad(path, 1, format!("not MCAP: {e}")))?;
    let mut header: Option<Header> = None;
    let mut parsed = Parsed::default();
    for (k, msg) in stream.enumerate() {
        let record = k + 1;
        let msg = match msg {
            Ok(m) => m,
            // A file without its end was cut short: what came before stands.
            Err(_) if !ended => return finish(path, header, parsed, true),
            Err(e) => return Err(bad(path, record, e.to_string())),
        };
        let topic = msg.channel.topic.as_str();
        match (&header, topic) {
            (None, MEMBER_TOPIC) => {
                let h: Header = serde_json::from_slice(&msg.data)
                    .map_err(|e| bad(path, record, format!("not a recording's header: {e}")))?;
                check_header(&h, id, hash).map_err(|why| bad(path, record, why.to_string()))?;
                header = Some(h);
            }
            (Some(_), AGES_TOPIC) => {
                let a: Ages = serde_json::from_slice(&msg.data)
                    .map_err(|e| bad(path, record, format!("not a batch of ticks: {e}")))?;
                append(&a, id, &mut parsed).map_err(|why| bad(path, record, why.to_string()))?;
            }
            (Some(_), SWITCH_TOPIC) => {
                let s: SwitchMsg = serde_json::from_slice(&msg.data)
                    .map_err(|e| bad(path, record, format!("not a switch: {e}")))?;
                switched(&s, id, &mut parsed).map_err(|why| bad(path, record, why.to_string()))?;
            }
            _ => {
                return Err(bad(
                    path,
                    record,
                    format!("unexpected message on {topic} (the first is the member's header)"),
                ))
            }
        }
    }
    finish(path, header, parsed, !ended)
}

/// What the messages read so far hold.
#[derive(Default)]
struct Parsed {
    used: Vec<[Option<u64>; 3]>,
    switches: Vec<Switch>,
}

/// The recordings of `ids` in the run directory's recording folder `dir`.
pub fn read_dir(
    dir: &Path,
    ids: &[u32],
    hash: u64,
) -> Result<BTreeMap<u32, Recording>, RecordingError> {
    ids.iter()
        .map(|&id| Ok((id, read(&dir.join(file_name(id)), id, hash)?)))
        .collect()
}

fn finish(
    path: &Path,
    header: Option<Header>,
    read: Parsed,
    cut_short: bool,
) -> Result<Recording, RecordingError> {
    let header =
        header.ok_or_else(|| bad(path, 1, "no header: not a member's recording".into()))?;
    Ok(Recording {
        header,
        used: read.used,
        switches: read.switches,
        cut_short,
    })
}

/// What makes a record not one of this member's recording (the reason of
/// [`RecordingError::Bad`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum BadRecord {
    #[error("format {found:?}, expected {expected:?}", expected = FORMAT)]
    Format { found: String },
    #[error("the recording of agent {found}, not of agent {id}")]
    OtherMember { found: u32, id: u32 },
    #[error("of scenario {found}, not of this run's {want}")]
    OtherScenario { found: String, want: String },
    #[error("dt_s {0} is not a period")]
    Period(f64),
    #[error("ticks of agent {found}, not of agent {id}")]
    OtherMembersTicks { found: u32, id: u32 },
    #[error("starts at tick {found}, expected tick {next}")]
    Start { found: u64, next: u64 },
    #[error("{0} ticks in one batch")]
    BatchSize(u64),
    #[error("tick {tick} slot {slot}: age {age} is not in {lowest}..={tick}", lowest = 1 - MAX_AHEAD)]
    Age { tick: u64, slot: usize, age: i64 },
    #[error("tick {tick} slot {slot}: flew on {now:?}, older than the {before:?} before")]
    Older {
        tick: u64,
        slot: usize,
        now: Option<u64>,
        before: Option<u64>,
    },
    #[error("{ages} ages for {ticks} ticks (three per tick, or none for a leader)")]
    AgeCount { ages: u64, ticks: u64 },
    #[error("a switch of agent {found}, not of agent {id}")]
    OtherMembersSwitch { found: u32, id: u32 },
    #[error("a switch at tick {tick}, written after tick {flown} was flown")]
    SwitchAfterItsTick { tick: u64, flown: u64 },
    #[error("a switch at tick {tick}, after one at tick {before}")]
    SwitchOutOfOrder { tick: u64, before: u64 },
    #[error("the repaired link of tick {at} applied at tick {tick}, before it")]
    RepairBeforeItsTick { at: u64, tick: u64 },
}

/// Takes a switch: written before the ticks flown on it, after those of the switches before.
fn switched(s: &SwitchMsg, id: u32, read: &mut Parsed) -> Result<(), BadRecord> {
    if s.member != id {
        return Err(BadRecord::OtherMembersSwitch {
            found: s.member,
            id,
        });
    }
    let sw = s.switch();
    let flown = read.used.len() as u64;
    if sw.tick < flown {
        return Err(BadRecord::SwitchAfterItsTick {
            tick: sw.tick,
            flown: flown - 1,
        });
    }
    if let Some(before) = read.switches.last().filter(|b| b.tick > sw.tick) {
        return Err(BadRecord::SwitchOutOfOrder {
            tick: sw.tick,
            before: before.tick,
        });
    }
    if let Switched::Repair { at, .. } = sw.what {
        if at > sw.tick {
            return Err(BadRecord::RepairBeforeItsTick { at, tick: sw.tick });
        }
    }
    read.switches.push(sw);
    Ok(())
}

/// True when a repaired link applied at `tick` (its slots then name other neighbours).
fn relinked_at(switches: &[Switch], tick: u64) -> bool {
    switches
        .iter()
        .any(|s| s.tick == tick && matches!(s.what, Switched::Repair { .. }))
}

fn check_header(h: &Header, id: u32, hash: u64) -> Result<(), BadRecord> {
    if h.format != FORMAT {
        return Err(BadRecord::Format {
            found: h.format.clone(),
        });
    }
    if h.member != id {
        return Err(BadRecord::OtherMember {
            found: h.member,
            id,
        });
    }
    let want = RunRecord::hash_text(hash);
    if h.scenario_hash != want {
        return Err(BadRecord::OtherScenario {
            found: h.scenario_hash.clone(),
            want,
        });
    }
    if !(h.dt_s.is_finite() && h.dt_s > 0.0) {
        return Err(BadRecord::Period(h.dt_s));
    }
    Ok(())
}

/// Appends a batch's ticks to `read.used` (which holds every tick before it).
fn append(a: &Ages, id: u32, read: &mut Parsed) -> Result<(), BadRecord> {
    let (used, switches) = (&mut read.used, &read.switches);
    if a.member != id {
        return Err(BadRecord::OtherMembersTicks {
            found: a.member,
            id,
        });
    }
    let next = used.len() as u64;
    if a.tick != next {
        return Err(BadRecord::Start {
            found: a.tick,
            next,
        });
    }
    if a.ticks == 0 || a.ticks > 1 << 20 {
        return Err(BadRecord::BatchSize(a.ticks));
    }
    match a.age.len() as u64 {
        0 => used.extend((0..a.ticks).map(|_| [None; 3])),
        n if n == 3 * a.ticks => {
            for (k, ages) in a.age.chunks_exact(3).enumerate() {
                let tick = a.tick + k as u64;
                let mut u = [None; 3];
                for (slot, &age) in ages.iter().enumerate() {
                    // A late member may fly on a state stamped after its own time (age < 0),
                    // never on one of a tick before 0.
                    u[slot] = match age {
                        None => None,
                        Some(age) if age <= tick as i64 && age > -MAX_AHEAD => {
                            Some((tick as i64 - age) as u64)
                        }
                        Some(age) => return Err(BadRecord::Age { tick, slot, age }),
                    };
                }
                // A slot keeps the newest state heard: it never flies on an older one (unless
                // a repaired link gave it another neighbour).
                if let Some(before) = used.last().filter(|_| !relinked_at(switches, tick)) {
                    if let Some(slot) = (0..3).find(|&k| u[k] < before[k]) {
                        return Err(BadRecord::Older {
                            tick,
                            slot,
                            now: u[slot],
                            before: before[slot],
                        });
                    }
                }
                used.push(u);
            }
        }
        ages => {
            return Err(BadRecord::AgeCount {
                ages,
                ticks: a.ticks,
            })
        }
    }
    Ok(())
}

fn bad(path: &Path, record: usize, reason: String) -> RecordingError {
    RecordingError::Bad {
        path: path.to_path_buf(),
        record,
        reason,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::McapJournal;
    use cdm_runtime::realtime_journal::{Flown, Journal};

    fn dir(test: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("cdm-recording-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("temp dir");
        d
    }

    /// 250 ticks at 100 Hz of agent 7, flying on slot 0's state one tick old, slot 1's two
    /// ticks old, slot 2's never heard.
    fn write(path: &Path) -> Vec<[Option<u64>; 3]> {
        let mut j = McapJournal::create(path, (7, false), 0xabc, 0.01).expect("created");
        let mut want = Vec::new();
        for tick in 0..250u64 {
            let used = [tick.checked_sub(1), tick.checked_sub(2), None];
            j.flown(&Flown { tick, used });
            want.push(used);
        }
        want
    }

    #[test]
    fn a_recording_reads_back_as_written() {
        let d = dir("back");
        let p = d.join("7.mcap");
        let want = write(&p);
        let r = read(&p, 7, 0xabc).expect("read");
        assert_eq!(r.used, want);
        assert!(!r.cut_short);
        assert_eq!(r.header.member, 7);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn switches_read_back_and_a_repaired_slot_may_name_an_older_state() {
        use cdm_runtime::realtime_journal::{Switch, Switched};
        let d = dir("switch");
        let p = d.join("7.mcap");
        let relink = Switch {
            tick: 150,
            what: Switched::Repair {
                at: 140,
                in_neighbors: Some([1, 3, 8]),
            },
        };
        let command = Switch {
            tick: 160,
            what: Switched::Command { seq: 1, at: 200 },
        };
        {
            let mut j = McapJournal::create(&p, (7, false), 0xabc, 0.01).expect("created");
            for tick in 0..250u64 {
                for s in [relink, command].iter().filter(|s| s.tick == tick) {
                    j.switched(s);
                }
                // From the repair on, slot 1 is a new neighbour, heard from far behind.
                let used = match tick {
                    150.. => [tick.checked_sub(1), tick.checked_sub(40), None],
                    _ => [tick.checked_sub(1), tick.checked_sub(2), None],
                };
                j.flown(&Flown { tick, used });
            }
        }
        let r = read(&p, 7, 0xabc).expect("read");
        assert_eq!(r.switches, [relink, command]);
        assert_eq!(r.used[150], [Some(149), Some(110), None]);
        // A switch claimed for a tick already flown is a tampered file.
        let mut bytes = std::fs::read(&p).expect("written");
        let at = bytes
            .windows(10)
            .position(|w| w == b"\"tick\":160")
            .expect("the command's switch");
        bytes[at + 7..at + 10].copy_from_slice(b" 10");
        std::fs::write(&p, &bytes).expect("edited");
        let e = read(&p, 7, 0xabc).unwrap_err().to_string();
        assert!(
            e.contains("a switch at tick 10, written after tick 99 was flown"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_recording_cut_short_reads_up_to_where_it_ends() {
        let d = dir("cut");
        let p = d.join("7.mcap");
        let want = write(&p);
        let bytes = std::fs::read(&p).expect("written");
        // Cut inside the third batch's message (after the header and two batches).
        let mut cut = bytes.clone();
        let third = bytes
            .windows(10)
            .position(|w| w == b"\"tick\":200")
            .expect("third batch");
        cut.truncate(third + 40);
        std::fs::write(&p, &cut).expect("cut");
        let r = read(&p, 7, 0xabc).expect("read");
        assert!(r.cut_short);
        assert_eq!(r.used, want[..200]);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_foreign_or_tampered_recording_names_its_first_bad_record() {
        let d = dir("bad");
        let p = d.join("7.mcap");
        write(&p);
        let e = read(&p, 7, 0xabd).unwrap_err().to_string();
        assert!(e.contains("7.mcap: record 1: of scenario"), "{e}");
        let e = read(&p, 8, 0xabc).unwrap_err().to_string();
        assert!(e.contains("record 1: the recording of agent 7"), "{e}");
        // An age edited to an older state than the one before, in the second batch (record 3).
        let mut bytes = std::fs::read(&p).expect("written");
        let at = bytes
            .windows(10)
            .position(|w| w == b"\"tick\":100")
            .expect("second batch");
        let age = at
            + bytes[at..]
                .windows(7)
                .position(|w| w == b"\"age\":[")
                .expect("ages")
            + 7;
        bytes[age] = b'9';
        std::fs::write(&p, &bytes).expect("edited");
        let e = read(&p, 7, 0xabc).unwrap_err().to_string();
        assert!(
            e.contains("record 3: tick 100 slot 0: flew on Some(91)"),
            "{e}"
        );
        std::fs::write(&p, b"not an mcap file at all").expect("foreign");
        let e = read(&p, 7, 0xabc).unwrap_err().to_string();
        assert!(e.contains("record 1: not MCAP"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
