//! `launch --realtime`: the team on the wall clock.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod realtime;
