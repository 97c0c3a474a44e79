//! telemetry.csv: one row per agent per tick, ordered by tick then id. Numbers use Rust's
//! shortest round-trip formatting, so equal values give equal bytes (the determinism contract
//! between `simulate` and `launch` is checked on these bytes).

use std::io::{self, Write};

use crate::formation::Role;
use crate::math::{Real, Vec3};

/// The header line.
pub const HEADER: &str = "tick,t,id,role,x,y,z,vx,vy,vz,x_ht,y_ht,z_ht";

/// The file format of a run's telemetry (`--telemetry`). CSV is the default: it is what the
/// byte-identical determinism tests compare. Parquet (crate `cdm-parquet`) holds the same
/// columns and values in a fraction of the bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TelemetryFormat {
    #[default]
    Csv,
    Parquet,
}

impl TelemetryFormat {
    /// The file name in the run directory.
    pub fn file_name(self) -> &'static str {
        match self {
            TelemetryFormat::Csv => "telemetry.csv",
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

/// One agent at one tick.
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

/// Writes telemetry rows, keeping every `every`-th tick. Each tick's rows are written together,
/// so a file cut short by a fault holds only complete ticks.
pub struct TelemetryWriter<W: Write> {
    out: W,
    every: u64,
    line: String,
}

impl<W: Write> TelemetryWriter<W> {
    /// Start a file: writes the header.
    pub fn new(mut out: W, every: u64) -> io::Result<Self> {
        writeln!(out, "{HEADER}")?;
        Ok(TelemetryWriter {
            out,
            every: every.max(1),
            line: String::with_capacity(4096),
        })
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
        self.line.clear();
        // Shortest round-trip text (zmij, itoa): std's float formatting took over half of the
        // orchestrator's time at N = 40. NaN (a missing state) prints as "NaN".
        let mut ints = itoa::Buffer::new();
        let mut floats = zmij::Buffer::new();
        for r in rows {
            let line = &mut self.line;
            line.push_str(ints.format(r.tick));
            line.push(',');
            line.push_str(floats.format(r.t_s));
            line.push(',');
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
        self.out.write_all(self.line.as_bytes())
    }

    /// Flush buffered rows to the file.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }
}

impl<W: Write> TelemetrySink for TelemetryWriter<W> {
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
