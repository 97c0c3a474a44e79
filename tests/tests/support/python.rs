//! The test venv's Python (scripts/test-deps.sh: the PyPI `iceoryx2` package among others) with
//! `python/` on its path, for the tests of `python/cdm_bus.py` and its examples.

use std::path::{Path, PathBuf};
use std::process::Command;

use integration_tests::venv_python;

/// The repository's `python/` folder.
pub fn python_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("python")
}

/// The venv's interpreter with `args`, importing from `python/`.
pub fn python(args: &[&str]) -> Command {
    let mut c = Command::new(venv_python());
    // No __pycache__ in the source tree.
    c.env("PYTHONPATH", python_dir())
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .args(args);
    c
}
