//! Bad and hostile input, and losing no data: refused with exit 2 and a clear message.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod bad_input;
mod hardening_files;
mod hardening_inputs;
