//! Bytes a row and writing time of telemetry.parquet under the encodings and codecs the
//! `parquet` crate offers, on the rows of a real run (docs/src/benchmarks/telemetry.md).
//!
//! How to run:
//!   orchestrator simulate --n 1000 --every 23 --telemetry parquet --out /tmp/run --no-figures
//!   cargo run --release -p cdm-parquet --example encodings -- /tmp/run/telemetry.parquet
//!
//! Each candidate rewrites the same rows, tick by tick, through `ParquetTelemetryWriter` (the
//! sink `simulate` and `launch` use), reads them back and checks every value bit for bit.

use std::path::{Path, PathBuf};
use std::time::Instant;

use cdm_parquet::{read_rows, writer_properties, ParquetTelemetryWriter};
use cdm_records::telemetry::{Row, TelemetrySink};
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::file::properties::{WriterProperties, WriterPropertiesBuilder};
use parquet::schema::types::ColumnPath;

const FLOATS: [&str; 10] = ["t", "x", "y", "z", "vx", "vy", "vz", "x_ht", "y_ht", "z_ht"];

/// The properties before this page's choice: PLAIN everywhere, dictionary for `role`.
fn plain(c: Compression) -> WriterPropertiesBuilder {
    WriterProperties::builder()
        .set_compression(c)
        .set_dictionary_enabled(false)
        .set_column_dictionary_enabled(ColumnPath::from("role"), true)
}

/// BYTE_STREAM_SPLIT floats and DELTA_BINARY_PACKED tick and id, with codec `c`.
fn split(c: Compression) -> WriterPropertiesBuilder {
    writer_properties().set_compression(c)
}

fn zstd(level: i32) -> Compression {
    Compression::ZSTD(ZstdLevel::try_new(level).expect("a valid zstd level"))
}

fn bits(r: &Row) -> Vec<u64> {
    let mut b = vec![r.tick, r.t_s.to_bits(), u64::from(r.id), r.role as u64];
    b.extend(
        [r.r, r.v, r.ht]
            .iter()
            .flat_map(|v| v.iter().map(|c| c.to_bits())),
    );
    b
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let input = PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: encodings TELEMETRY.parquet")?,
    );
    let mut ticks: Vec<Vec<Row>> = Vec::new();
    read_rows(&input, |r| {
        match ticks.last_mut() {
            Some(t) if t[0].tick == r.tick => t.push(*r),
            _ => ticks.push(vec![*r]),
        }
        Ok::<_, std::convert::Infallible>(())
    })?;
    let rows: usize = ticks.iter().map(Vec::len).sum();
    println!("{}: {rows} rows in {} ticks", input.display(), ticks.len());
    let dict_floats = FLOATS.iter().fold(plain(zstd(1)), |p, c| {
        p.set_column_dictionary_enabled(ColumnPath::from(*c), true)
    });
    let candidates: Vec<(&str, WriterPropertiesBuilder)> = vec![
        ("PLAIN, snappy (before)", plain(Compression::SNAPPY)),
        ("PLAIN, zstd 1", plain(zstd(1))),
        ("PLAIN + dictionary on floats, zstd 1", dict_floats),
        (
            "BYTE_STREAM_SPLIT + DELTA, uncompressed",
            split(Compression::UNCOMPRESSED),
        ),
        (
            "BYTE_STREAM_SPLIT + DELTA, snappy",
            split(Compression::SNAPPY),
        ),
        (
            "BYTE_STREAM_SPLIT + DELTA, zstd 1 (chosen)",
            writer_properties(),
        ),
        ("BYTE_STREAM_SPLIT + DELTA, zstd 3", split(zstd(3))),
        ("BYTE_STREAM_SPLIT + DELTA, zstd 9", split(zstd(9))),
        (
            "PLAIN floats + DELTA tick and id, zstd 1",
            plain(zstd(1))
                .set_column_encoding(ColumnPath::from("tick"), Encoding::DELTA_BINARY_PACKED)
                .set_column_encoding(ColumnPath::from("id"), Encoding::DELTA_BINARY_PACKED),
        ),
    ];
    let dir = std::env::temp_dir().join(format!("cdm-encodings-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    println!("| encoding, codec | bytes a row | writing ns a row |");
    println!("|---|---|---|");
    for (name, props) in candidates {
        let path = dir.join("candidate.parquet");
        let ns = write(&path, props, &ticks)? / rows as f64;
        let size = std::fs::metadata(&path)?.len();
        let mut flat = ticks.iter().flatten();
        read_rows(&path, |r| match flat.next() {
            Some(want) if bits(want) == bits(r) => Ok(()),
            _ => Err(format!("{name}: row {r:?} differs")),
        })?;
        if flat.next().is_some() {
            return Err(format!("{name}: rows missing").into());
        }
        println!("| {name} | {:.2} | {ns:.0} |", size as f64 / rows as f64);
    }
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}

/// Nanoseconds to write `ticks` into a new file at `path` and finish it.
fn write(
    path: &Path,
    props: WriterPropertiesBuilder,
    ticks: &[Vec<Row>],
) -> Result<f64, Box<dyn std::error::Error>> {
    let started = Instant::now();
    let mut w = ParquetTelemetryWriter::create_with(path, 1, props)?;
    for t in ticks {
        w.write_tick(t)?;
    }
    w.finish()?;
    Ok(started.elapsed().as_nanos() as f64)
}
