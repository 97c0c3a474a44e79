// Cargo resolves a crate's [build-dependencies] only when it has a build script: this empty one
// makes the build-time features count too.
fn main() {}
