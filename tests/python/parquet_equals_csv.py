"""Check that telemetry.parquet files hold exactly telemetry.csv's columns and values.

Usage: parquet_equals_csv.py TELEMETRY.csv TELEMETRY.parquet [MORE.parquet ...]

Reads each Parquet file with pyarrow (the reader pandas, polars and DuckDB users get) and the CSV
with Python's csv module, then compares column names, types, row count and every value exactly
(CSV prints shortest round-trip floats, so float(text) is the very same double), and that each
column chunk is stored as the writer chooses to (ENCODINGS, zstd). Prints one line per file; exits
1 naming the first difference.
"""

import csv
import math
import sys

import pyarrow as pa
import pyarrow.parquet as pq

TYPES = {"tick": pa.uint64(), "t": pa.float64(), "id": pa.uint32(), "role": pa.string()}
# The data pages' encoding of each column (the f64 columns: BYTE_STREAM_SPLIT); every chunk is
# compressed with zstd.
ENCODINGS = {"tick": "DELTA_BINARY_PACKED", "id": "DELTA_BINARY_PACKED", "role": "RLE_DICTIONARY"}


def read_csv(path):
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        cols = {name: [] for name in header}
        for row in reader:
            for name, text in zip(header, row):
                if name in ("tick", "id"):
                    cols[name].append(int(text))
                elif name == "role":
                    cols[name].append(text)
                else:
                    cols[name].append(float(text))
    return header, cols


def same(a, b):
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b


def check(csv_path, header, cols, parquet_path):
    table = pq.read_table(parquet_path)
    names = table.schema.names
    if names != header:
        sys.exit(f"{parquet_path}: columns {names}, CSV has {header}")
    for field in table.schema:
        want = TYPES.get(field.name, pa.float64())
        if field.type != want:
            sys.exit(f"{parquet_path}: column {field.name} is {field.type}, expected {want}")
    rows = len(cols[header[0]])
    if table.num_rows != rows:
        sys.exit(f"{parquet_path}: {table.num_rows} rows, {csv_path} has {rows}")
    for name in header:
        got = table.column(name).to_pylist()
        for i, (a, b) in enumerate(zip(got, cols[name])):
            if not same(a, b):
                sys.exit(f"{parquet_path}: row {i + 1} column {name}: {a!r}, CSV has {b!r}")
    meta = pq.ParquetFile(parquet_path).metadata
    for g in range(meta.num_row_groups):
        for c in range(meta.num_columns):
            chunk = meta.row_group(g).column(c)
            want = ENCODINGS.get(chunk.path_in_schema, "BYTE_STREAM_SPLIT")
            if want not in chunk.encodings or chunk.compression != "ZSTD":
                sys.exit(
                    f"{parquet_path}: row group {g} column {chunk.path_in_schema}: "
                    f"{chunk.encodings} {chunk.compression}, expected {want} and ZSTD"
                )
    print(f"{parquet_path}: {rows} rows x {len(header)} columns equal, {meta.num_row_groups} row groups")


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    header, cols = read_csv(sys.argv[1])
    for path in sys.argv[2:]:
        check(sys.argv[1], header, cols, path)


if __name__ == "__main__":
    main()
