//! The `ferrocat` Python package's native module: the master in-process, the virtual segment,
//! and the client of a running `ferrocat run`.
use pyo3::prelude::*;

mod client;
mod drive;
mod error;
mod master;
mod running;
mod segment;
mod segment_view;
mod slave;
mod world;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Error", m.py().get_type::<error::Error>())?;
    m.add("SdoAbort", m.py().get_type::<error::SdoAbort>())?;
    m.add_class::<master::Master>()?;
    m.add_class::<segment::Segment>()?;
    m.add_class::<segment_view::SegmentView>()?;
    m.add_class::<slave::Slave>()?;
    m.add_class::<slave::Variable>()?;
    m.add_class::<drive::Axis>()?;
    m.add_class::<client::Client>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
