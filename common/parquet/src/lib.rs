//! telemetry.parquet: the columns of telemetry.csv (`cdm_core::telemetry::HEADER`) as a Parquet
//! file, written and read with the `parquet` and `arrow` crates, so pandas, polars, DuckDB and
//! pyarrow read it as they are.
//!
//! Memory stays bounded: rows are buffered in columns and written as one row group of
//! [`ROW_GROUP_ROWS`] rows at a time (about 6 MiB of buffered values), whatever the run's length.
//! The values are the same f64 / integers telemetry.csv prints (CSV prints them shortest
//! round-trip, so both files hold the same numbers; tested with pyarrow).

use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use arrow_array::{Array, Float64Array, RecordBatch, StringArray, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use cdm_core::formation::Role;
use cdm_core::math::Vec3;
use cdm_core::telemetry::{Row, TelemetrySink};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::errors::ParquetError;
use parquet::file::properties::WriterProperties;
use parquet::schema::types::ColumnPath;

/// Rows per row group: 65,536 rows of 13 columns are about 6 MiB before encoding.
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

/// Streams telemetry rows into a Parquet file, every `every`-th tick.
pub struct ParquetTelemetryWriter {
    writer: Option<ArrowWriter<File>>,
    every: u64,
    tick: Vec<u64>,
    t: Vec<f64>,
    id: Vec<u32>,
    role: Vec<&'static str>,
    vectors: [Vec<f64>; 9],
}

impl ParquetTelemetryWriter {
    /// Create (truncate) the file at `path`.
    pub fn create(path: &Path, every: u64) -> Result<Self, TelemetryParquetError> {
        let file = File::create(path)?;
        let props = WriterProperties::builder()
            .set_compression(Compression::SNAPPY)
            .set_max_row_group_row_count(Some(ROW_GROUP_ROWS))
            // Dictionary encoding pays only where values repeat: `role` (three values). On the
            // f64 columns, whose values barely repeat, it cost a quarter of a whole run in
            // the interner and its hash table (BENCHMARKS.md).
            .set_dictionary_enabled(false)
            .set_column_dictionary_enabled(ColumnPath::from("role"), true)
            .build();
        let writer = ArrowWriter::try_new(file, schema(), Some(props))?;
        Ok(ParquetTelemetryWriter {
            writer: Some(writer),
            every: every.max(1),
            tick: Vec::with_capacity(ROW_GROUP_ROWS),
            t: Vec::with_capacity(ROW_GROUP_ROWS),
            id: Vec::with_capacity(ROW_GROUP_ROWS),
            role: Vec::with_capacity(ROW_GROUP_ROWS),
            vectors: std::array::from_fn(|_| Vec::with_capacity(ROW_GROUP_ROWS)),
        })
    }

    /// Write the buffered rows as one record batch (a row group once it is full).
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
        let batch = RecordBatch::try_new(schema(), columns).map_err(ParquetError::from)?;
        writer.write(&batch)?;
        Ok(())
    }

    /// Write what is buffered and the footer.
    fn close(&mut self) -> Result<(), TelemetryParquetError> {
        self.write_buffered()?;
        if let Some(writer) = self.writer.take() {
            writer.close()?;
        }
        Ok(())
    }
}

fn to_io(e: TelemetryParquetError) -> std::io::Error {
    match e {
        TelemetryParquetError::Io(e) => e,
        other => std::io::Error::other(other),
    }
}

impl TelemetrySink for ParquetTelemetryWriter {
    fn keeps(&self, tick: u64) -> bool {
        tick.is_multiple_of(self.every)
    }

    fn write_tick(&mut self, rows: &[Row]) -> std::io::Result<()> {
        let Some(first) = rows.first() else {
            return Ok(());
        };
        if !self.keeps(first.tick) {
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
            self.write_buffered().map_err(to_io)?;
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        // A Parquet file is readable only with its footer: complete ticks become readable at
        // `finish`, so there is nothing useful to push earlier than a full row group.
        Ok(())
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.close().map_err(to_io)
    }
}

impl Drop for ParquetTelemetryWriter {
    fn drop(&mut self) {
        // A run that ends on an error path still leaves a readable file of its complete ticks.
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
/// `visit` may stop the read with a message ([`TelemetryParquetError::Refused`]).
pub fn read_rows(
    path: &Path,
    mut visit: impl FnMut(&Row) -> Result<(), String>,
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
            .map_err(|message| TelemetryParquetError::Refused {
                row: row_no,
                message,
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
            Ok(())
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
}
