//! The paper's rewards over rows of numpy arrays (`stagerl.rewards.compute`).

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::mem::MaybeUninit;

use stagerl::reward::batch::{compute_rows, Rows, COLUMNS};
use stagerl::reward::{RewardConfig, RewardTerms};

use crate::{bad_arg, contiguous, guard, to_py};

/// The keys of the result, in the order `stagerl reward` writes them.
#[pyfunction]
pub fn keys() -> Vec<&'static str> {
    RewardTerms::default().reported().iter().map(|(k, _)| *k).collect()
}

/// `array` as a contiguous slice of `rows x cols`, or a ValueError naming `field`.
fn rows<'a>(
    field: &str,
    array: &'a PyReadonlyArray2<'_, f64>,
    n: Option<usize>,
    cols: Option<usize>,
) -> PyResult<&'a [f64]> {
    let shape = array.shape();
    let (r, c) = (shape[0], shape[1]);
    if n.is_some_and(|n| n != r) || cols.is_some_and(|k| k != c) {
        let want_r = n.map_or("N".to_string(), |n| n.to_string());
        let want_c = cols.map_or("J >= 1".to_string(), |c| c.to_string());
        return Err(bad_arg(
            &format!("{field}.shape"),
            format!("({r}, {c})"),
            &format!("({want_r}, {want_c})"),
        ));
    }
    contiguous(field, array)
}

/// Every reported term for every row; `config_json` holds the reward section's fields. With
/// `out` (the float columns, in the order of [`keys`] without `reached`) and `out_reached`, the
/// values are written into those arrays (each of length N, C-contiguous, writable, sharing no
/// memory with another or with the inputs) and `None` is returned; else a dict of new arrays.
#[pyfunction]
#[pyo3(signature = (ee_pos, ee_quat, target, joint_vel, config_json, dt_s, prev_ee_pos=None, out=None, out_reached=None))]
#[allow(clippy::too_many_arguments)]
pub fn compute<'py>(
    py: Python<'py>,
    ee_pos: PyReadonlyArray2<'py, f64>,
    ee_quat: PyReadonlyArray2<'py, f64>,
    target: PyReadonlyArray2<'py, f64>,
    joint_vel: PyReadonlyArray2<'py, f64>,
    config_json: &str,
    dt_s: f64,
    prev_ee_pos: Option<PyReadonlyArray2<'py, f64>>,
    out: Option<Vec<Bound<'py, PyArray1<f64>>>>,
    out_reached: Option<Bound<'py, PyArray1<bool>>>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let cfg: RewardConfig = serde_json::from_str(config_json)
        .map_err(|e| bad_arg("constants", config_json, &format!("fields of the [reward] section ({e})")))?;
    cfg.validate().map_err(to_py)?;
    cfg.pose_only("stagerl.rewards.compute").map_err(to_py)?;
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(bad_arg("dt_s", dt_s, "a finite number of seconds > 0"));
    }
    let n = ee_pos.shape()[0];
    let p = rows("ee_pos", &ee_pos, Some(n), Some(3))?;
    let q = rows("ee_quat", &ee_quat, Some(n), Some(4))?;
    let t = rows("target", &target, Some(n), Some(3))?;
    let v = rows("joint_vel", &joint_vel, Some(n), None)?;
    let j = joint_vel.shape()[1];
    if j == 0 {
        return Err(bad_arg("joint_vel.shape", format!("({n}, 0)"), "(N, J) with J >= 1 joints"));
    }
    let prev = match &prev_ee_pos {
        Some(a) => Some(rows("prev_ee_pos", a, Some(n), Some(3))?),
        None => None,
    };
    if cfg.direction == stagerl::reward::DirectionSource::Displacement && prev.is_none() {
        return Err(bad_arg("prev_ee_pos", "None", "an (N, 3) array when direction = \"displacement\""));
    }
    let rows = Rows::new(p, q, t, v, j, prev).map_err(to_py)?;
    match (out, out_reached) {
        (Some(out), Some(out_reached)) => {
            compute_into(py, &cfg, dt_s, &rows, n, &out, &out_reached)?;
            return Ok(None);
        }
        (None, None) => {}
        _ => return Err(bad_arg("out", "a half-given output", "both `out` and `out_reached`, or neither")),
    }
    // The columns are the rows of one (KEYS - 1, n) buffer (one allocation: one unaligned head and
    // tail for the huge pages, see `column`), written once each, so not zeroed first (filling them
    // with zeros cost a tenth of the call); the result's arrays are views of its rows.
    let mut buf = column((KEYS - 1) * n);
    let mut reached = vec![false; n];
    {
        let mut cols: Vec<&mut [MaybeUninit<f64>]> =
            buf.spare_capacity_mut()[..(KEYS - 1) * n].chunks_mut(n.max(1)).collect();
        cols.resize_with(KEYS - 1, Default::default);
        py.detach(|| {
            guard("rewards.compute", || compute_parallel(&cfg, dt_s, &rows, &mut cols, &mut reached))
        })?;
    }
    // SAFETY: compute_parallel returned Ok, so compute_rows wrote every one of the n values of
    // every column (each thread all the rows of its chunk, the chunks covering 0..n).
    unsafe { buf.set_len((KEYS - 1) * n) };
    let all = numpy::ndarray::Array2::from_shape_vec((KEYS - 1, n), buf).expect("KEYS - 1 rows of n values");
    let all = numpy::PyArray2::from_owned_array(py, all);
    let d = PyDict::new(py);
    let mut row = 0;
    for key in keys() {
        if key == "reached" {
            d.set_item(key, PyArray1::from_vec(py, std::mem::take(&mut reached)))?;
        } else {
            d.set_item(key, all.get_item(row)?)?;
            row += 1;
        }
    }
    Ok(Some(d))
}

/// [`compute`] into the caller's arrays (`out`: the float columns in order; `out_reached`).
fn compute_into(
    py: Python<'_>,
    cfg: &RewardConfig,
    dt_s: f64,
    rows: &Rows<'_>,
    n: usize,
    out: &[Bound<'_, PyArray1<f64>>],
    out_reached: &Bound<'_, PyArray1<bool>>,
) -> PyResult<()> {
    if out.len() != KEYS - 1 {
        return Err(bad_arg(
            "out",
            format!("{} float arrays", out.len()),
            &format!("{} (every key but `reached`)", KEYS - 1),
        ));
    }
    let shared = |e: numpy::BorrowError| {
        bad_arg(
            "out",
            format!("arrays that cannot all be written at once ({e})"),
            "writable arrays that share no memory with one another or with the inputs",
        )
    };
    let mut cols_rw = Vec::with_capacity(KEYS - 1);
    for a in out {
        cols_rw.push(a.try_readwrite().map_err(shared)?);
    }
    let mut reached_rw = out_reached.try_readwrite().map_err(shared)?;
    let mut cols: Vec<&mut [MaybeUninit<f64>]> = Vec::with_capacity(KEYS - 1);
    for (c, key) in cols_rw.iter_mut().zip(keys().into_iter().filter(|k| *k != "reached")) {
        let slice = out_slice(key, c, n)?;
        // SAFETY: MaybeUninit<f64> has f64's layout; the slice is only written.
        cols.push(unsafe { &mut *(slice as *mut [f64] as *mut [MaybeUninit<f64>]) });
    }
    let reached = out_slice("reached", &mut reached_rw, n)?;
    py.detach(|| guard("rewards.compute", || compute_parallel(cfg, dt_s, rows, &mut cols, reached)))
}

/// The values of the output array for `key`: C-contiguous, `n` of them, or a `ValueError`.
fn out_slice<'a, T: numpy::Element>(
    key: &str,
    array: &'a mut numpy::PyReadwriteArray1<'_, T>,
    n: usize,
) -> PyResult<&'a mut [T]> {
    let len = array.len();
    if len != n {
        return Err(bad_arg(
            &format!("out[{key:?}].shape"),
            format!("({len},)"),
            &format!("({n},), one value per row"),
        ));
    }
    array
        .as_slice_mut()
        .map_err(|_| bad_arg(&format!("out[{key:?}]"), "a non-contiguous array", "C-contiguous"))
}

/// An empty vector with room for `n` values whose pages, on Linux, the kernel is asked to back with
/// transparent huge pages (`madvise(MADV_HUGEPAGE)` on the 2 MiB-aligned part): the first write
/// to fresh output memory then faults once per 2 MiB instead of once per 4 KiB, which was a fifth of
/// a large call's time. Only a hint: where it is refused, nothing changes but the speed.
fn column(n: usize) -> Vec<f64> {
    let v: Vec<f64> = Vec::with_capacity(n);
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let (ptr, len) = (v.as_ptr() as usize, n * std::mem::size_of::<f64>());
        let (start, end) = (ptr.next_multiple_of(HUGE), (ptr + len) / HUGE * HUGE);
        if end > start {
            // SAFETY: [start, end) lies inside the allocation `v` owns, which nothing has touched;
            // MADV_HUGEPAGE changes no content, only how the kernel backs the pages.
            unsafe { libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE) };
        }
    }
    v
}

/// Number of reported terms (the keys of the result).
const KEYS: usize = 12;

/// Rows of the inputs below which one thread computes them all.
const ROWS_PER_THREAD: usize = 1 << 16;

/// Every row into `cols` (the reported terms but `reached`, in order) and `reached`, on up to
/// one thread per core for large inputs (each row is computed alone, so the split changes no
/// value); the first bad row's error.
fn compute_parallel(
    cfg: &RewardConfig,
    dt_s: f64,
    rows: &Rows<'_>,
    cols: &mut [&mut [MaybeUninit<f64>]],
    reached: &mut [bool],
) -> PyResult<()> {
    let n = reached.len();
    debug_assert!(cols.iter().all(|c| c.len() == n));
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let threads = cores.min(n / ROWS_PER_THREAD).max(1);
    let chunk = n.div_ceil(threads).max(1);
    let mut col_chunks: Vec<_> = cols.iter_mut().map(|c| c.chunks_mut(chunk)).collect();
    let mut reached_chunks = reached.chunks_mut(chunk);
    std::thread::scope(|s| {
        let mut handles = Vec::new();
        for k in 0..n.div_ceil(chunk) {
            let mine: Vec<&mut [MaybeUninit<f64>]> =
                col_chunks.iter_mut().filter_map(Iterator::next).collect();
            let r = reached_chunks.next().expect("one chunk per thread");
            let mut mine: [&mut [MaybeUninit<f64>]; COLUMNS] =
                mine.try_into().expect("one chunk per reported term but `reached`");
            handles.push(s.spawn(move || {
                compute_rows(cfg, dt_s, rows, k * chunk, &mut mine, r)
                    .map_err(|bad| pyo3::exceptions::PyValueError::new_err(bad.to_string()))
            }));
        }
        // In row order, so the error returned is the first bad row's.
        handles.into_iter().try_for_each(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
    })
}
