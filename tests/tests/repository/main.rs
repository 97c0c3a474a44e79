//! The repository itself: style rules, crate layering, the docs, the examples.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod docs;
mod examples;
mod layers;
mod style;
