//! What a run looks like: `report`'s figures, the 3-D viewer, Foxglove.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod foxglove;
mod report;
mod viewer;
