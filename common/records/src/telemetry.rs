//! telemetry.csv: one row per member per tick, ordered by tick then id. Numbers use Rust's
//! shortest round-trip formatting, so equal values give equal bytes (the determinism contract
//! between `simulate` and `launch` is checked on these bytes).

use std::io::{self, Write};

use cdm_math::{Real, Vec3};
use cdm_model::formation::Role;

/// The header line.
pub const HEADER: &str = "tick,t,id,role,x,y,z,vx,vy,vz,x_ht,y_ht,z_ht";

/// The file format of a run's telemetry (`--telemetry`). CSV is the default: it is what the
/// byte-identical determinism tests compare. Parquet (crate `cdm-parquet`) holds the same
/// columns and values in a fraction of the bytes. Mcap is telemetry.csv and, beside it, the run
/// as a ROS 2 bag written during the run (crate `cdm-rosbag`, directory `rosbag2/`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TelemetryFormat {
    #[default]
    Csv,
    Parquet,
    Mcap,
}

impl TelemetryFormat {
    /// The file name in the run directory (of the table: a bag is beside telemetry.csv).
    pub fn file_name(self) -> &'static str {
        match self {
            TelemetryFormat::Csv | TelemetryFormat::Mcap => "telemetry.csv",
            TelemetryFormat::Parquet => "telemetry.parquet",
        }
    }
}

/// Where `simulate` and `launch` stream telemetry, whatever the format.
pub trait TelemetrySink {
    /// Whether a tick is kept (`--every`).
    fn keeps(&self, tick: u64) -> bool;
    /// Write one tick's rows (sorted by id by the caller).
    fn write_tick(&mut self, rows: &[Row]) -> io::Result<()>;
    /// Push complete ticks towards the file where the format allows it (CSV: every tick so far;
    /// Parquet: whole row groups only, the file is readable once finished).
    fn flush(&mut self) -> io::Result<()>;
    /// End the file (Parquet writes its footer). Called once at the end of a run; a writer that
    /// is dropped unfinished finishes itself, best effort.
    fn finish(&mut self) -> io::Result<()>;
}

/// One member at one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    pub tick: u64,
    pub t_s: Real,
    pub id: u32,
    pub role: Role,
    pub r: Vec3,
    pub v: Vec3,
    pub ht: Vec3,
}

/// Where telemetry goes: a writer that can drop everything after a given length, so a failed
/// write (a full disk) leaves the file ending on a whole tick.
pub trait Rewind: Write {
    /// Truncate to `len` bytes and continue writing there.
    fn rewind_to(&mut self, len: u64) -> io::Result<()>;
}

impl Rewind for Vec<u8> {
    fn rewind_to(&mut self, len: u64) -> io::Result<()> {
        self.truncate(usize::try_from(len).unwrap_or(usize::MAX));
        Ok(())
    }
}

impl Rewind for std::fs::File {
    fn rewind_to(&mut self, len: u64) -> io::Result<()> {
        use std::io::Seek;
        self.set_len(len)?;
        self.seek(io::SeekFrom::Start(len)).map(drop)
    }
}

/// Buffered bytes written to the output at once (whole ticks only).
const BATCH_BYTES: usize = 1 << 20;

/// Writes telemetry rows, keeping every `every`-th tick. Rows are buffered a whole tick at a
/// time and handed to the output in batches of whole ticks; when a batch fails (a full disk)
/// the output is cut back to the last whole batch, so the file holds only complete ticks.
pub struct TelemetryWriter<W: Rewind> {
    out: W,
    every: u64,
    line: String,
    /// "tick,t," of the rows being written (the same for every row of a tick).
    prefix: String,
    /// Bytes of whole ticks the output has taken.
    committed: u64,
    /// Where each buffered tick ends in `line`, so a batch cut short keeps its whole ticks.
    tick_ends: Vec<usize>,
}

impl<W: Rewind> TelemetryWriter<W> {
    /// Start a file: writes the header.
    pub fn new(out: W, every: u64) -> io::Result<Self> {
        let mut w = TelemetryWriter {
            out,
            every: every.max(1),
            line: String::with_capacity(BATCH_BYTES + 4096),
            prefix: String::with_capacity(64),
            committed: 0,
            tick_ends: Vec::new(),
        };
        w.line.push_str(HEADER);
        w.line.push('\n');
        w.tick_ends.push(w.line.len());
        w.flush()?;
        Ok(w)
    }

    /// Whether a tick is kept.
    pub fn keeps(&self, tick: u64) -> bool {
        tick.is_multiple_of(self.every)
    }

    /// Write one tick's rows (sorted by id by the caller).
    pub fn write_tick(&mut self, rows: &[Row]) -> io::Result<()> {
        let Some(first) = rows.first() else {
            return Ok(());
        };
        if !self.keeps(first.tick) {
            return Ok(());
        }
        // Shortest round-trip text (zmij, itoa): std's float formatting took over half of the
        // orchestrator's time at N = 40. NaN (a missing state) prints as "NaN". "tick,t," is
        // the same for every row of a tick: formatted once, copied per row.
        let mut ints = itoa::Buffer::new();
        let mut floats = zmij::Buffer::new();
        let mut head = None;
        for r in rows {
            if head != Some((r.tick, r.t_s.to_bits())) {
                head = Some((r.tick, r.t_s.to_bits()));
                self.prefix.clear();
                self.prefix.push_str(ints.format(r.tick));
                self.prefix.push(',');
                self.prefix.push_str(floats.format(r.t_s));
                self.prefix.push(',');
            }
            let line = &mut self.line;
            line.push_str(&self.prefix);
            line.push_str(ints.format(r.id));
            line.push(',');
            line.push_str(r.role.as_str());
            for v in [r.r, r.v, r.ht] {
                for c in [v.x, v.y, v.z] {
                    line.push(',');
                    line.push_str(floats.format(c));
                }
            }
            line.push('\n');
        }
        self.tick_ends.push(self.line.len());
        if self.line.len() >= BATCH_BYTES {
            self.flush()?;
        }
        Ok(())
    }

    /// Hand the buffered ticks to the output. When the output fails part way (a full disk) it
    /// is cut back to the last whole tick it took; the error is the write's, the rest of the
    /// batch is dropped.
    pub fn flush(&mut self) -> io::Result<()> {
        let bytes = self.line.as_bytes();
        let mut done = 0;
        let mut failed = None;
        while done < bytes.len() {
            match self.out.write(&bytes[done..]) {
                Ok(0) => {
                    failed = Some(io::Error::from(io::ErrorKind::WriteZero));
                    break;
                }
                Ok(n) => done += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        let failed = failed.or_else(|| self.out.flush().err());
        let kept = match failed {
            None => done,
            Some(_) => self
                .tick_ends
                .iter()
                .copied()
                .take_while(|&e| e <= done)
                .last()
                .unwrap_or(0),
        };
        self.committed += kept as u64;
        self.line.clear();
        self.tick_ends.clear();
        match failed {
            None => Ok(()),
            Some(e) => {
                let _ = self.out.rewind_to(self.committed);
                Err(e)
            }
        }
    }

    /// Bytes of whole ticks written so far (the file's length after a failed write).
    pub fn committed_len(&self) -> u64 {
        self.committed
    }
}

/// A writer dropped on any path (a fault, an interrupt) still hands its whole buffered ticks to
/// the file: telemetry keeps every complete tick (best effort; a failing output keeps its last
/// whole tick, as in `flush`).
impl<W: Rewind> Drop for TelemetryWriter<W> {
    fn drop(&mut self) {
        let _ = self.flush();
    }
}

impl<W: Rewind> TelemetrySink for TelemetryWriter<W> {
    fn keeps(&self, tick: u64) -> bool {
        TelemetryWriter::keeps(self, tick)
    }

    fn write_tick(&mut self, rows: &[Row]) -> io::Result<()> {
        TelemetryWriter::write_tick(self, rows)
    }

    fn flush(&mut self) -> io::Result<()> {
        TelemetryWriter::flush(self)
    }

    fn finish(&mut self) -> io::Result<()> {
        TelemetryWriter::flush(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Takes `room` bytes, then fails like a full disk.
    struct Full {
        bytes: Vec<u8>,
        room: usize,
    }

    impl Write for Full {
        fn write(&mut self, b: &[u8]) -> io::Result<usize> {
            let n = b.len().min(self.room - self.bytes.len());
            if n == 0 {
                return Err(io::Error::from_raw_os_error(libc::ENOSPC));
            }
            self.bytes.extend_from_slice(&b[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Rewind for Full {
        fn rewind_to(&mut self, len: u64) -> io::Result<()> {
            self.bytes.truncate(len as usize);
            Ok(())
        }
    }

    /// The text of one row field by field, as `write_tick` wrote it before it shared "tick,t,"
    /// between the rows of a tick.
    fn reference(rows: &[Row]) -> String {
        let mut out = String::new();
        let mut floats = zmij::Buffer::new();
        for r in rows {
            out.push_str(&format!(
                "{},{},{},{}",
                r.tick,
                floats.format(r.t_s),
                r.id,
                r.role.as_str()
            ));
            for c in [r.r, r.v, r.ht].iter().flat_map(|v| [v.x, v.y, v.z]) {
                out.push(',');
                out.push_str(floats.format(c));
            }
            out.push('\n');
        }
        out
    }

    #[test]
    fn rows_are_the_text_of_each_field_whatever_their_tick() {
        let edge = [
            0.0,
            -0.0,
            1e-310,
            -5e-324,
            1.7976931348623157e308,
            0.1,
            1e21,
            123456.789,
        ];
        let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            // SplitMix64: random bit patterns, every exponent.
            seed = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = seed;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        };
        let mut w = TelemetryWriter::new(Vec::new(), 1).unwrap();
        let mut want = format!("{HEADER}\n");
        for tick in 0..200u64 {
            let mut f = |k: u64| match (tick + k) % 7 {
                0 => edge[(next() % edge.len() as u64) as usize],
                1 => specials[(next() % 3) as usize],
                _ => f64::from_bits(next()),
            };
            let t = f(0);
            let rows: Vec<Row> = (0..5u64)
                .map(|k| Row {
                    // Rows of a tick share tick and t, except in every tenth call.
                    tick: if tick % 10 == 9 { tick + k } else { tick },
                    t_s: if tick % 10 == 9 { f(k) } else { t },
                    id: (tick * 5 + k) as u32 * 7919,
                    role: [Role::Primary, Role::Secondary, Role::Follower][(k % 3) as usize],
                    r: Vec3::new(f(1), f(2), f(3)),
                    v: Vec3::new(f(4), f(5), f(6)),
                    ht: Vec3::new(f(7), f(8), f(9)),
                })
                .collect();
            w.write_tick(&rows).unwrap();
            want.push_str(&reference(&rows));
        }
        w.flush().unwrap();
        assert_eq!(String::from_utf8(w.out.clone()).unwrap(), want);
    }

    #[test]
    fn a_full_output_keeps_whole_ticks_only() {
        let row = |tick| Row {
            tick,
            t_s: tick as f64 * 0.01,
            id: 1,
            role: Role::Follower,
            r: Vec3::zeros(),
            v: Vec3::zeros(),
            ht: Vec3::zeros(),
        };
        let mut w = TelemetryWriter::new(
            Full {
                bytes: Vec::new(),
                room: 200,
            },
            1,
        )
        .unwrap();
        let mut failed = false;
        for tick in 0..20 {
            w.write_tick(&[row(tick)]).unwrap();
            if w.flush().is_err() {
                failed = true;
                break;
            }
        }
        assert!(failed);
        let text = String::from_utf8(w.out.bytes.clone()).unwrap();
        assert!(text.ends_with('\n'), "{text:?}");
        assert_eq!(text.len() as u64, w.committed_len());
        assert!(text.lines().all(|l| l.split(',').count() == 13));
    }
}
