//! `fleetlink._native`: the per-sample and per-record work of the edge and the uplink, in Rust.

pub mod attachment;
pub mod cdr_avro;
pub mod dataplane;
pub mod drops;
pub mod producer;
pub mod rdkafka;
pub mod seq;
pub mod wakeups;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

/// A compiled layout, for checking the converter against the Python one.
#[pyclass(module = "fleetlink._native", frozen)]
struct AvroProgram {
    program: cdr_avro::Program,
}

#[pymethods]
impl AvroProgram {
    #[new]
    fn new(code: &[u8]) -> PyResult<Self> {
        Ok(AvroProgram { program: cdr_avro::Program::parse(code).map_err(PyValueError::new_err)? })
    }

    /// The Avro body of a CDR message, or `None` when the fast path does not take it.
    fn convert<'py>(&self, py: Python<'py>, cdr: &[u8]) -> Option<Bound<'py, PyBytes>> {
        let mut out = Vec::with_capacity(cdr.len());
        self.program.convert(cdr, &mut out).ok().map(|_| PyBytes::new(py, &out))
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<AvroProgram>()?;
    m.add_class::<dataplane::DataPlane>()?;
    m.add_class::<producer::ScannedBatch>()?;
    m.add_class::<producer::NativeProducer>()?;
    m.add("MISMATCH", dataplane::MISMATCH)?;
    Ok(())
}
