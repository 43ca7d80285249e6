//! `stagerl._core`: the native half of the Python package `stagerl` (python/).
//!
//! Thin bindings over the library: the reaching environment ([`env`]) and a batch of them
//! ([`vec`]), the rewards over batches of rows ([`reward`]), the kinematics of any URDF chain
//! ([`kin`]), trained policies and planning ([`policy`]), the trainer ([`train`]). The Python
//! modules in `python/stagerl/` hold the Gymnasium API, argument defaults and documentation;
//! this crate holds no logic of its own beyond shapes, conversions and error mapping, and the
//! offscreen frames of `render_mode="rgb_array"` ([`render`], over the small software rasterizer
//! [`raster`]), which only read the environments.
//!
//! Errors: every library error becomes a `ValueError` (a missing file a `FileNotFoundError`,
//! other I/O failures an `OSError`) carrying the library's message, which names the field, the
//! value and what is allowed. Every call into the library runs inside [`guard`], so a Rust panic
//! surfaces as a `RuntimeError` instead of PyO3's `PanicException`.

use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

mod checker;
mod env;
mod kin;
mod obstacles;
mod policy;
mod raster;
mod render;
mod reward;
mod train;
mod vec;

/// The Python exception for a library error.
pub(crate) fn to_py(e: stagerl::Error) -> PyErr {
    match &e {
        stagerl::Error::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        stagerl::Error::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// A `ValueError` naming an argument, its value and what is allowed.
pub(crate) fn bad_arg(field: &str, value: impl std::fmt::Display, allowed: &str) -> PyErr {
    PyValueError::new_err(format!("`{field}` = {value} is invalid: {allowed}"))
}

/// The values of a C-contiguous array, or a `ValueError` naming `field`.
pub(crate) fn contiguous<'a, T: numpy::Element, D: numpy::ndarray::Dimension>(
    field: &str,
    array: &'a numpy::PyReadonlyArray<'_, T, D>,
) -> PyResult<&'a [T]> {
    array.as_slice().map_err(|_| {
        let dtype = std::any::type_name::<T>()
            .replace("f64", "float64")
            .replace("f32", "float32")
            .replace("u64", "uint64");
        bad_arg(field, "a non-contiguous array", &format!("a C-contiguous {dtype} array"))
    })
}

/// Run `f`, turning a panic into a `RuntimeError` (a bug in stagerl, never the caller's fault).
pub(crate) fn guard<T>(what: &str, f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in stagerl ({what}): {msg}; please report it"
            )))
        }
    }
}

/// The package's native module.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    stagerl::run::provenance::Code::record_build(env!("STAGERL_GIT_COMMIT"), env!("STAGERL_GIT_DIRTY"));
    // A bad STAGERL_SIMD: the import fails with the command line's message (ValueError).
    stagerl::base::simd::simd_cap().map_err(to_py)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("SIMD_LEVEL", stagerl::base::simd::simd_level().name())?;
    m.add("STEP_KEYS", env::STEP_KEYS.to_vec())?;
    m.add_class::<env::ReachCore>()?;
    m.add_class::<kin::Chain>()?;
    m.add_class::<checker::CollisionChecker>()?;
    m.add_class::<vec::VecCore>()?;
    m.add_class::<policy::PolicyCore>()?;
    m.add_function(wrap_pyfunction!(policy::plan, m)?)?;
    m.add_function(wrap_pyfunction!(train::train, m)?)?;
    m.add_function(wrap_pyfunction!(train::evaluate_run, m)?)?;
    m.add_function(wrap_pyfunction!(train::export_onnx, m)?)?;
    m.add_function(wrap_pyfunction!(train::report, m)?)?;
    m.add_function(wrap_pyfunction!(train::reproduce, m)?)?;
    m.add_function(wrap_pyfunction!(reward::compute, m)?)?;
    m.add_function(wrap_pyfunction!(reward::keys, m)?)?;
    Ok(())
}
