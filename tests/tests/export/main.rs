//! `orchestrator export` and the telemetry formats, read back by other people's readers.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod export;
mod map_exports;
mod parquet;
mod rosbag;
