//! The package's exceptions: `ferrocat.Error` for everything the master, the segment or a
//! running master's socket refuses, with the message the CLI would print, and
//! `ferrocat.SdoAbort` (an `Error`) carrying the slave's abort code.
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(ferrocat, Error, PyException, "An error of the master, the segment or a running master.");
create_exception!(ferrocat, SdoAbort, Error, "A slave aborted an SDO transfer; `code` is its abort code.");

/// A master error as a Python exception; an SDO abort keeps its code and where it happened.
pub fn master(e: ferrocat_master::MasterError) -> PyErr {
    if let ferrocat_master::MasterError::Abort { position, index, subindex, code, .. } = &e {
        let err = SdoAbort::new_err(e.to_string());
        Python::attach(|py| {
            let v = err.value(py);
            let _ = v.setattr("code", code.0);
            let _ = v.setattr("position", *position);
            let _ = v.setattr("index", *index);
            let _ = v.setattr("subindex", *subindex);
        });
        return err;
    }
    Error::new_err(e.to_string())
}

/// Any other error, with its whole chain of causes as the CLI prints them (": "-joined).
pub fn other(e: impl std::error::Error) -> PyErr {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let more = c.to_string();
        if !text.contains(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        cause = c.source();
    }
    Error::new_err(text)
}

pub fn text(message: impl Into<String>) -> PyErr {
    Error::new_err(message.into())
}
