//! Trained policies and planning (`stagerl.Policy`, `stagerl.plan`).

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use stagerl::agent::Agent;
use stagerl::plan::Planner;
use stagerl::run::dir::RunDir;

use crate::vec::array2;
use crate::{bad_arg, contiguous, guard, to_py};

/// The deterministic policy of a checkpoint (`Agent::predict`, as evaluation and planning run it).
#[pyclass(module = "stagerl._core")]
pub struct PolicyCore {
    /// In a mutex: a pyclass is shared between threads, and `predict` takes `&mut`.
    agent: Mutex<Box<dyn Agent>>,
    checkpoint: PathBuf,
    spec: String,
}

impl PolicyCore {
    fn agent(&self) -> MutexGuard<'_, Box<dyn Agent>> {
        // A panic inside `predict` is reported by `guard`; the agent itself stays usable.
        self.agent.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl PolicyCore {
    /// The policy of a run directory (its best available checkpoint) or of a checkpoint file.
    #[new]
    fn new(path: &str) -> PyResult<Self> {
        guard("Policy.load", || {
            let (checkpoint, _, agent) = stagerl::train::eval::load_policy(Path::new(path)).map_err(to_py)?;
            let ck = stagerl::io::checkpoint::Checkpoint::load(&checkpoint).map_err(to_py)?;
            let spec = ck.meta(stagerl::run::policy::POLICY_KEY).map_err(to_py)?.to_string();
            Ok(PolicyCore { agent: Mutex::new(agent), checkpoint, spec })
        })
    }

    #[getter]
    fn obs_dim(&self) -> usize {
        self.agent().obs_dim()
    }
    #[getter]
    fn act_dim(&self) -> usize {
        self.agent().act_dim()
    }
    #[getter]
    fn algorithm(&self) -> &'static str {
        self.agent().algo().name()
    }
    #[getter]
    fn checkpoint(&self) -> String {
        self.checkpoint.display().to_string()
    }
    /// The checkpoint's policy description (`stagerl::run::policy::PolicySpec`) as JSON.
    #[getter]
    fn spec_json(&self) -> &str {
        &self.spec
    }

    /// Actions (N, act_dim) in [-1, 1] for observations (N, obs_dim), row by row.
    fn predict<'py>(
        &self,
        py: Python<'py>,
        obs: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let (n, d) = (obs.shape()[0], obs.shape()[1]);
        let (od, ad) = (self.obs_dim(), self.act_dim());
        if d != od {
            return Err(bad_arg(
                "obs.shape",
                format!("({n}, {d})"),
                &format!("(N, {od}): the policy's observation length"),
            ));
        }
        let obs = contiguous("obs", &obs)?;
        if let Some(k) = obs.iter().position(|x| !x.is_finite()) {
            return Err(bad_arg(&format!("obs[{}, {}]", k / od, k % od), obs[k], "a finite number"));
        }
        let mut actions = vec![0.0f32; n * ad];
        py.detach(|| {
            guard("Policy", || {
                let mut agent = self.agent();
                for (o, a) in obs.chunks_exact(od).zip(actions.chunks_exact_mut(ad)) {
                    agent.predict(o, a);
                }
                Ok(())
            })
        })?;
        Ok(array2(py, n, ad, |out| out.copy_from_slice(&actions)))
    }
}

/// The trajectory `stagerl plan` writes for the run's policy: (a dict of arrays keyed like its
/// JSON lines, the summary line's fields as JSON, the warning or None); `shield`: through the
/// safety shield or not (`--shield`, `--no-shield`; unset: as the run was trained), the summary
/// then adds its `shield_*` counts when it ran.
#[pyfunction]
#[pyo3(signature = (run_dir, target, start=None, checkpoint=None, max_steps=None, obstacles=None, shield=None))]
#[allow(clippy::too_many_arguments)] // Python's keyword arguments, one per plan option
pub fn plan<'py>(
    py: Python<'py>,
    run_dir: &str,
    target: Vec<f64>,
    start: Option<Vec<f64>>,
    checkpoint: Option<&str>,
    max_steps: Option<u32>,
    obstacles: Option<Bound<'py, PyAny>>,
    shield: Option<bool>,
) -> PyResult<(Bound<'py, PyDict>, String, Option<String>)> {
    let obstacles = crate::obstacles::obstacles_of(obstacles.as_ref())?;
    let plan = guard("plan", || {
        let run = RunDir::new(Path::new(run_dir));
        let (_, mut planner) =
            Planner::from_run(&run, checkpoint.map(Path::new), max_steps).map_err(to_py)?;
        if let Some(on) = shield {
            planner.set_shield(on).map_err(to_py)?;
        }
        planner.plan_among(&target, start.as_deref(), obstacles.as_deref()).map_err(to_py)
    })?;
    let (rows, dof) = (plan.rows(), plan.dof);
    let d = PyDict::new(py);
    d.set_item("step", PyArray1::from_vec(py, (0..rows as u64).collect()))?;
    d.set_item("t_s", PyArray1::from_vec(py, (0..rows).map(|k| plan.row(k).t_s).collect()))?;
    d.set_item("q", PyArray1::from_slice(py, &plan.q).reshape([rows, dof])?)?;
    d.set_item("joint_vel", PyArray1::from_slice(py, &plan.joint_vel).reshape([rows, dof])?)?;
    d.set_item(
        "ee_pos",
        PyArray2::from_vec2(py, &plan.ee_pos.iter().map(|p| p.to_vec()).collect::<Vec<_>>())?,
    )?;
    d.set_item(
        "ee_quat",
        PyArray2::from_vec2(py, &plan.ee_quat.iter().map(|p| p.to_vec()).collect::<Vec<_>>())?,
    )?;
    d.set_item("distance", PyArray1::from_slice(py, &plan.distance))?;
    d.set_item("reward", PyArray1::from_slice(py, &plan.reward))?;
    let summary = serde_json::to_string(&plan.summary).map_err(|e| {
        pyo3::exceptions::PyRuntimeError::new_err(format!("internal error in stagerl (plan): {e}"))
    })?;
    Ok((d, summary, plan.warning))
}
