//! Python: the `cdm` package and a team's live bus.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod python_bus;
mod python_package;
