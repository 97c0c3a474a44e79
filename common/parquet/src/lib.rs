//! telemetry.parquet: the columns of telemetry.csv (`cdm_records::telemetry::HEADER`) as a Parquet
//! file, written and read with the `parquet` and `arrow` crates, so pandas, polars, DuckDB and
//! pyarrow read it as they are.
//!
//! Memory stays bounded: rows are buffered in columns and written as one row group of whole
//! ticks once [`ROW_GROUP_ROWS`] rows are buffered (about 6 MiB of values), whatever the run's
//! length. The file is a readable Parquet file between any two row groups (a footer follows
//! each), so a full disk or a killed run keeps every whole row group written.
//! The values are the same f64 / integers telemetry.csv prints (CSV prints them shortest
//! round-trip, so both files hold the same numbers; tested with pyarrow).

use std::fs::File;
use std::io::{Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::{Array, Float64Array, RecordBatch, StringArray, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use cdm_files::describe;
use cdm_math::Vec3;
use cdm_model::formation::Role;
use cdm_records::telemetry::{Row, TelemetrySink};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::arrow_writer::ArrowWriterOptions;
use parquet::arrow::{add_encoded_arrow_schema_to_metadata, ArrowSchemaConverter, ArrowWriter};
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::errors::ParquetError;
use parquet::file::metadata::{
    FileMetaData, KeyValue, ParquetMetaData, ParquetMetaDataWriter, RowGroupMetaData,
};
use parquet::file::properties::{WriterProperties, WriterPropertiesBuilder};
use parquet::schema::types::{ColumnPath, SchemaDescPtr};

/// Rows buffered before a row group is written (whole ticks: a row group holds up to one tick
/// more): 65,536 rows of 13 columns are about 6 MiB before encoding.
pub const ROW_GROUP_ROWS: usize = 1 << 16;

/// The nine f64 columns after `tick, t, id, role`, in telemetry.csv's order.
const VECTORS: [&str; 9] = ["x", "y", "z", "vx", "vy", "vz", "x_ht", "y_ht", "z_ht"];

/// A Parquet telemetry problem.
#[derive(Debug, thiserror::Error)]
pub enum TelemetryParquetError {
    /// Opening, writing or reading the file failed (the path is named by the caller).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The parquet or arrow library refused the data or the file.
    #[error(transparent)]
    Parquet(#[from] ParquetError),
    /// The file is valid Parquet but not telemetry: a column is missing or of another type.
    #[error("column `{column}`: {problem}")]
    Column {
        column: &'static str,
        problem: &'static str,
    },
    /// A row's role is not primary, secondary or follower.
    #[error("row {row}: unknown role `{role}`")]
    Role { row: u64, role: String },
    /// The caller's visitor refused a row (rows count from 1).
    #[error("row {row}: {message}")]
    Refused { row: u64, message: String },
}

/// The schema: the same column names as telemetry.csv.
pub fn schema() -> SchemaRef {
    let mut fields = vec![
        Field::new("tick", DataType::UInt64, false),
        Field::new("t", DataType::Float64, false),
        Field::new("id", DataType::UInt32, false),
        Field::new("role", DataType::Utf8, false),
    ];
    fields.extend(
        VECTORS
            .iter()
            .map(|name| Field::new(*name, DataType::Float64, false)),
    );
    Arc::new(Schema::new(fields))
}

/// How telemetry.parquet stores its columns (measured in docs/src/benchmarks/telemetry.md, bytes
/// a row and writing time, against the other encodings and codecs of the `parquet` crate):
/// - the f64 columns in BYTE_STREAM_SPLIT: byte k of every value together, so the bytes that
///   barely change from one member to the next (sign, exponent, leading mantissa) form long
///   runs the codec shrinks, where PLAIN interleaves them with the mantissa's noise;
/// - `tick` and `id` in DELTA_BINARY_PACKED: one tick repeated N times and ids counting up by
///   one are deltas of 0 and 1, a few bits a row before compression;
/// - dictionary encoding only for `role` (three values): the f64 values barely repeat, and a
///   dictionary of them cost a quarter of a whole run in the interner and its hash table;
/// - zstd at level 1 on every page: on BYTE_STREAM_SPLIT columns it finds the repeats that
///   snappy's short matches miss, at a writing cost close to snappy's on the same split bytes.
///
/// Lossless: every value reads back bit for bit (tested here and with pyarrow against
/// telemetry.csv).
pub fn writer_properties() -> WriterPropertiesBuilder {
    let mut props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::default()))
        .set_dictionary_enabled(false)
        .set_column_dictionary_enabled(ColumnPath::from("role"), true);
    for name in ["tick", "id"] {
        props = props.set_column_encoding(ColumnPath::from(name), Encoding::DELTA_BINARY_PACKED);
    }
    for name in std::iter::once("t").chain(VECTORS) {
        props = props.set_column_encoding(ColumnPath::from(name), Encoding::BYTE_STREAM_SPLIT);
    }
    props
}

/// Streams telemetry rows into a Parquet file, every `every`-th tick.
///
/// The file is readable at every moment, not only once finished: each row group (whole ticks)
/// is followed by a footer that lists the row groups so far, written by the `parquet` crate's
/// own [`ParquetMetaDataWriter`]; the next row group overwrites that footer in place. So a
/// full disk, or a run killed before `finish`, leaves a Parquet file of the whole row groups
/// written so far. When a write fails, the file is cut back to the last whole row group and
/// its footer written again: that space was the old footer's and has just been freed.
pub struct ParquetTelemetryWriter {
    writer: Option<ArrowWriter<File>>,
    schema: SchemaRef,
    /// The same open file as the writer's (a duplicated descriptor, so the same offset): the
    /// footers between row groups and the cut back after a failure go through it.
    file: File,
    path: PathBuf,
    /// What a footer says besides its row groups: schema, version, writer, ARROW:schema.
    footer: FooterParts,
    /// The row groups on disk in full, and where the last one ends.
    committed: Vec<RowGroupMetaData>,
    committed_end: u64,
    every: u64,
    tick: Vec<u64>,
    t: Vec<f64>,
    id: Vec<u32>,
    role: Vec<&'static str>,
    vectors: [Vec<f64>; 9],
}

/// The parts of the file metadata that do not change from one row group to the next.
struct FooterParts {
    schema: SchemaDescPtr,
    version: i32,
    created_by: String,
    key_value: Option<Vec<KeyValue>>,
}

impl FooterParts {
    /// The whole footer of a file holding `row_groups`.
    fn metadata(&self, row_groups: &[RowGroupMetaData]) -> ParquetMetaData {
        let rows = row_groups.iter().map(RowGroupMetaData::num_rows).sum();
        let file = FileMetaData::new(
            self.version,
            rows,
            Some(self.created_by.clone()),
            self.key_value.clone(),
            Arc::clone(&self.schema),
            None,
        );
        ParquetMetaData::new(file, row_groups.to_vec())
    }
}

impl ParquetTelemetryWriter {
    /// Create (truncate) the file at `path`; it is at once a readable file of no rows. The
    /// columns are stored as [`writer_properties`] says.
    pub fn create(path: &Path, every: u64) -> Result<Self, TelemetryParquetError> {
        Self::create_with(path, every, writer_properties())
    }

    /// [`create`](Self::create) with other encodings or compression (`props`; its row group
    /// size is set here): for measuring what they cost (the `encodings` example).
    pub fn create_with(
        path: &Path,
        every: u64,
        props: WriterPropertiesBuilder,
    ) -> Result<Self, TelemetryParquetError> {
        let file = File::create(path)?;
        let mut props = props
            // One row group per batch of whole ticks (`write_buffered` ends each): a file cut
            // back to its last row group ends on a whole tick, as telemetry.csv does.
            .set_max_row_group_row_count(None)
            .build();
        // What ArrowWriter would derive itself, derived once here so that the footers written
        // between row groups say exactly what its own final footer says.
        let arrow = schema();
        let parquet_schema = ArrowSchemaConverter::new()
            .with_coerce_types(props.coerce_types())
            .convert(&arrow)?;
        add_encoded_arrow_schema_to_metadata(&arrow, &mut props);
        let footer = FooterParts {
            schema: Arc::new(parquet_schema.clone()),
            version: props.writer_version().as_num(),
            created_by: props.created_by().to_string(),
            key_value: props.key_value_metadata().cloned(),
        };
        let options = ArrowWriterOptions::new()
            .with_properties(props)
            .with_skip_arrow_metadata(true)
            .with_parquet_schema(parquet_schema);
        let own = file.try_clone()?;
        let writer = ArrowWriter::try_new_with_options(file, Arc::clone(&arrow), options)?;
        let mut w = ParquetTelemetryWriter {
            writer: Some(writer),
            schema: arrow,
            file: own,
            path: path.to_path_buf(),
            footer,
            committed: Vec::new(),
            committed_end: 0,
            every: every.max(1),
            tick: Vec::with_capacity(ROW_GROUP_ROWS),
            t: Vec::with_capacity(ROW_GROUP_ROWS),
            id: Vec::with_capacity(ROW_GROUP_ROWS),
            role: Vec::with_capacity(ROW_GROUP_ROWS),
            vectors: std::array::from_fn(|_| Vec::with_capacity(ROW_GROUP_ROWS)),
        };
        w.commit()?;
        Ok(w)
    }

    /// Everything the writer took is on disk: note where it ends and which row groups it
    /// holds, write their footer after them and step back, so that the next row group
    /// overwrites it.
    fn commit(&mut self) -> Result<(), TelemetryParquetError> {
        let Some(writer) = self.writer.as_mut() else {
            return Ok(());
        };
        writer.sync()?;
        let flushed = writer.flushed_row_groups();
        self.committed
            .extend_from_slice(&flushed[self.committed.len().min(flushed.len())..]);
        self.committed_end = writer.bytes_written() as u64;
        self.write_footer()
    }

    /// The footer of the committed row groups, at `committed_end`; the file ends after it and
    /// the shared offset is back at `committed_end`.
    fn write_footer(&mut self) -> Result<(), TelemetryParquetError> {
        let metadata = self.footer.metadata(&self.committed);
        self.file.seek(SeekFrom::Start(self.committed_end))?;
        ParquetMetaDataWriter::new(&mut self.file, &metadata)
            .with_preserve_page_index_locations(false)
            .finish()?;
        let end = self.file.stream_position()?;
        self.file.set_len(end)?;
        self.file.seek(SeekFrom::Start(self.committed_end))?;
        Ok(())
    }

    /// After a failed write: no more writing; the file is cut back to the committed row
    /// groups and their footer written again. Returns `e` named with the file (and, on a full
    /// disk, the free space), and what the file keeps.
    fn fail(&mut self, e: TelemetryParquetError) -> std::io::Error {
        self.writer = None;
        // Described first: the free space when the write failed, not after the cut back.
        let cause = io_cause(&e);
        let what = match cause {
            Some(io) => describe(&self.path, io),
            None => e.to_string(),
        };
        let kept = self.file.set_len(self.committed_end).map_err(Into::into);
        let kept = kept.and_then(|()| self.write_footer());
        let rows: i64 = self.committed.iter().map(RowGroupMetaData::num_rows).sum();
        let kept = match kept {
            Ok(()) => format!(
                "kept {rows} rows (whole ticks) in {} row groups",
                self.committed.len()
            ),
            Err(again) => format!("and its footer could not be written again either: {again}"),
        };
        let kind = cause.map_or(std::io::ErrorKind::Other, std::io::Error::kind);
        std::io::Error::new(kind, format!("{}: {what}; {kept}", self.path.display()))
    }

    /// Write the buffered rows (whole ticks) as one row group and commit it.
    fn write_buffered(&mut self) -> Result<(), TelemetryParquetError> {
        let Some(writer) = self.writer.as_mut() else {
            return Ok(());
        };
        if self.tick.is_empty() {
            return Ok(());
        }
        let mut columns: Vec<Arc<dyn Array>> = vec![
            Arc::new(UInt64Array::from(std::mem::take(&mut self.tick))),
            Arc::new(Float64Array::from(std::mem::take(&mut self.t))),
            Arc::new(UInt32Array::from(std::mem::take(&mut self.id))),
            Arc::new(StringArray::from(std::mem::take(&mut self.role))),
        ];
        for v in &mut self.vectors {
            columns.push(Arc::new(Float64Array::from(std::mem::take(v))));
        }
        let batch =
            RecordBatch::try_new(Arc::clone(&self.schema), columns).map_err(ParquetError::from)?;
        writer.write(&batch)?;
        writer.flush()?;
        self.commit()
    }

    /// Write what is buffered and the writer's own footer (with its page indexes).
    fn close(&mut self) -> Result<(), std::io::Error> {
        let done = self.write_buffered().and_then(|()| {
            let Some(mut writer) = self.writer.take() else {
                return Ok(());
            };
            writer.finish()?;
            // The committed footer may have been longer than what follows the last row
            // group now.
            self.file.set_len(writer.bytes_written() as u64)?;
            Ok(())
        });
        done.map_err(|e| self.fail(e))
    }
}

/// The I/O error at the root of `e`, if it is one.
fn io_cause(e: &TelemetryParquetError) -> Option<&std::io::Error> {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(s) = source {
        if let Some(io) = s.downcast_ref::<std::io::Error>() {
            return Some(io);
        }
        source = s.source();
    }
    None
}

impl TelemetrySink for ParquetTelemetryWriter {
    fn keeps(&self, tick: u64) -> bool {
        tick.is_multiple_of(self.every)
    }

    fn write_tick(&mut self, rows: &[Row]) -> std::io::Result<()> {
        let Some(first) = rows.first() else {
            return Ok(());
        };
        if !self.keeps(first.tick) || self.writer.is_none() {
            return Ok(());
        }
        for r in rows {
            self.tick.push(r.tick);
            self.t.push(r.t_s);
            self.id.push(r.id);
            self.role.push(r.role.as_str());
            let values = [r.r, r.v, r.ht];
            for (k, column) in self.vectors.iter_mut().enumerate() {
                column.push(values[k / 3][k % 3]);
            }
        }
        if self.tick.len() >= ROW_GROUP_ROWS {
            self.write_buffered().map_err(|e| self.fail(e))?;
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        // Whole row groups are on disk with their footer as they are written; rows short of a
        // row group wait for it (a row group of a few rows would cost a footer each).
        Ok(())
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.close()
    }
}

impl Drop for ParquetTelemetryWriter {
    fn drop(&mut self) {
        // A run that ends on an error path still leaves a file of its complete ticks.
        let _ = self.close();
    }
}

fn column<'a, T: 'static>(
    batch: &'a RecordBatch,
    name: &'static str,
) -> Result<&'a T, TelemetryParquetError> {
    batch
        .column_by_name(name)
        .ok_or(TelemetryParquetError::Column {
            column: name,
            problem: "missing",
        })?
        .as_any()
        .downcast_ref::<T>()
        .ok_or(TelemetryParquetError::Column {
            column: name,
            problem: "not of telemetry's type",
        })
}

/// Read a telemetry.parquet row by row, in file order, one record batch in memory at a time.
/// `visit` may stop the read with its error, reported by its text and the row
/// ([`TelemetryParquetError::Refused`]).
pub fn read_rows<E: std::fmt::Display>(
    path: &Path,
    mut visit: impl FnMut(&Row) -> Result<(), E>,
) -> Result<(), TelemetryParquetError> {
    let file = File::open(path)?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)?.build()?;
    let mut row_no = 0u64;
    for batch in reader {
        let batch = batch.map_err(ParquetError::from)?;
        let tick = column::<UInt64Array>(&batch, "tick")?;
        let t = column::<Float64Array>(&batch, "t")?;
        let id = column::<UInt32Array>(&batch, "id")?;
        let role = column::<StringArray>(&batch, "role")?;
        let mut v: Vec<&Float64Array> = Vec::with_capacity(9);
        for name in VECTORS {
            v.push(column::<Float64Array>(&batch, name)?);
        }
        for i in 0..batch.num_rows() {
            let name = role.value(i);
            let role = Role::from_name(name).ok_or_else(|| TelemetryParquetError::Role {
                row: row_no + 1,
                role: name.to_string(),
            })?;
            let vec3 = |k: usize| Vec3::new(v[k].value(i), v[k + 1].value(i), v[k + 2].value(i));
            row_no += 1;
            visit(&Row {
                tick: tick.value(i),
                t_s: t.value(i),
                id: id.value(i),
                role,
                r: vec3(0),
                v: vec3(3),
                ht: vec3(6),
            })
            .map_err(|e| TelemetryParquetError::Refused {
                row: row_no,
                message: e.to_string(),
            })?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(tick: u64, id: u32) -> Row {
        let f = tick as f64 + id as f64 / 10.0;
        Row {
            tick,
            t_s: tick as f64 * 0.01,
            id,
            role: if id < 4 {
                Role::Primary
            } else {
                Role::Follower
            },
            r: Vec3::new(f, -f, 0.1 + f),
            v: Vec3::new(f * 3.0, f.sqrt(), f64::NAN),
            ht: Vec3::new(1e300, -1e-300, f / 7.0),
        }
    }

    #[test]
    fn rows_come_back_bit_for_bit_across_row_groups() {
        let dir = std::env::temp_dir().join(format!("cdm-parquet-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.parquet");
        let mut w = ParquetTelemetryWriter::create(&path, 2).unwrap();
        let mut want = Vec::new();
        // 30,000 ticks of 5 members, every 2nd kept: 75,000 rows, more than one row group.
        for tick in 0..30_000 {
            let rows: Vec<Row> = (1..=5).map(|id| row(tick, id)).collect();
            if w.keeps(tick) {
                want.extend(rows.iter().copied());
            }
            w.write_tick(&rows).unwrap();
        }
        w.finish().unwrap();
        let mut got = Vec::new();
        read_rows(&path, |r| {
            got.push(*r);
            Ok::<_, std::convert::Infallible>(())
        })
        .unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(got.len(), want.len());
        let bits = |r: &Row| {
            let mut b = vec![r.tick, r.t_s.to_bits(), r.id as u64, r.role as u64];
            b.extend(
                [r.r, r.v, r.ht]
                    .iter()
                    .flat_map(|v| v.iter().map(|c| c.to_bits())),
            );
            b
        };
        assert!(got.iter().zip(&want).all(|(a, b)| bits(a) == bits(b)));
    }

    fn read_back(path: &Path) -> Vec<Row> {
        let mut got = Vec::new();
        read_rows(path, |r| {
            got.push(*r);
            Ok::<_, std::convert::Infallible>(())
        })
        .unwrap();
        got
    }

    fn metadata_of(path: &Path) -> (SchemaRef, usize, Option<Vec<KeyValue>>) {
        let b = ParquetRecordBatchReaderBuilder::try_new(File::open(path).unwrap()).unwrap();
        let m = b.metadata();
        let kv = m.file_metadata().key_value_metadata().cloned();
        (b.schema().clone(), m.num_row_groups(), kv)
    }

    #[test]
    fn a_file_never_finished_holds_its_whole_row_groups_and_says_what_a_finished_one_says() {
        let dir = std::env::temp_dir().join(format!("cdm-parquet-kept-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (cut, done) = (dir.join("cut.parquet"), dir.join("done.parquet"));
        // Readable before any row: a file of no rows.
        let empty = std::mem::ManuallyDrop::new(ParquetTelemetryWriter::create(&cut, 1).unwrap());
        assert!(read_back(&cut).is_empty());
        drop(std::mem::ManuallyDrop::into_inner(empty));
        let mut cut_w =
            std::mem::ManuallyDrop::new(ParquetTelemetryWriter::create(&cut, 1).unwrap());
        let mut done_w = ParquetTelemetryWriter::create(&done, 1).unwrap();
        let mut want = Vec::new();
        // 15,000 ticks of 5 members: one row group of 13,108 whole ticks (65,540 rows), the
        // rest buffered.
        for tick in 0..15_000 {
            let rows: Vec<Row> = (1..=5).map(|id| row(tick, id)).collect();
            want.extend(rows.iter().copied());
            cut_w.write_tick(&rows).unwrap();
            done_w.write_tick(&rows).unwrap();
        }
        done_w.finish().unwrap();
        // `cut` is never finished nor dropped: as a killed run leaves it.
        let got = read_back(&cut);
        assert_eq!(got.len(), 65_540);
        assert!(got
            .iter()
            .zip(&want)
            .all(|(a, b)| a.tick == b.tick && a.id == b.id));
        assert_eq!(read_back(&done).len(), want.len());
        let (cut_schema, cut_groups, cut_kv) = metadata_of(&cut);
        let (done_schema, done_groups, done_kv) = metadata_of(&done);
        assert_eq!((cut_groups, done_groups), (1, 2));
        assert_eq!(cut_schema, done_schema);
        assert_eq!(cut_kv, done_kv);
        assert!(cut_kv.is_some_and(|kv| kv.iter().any(|k| k.key == "ARROW:schema")));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
