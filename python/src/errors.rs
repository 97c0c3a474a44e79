//! The CLI's failures as Python exceptions: the exit code picks the class, and the text is the
//! one the CLI prints after `error: ` (`Failure::message`).

use cdm_exit::{Exit, Failure};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    cdm,
    CdmError,
    PyException,
    "Any failure of the cdm package; the message is the orchestrator CLI's."
);
create_exception!(
    cdm,
    BadInput,
    CdmError,
    "Refused input (the CLI's exit 2): a scenario file, field, name or option, named in the message."
);
create_exception!(
    cdm,
    Fault,
    CdmError,
    "A run that could not complete (the CLI's exit 3): a control fault, a file that cannot be written."
);

/// The exception of a CLI failure.
pub fn to_py(f: Failure) -> PyErr {
    let text = f.message();
    match f.exit {
        Exit::BadInput => BadInput::new_err(text),
        _ => Fault::new_err(text),
    }
}

/// A refusal of the Python arguments themselves (the CLI's clap would refuse the same).
pub fn bad_input(text: impl Into<String>) -> PyErr {
    BadInput::new_err(text.into())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("CdmError", py.get_type::<CdmError>())?;
    m.add("BadInput", py.get_type::<BadInput>())?;
    m.add("Fault", py.get_type::<Fault>())?;
    Ok(())
}
