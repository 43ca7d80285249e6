//! The reaching environment for `stagerl.envs.ReachEnv` (the Gymnasium wrapper lives in Python).

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyString};
use std::path::Path;

use stagerl::config::Config;
use stagerl::env::{ReachEnv, Step};
use stagerl::reward::RewardFunction;

use crate::{bad_arg, guard, to_py};

/// A whole config from a TOML file, or from a JSON text of the TOML's fields (a Python dict),
/// or the defaults; then `reward` and `robot` override `reward.function` and `robot.urdf`.
pub(crate) fn build_config(
    config_path: Option<&str>,
    config_json: Option<&str>,
    reward: Option<&str>,
    robot: Option<&str>,
) -> PyResult<Config> {
    let mut cfg = match (config_path, config_json) {
        (Some(p), _) => Config::load(Path::new(p)).map_err(to_py)?,
        (None, Some(json)) => {
            let value: serde_json::Value =
                serde_json::from_str(json).map_err(|e| bad_arg("config", json, &e.to_string()))?;
            let text = toml::to_string(&value).map_err(|e| {
                bad_arg("config", json, &format!("a dict of the TOML's sections and fields ({e})"))
            })?;
            Config::from_toml_str(&text, Path::new("<config dict>")).map_err(to_py)?
        }
        (None, None) => Config::default(),
    };
    if let Some(r) = reward {
        cfg.reward.function = r.parse::<RewardFunction>().map_err(|_| {
            let names: Vec<&str> = RewardFunction::ALL.iter().map(|f| f.name()).collect();
            bad_arg("reward", format!("{r:?}"), &format!("one of {names:?}"))
        })?;
    }
    if let Some(r) = robot {
        if r.trim().is_empty() {
            return Err(bad_arg("robot", "\"\"", "\"ur5\" or a path to a URDF file"));
        }
        cfg.robot.urdf = r.to_string();
    }
    Ok(cfg)
}

/// The info keys of a step, in order: every reward term, then `collision` (1 when the step
/// ended with the arm in contact with the floor, itself or an obstacle, else 0); `is_success`
/// follows them in the info.
pub(crate) const STEP_KEYS: [&str; 18] = [
    "distance",
    "reached",
    "position",
    "phi",
    "direction",
    "posture",
    "move",
    "stride",
    "gamma_posture",
    "har",
    "alpha1",
    "alpha2",
    "sar",
    "basic",
    "reward",
    "bonus",
    "total",
    "collision",
];

/// The values of [`STEP_KEYS`] for a step.
pub(crate) fn step_values(s: &Step) -> [f64; 18] {
    let t = &s.terms;
    [
        t.distance,
        f64::from(u8::from(t.reached)),
        t.position,
        t.phi,
        t.direction,
        t.posture,
        t.movement,
        t.stride,
        t.gamma_posture,
        t.har,
        t.alpha1,
        t.alpha2,
        t.sar,
        t.basic,
        t.reward,
        t.bonus,
        t.total,
        f64::from(u8::from(s.collision.is_some())),
    ]
}

/// The info dict's keys ([`STEP_KEYS`], then `is_success`) as interned Python strings, made once:
/// a step's dict then creates no key string and hashes none (a fifth of a step's Python cost).
static INFO_KEYS: PyOnceLock<Vec<Py<PyString>>> = PyOnceLock::new();

fn step_info<'py>(py: Python<'py>, s: &Step) -> PyResult<Bound<'py, PyDict>> {
    let keys = INFO_KEYS.get_or_init(py, || {
        STEP_KEYS.iter().chain(&["is_success"]).map(|k| PyString::intern(py, k).unbind()).collect()
    });
    let d = PyDict::new(py);
    for (k, v) in keys.iter().zip(step_values(s)) {
        d.set_item(k.bind(py), v)?;
    }
    d.set_item(keys[STEP_KEYS.len()].bind(py), s.terms.reached)?;
    Ok(d)
}

/// An observation (or a bound of one) as a numpy float32 array.
type Obs<'py> = Bound<'py, PyArray1<f32>>;

/// One reaching environment (see `stagerl::env::ReachEnv`).
#[pyclass(module = "stagerl._core")]
pub struct ReachCore {
    env: ReachEnv,
}

#[pymethods]
impl ReachCore {
    #[new]
    #[pyo3(signature = (config_path=None, config_json=None, reward=None, robot=None))]
    fn new(
        config_path: Option<&str>,
        config_json: Option<&str>,
        reward: Option<&str>,
        robot: Option<&str>,
    ) -> PyResult<Self> {
        guard("ReachEnv", || {
            let cfg = build_config(config_path, config_json, reward, robot)?;
            let mut env = ReachEnv::from_config(&cfg, 0).map_err(to_py)?;
            env.set_obstacles_in_path(cfg.train.obstacles_in_path).map_err(to_py)?;
            Ok(ReachCore { env })
        })
    }

    /// What the environment is: see [`describe`].
    fn describe<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        describe(py, &self.env)
    }

    /// Reseed the environment's random stream and start an episode; returns (obs, distance_m).
    fn reset<'py>(&mut self, py: Python<'py>, seed: u64) -> PyResult<(Obs<'py>, f64)> {
        let obs = guard("reset", || Ok(self.env.reset_with_seed(seed).to_vec()))?;
        Ok((PyArray1::from_vec(py, obs), self.env.distance()))
    }

    /// Start an episode at joint positions `start` (radians; default: the home pose) with the
    /// given target (metres); the random stream is untouched. Returns (obs, distance_m).
    #[pyo3(signature = (target, start=None))]
    fn reset_to<'py>(
        &mut self,
        py: Python<'py>,
        target: Vec<f64>,
        start: Option<Vec<f64>>,
    ) -> PyResult<(Obs<'py>, f64)> {
        if target.len() != 3 {
            return Err(bad_arg("target", format!("{target:?}"), "3 values x, y, z in metres"));
        }
        // The check of `stagerl plan`: finite, above the floor, within the arm's reach.
        let t = self.env.check_target(&target).map_err(to_py)?;
        let start = start.unwrap_or_else(|| self.env.task().home_pose.clone());
        let env = &mut self.env;
        let obs = guard("reset", || Ok(env.reset_to(&start, t).map_err(to_py)?.to_vec()))?;
        Ok((PyArray1::from_vec(py, obs), self.env.distance()))
    }

    /// One step: (obs, reward, terminated, truncated, info).
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        action: PyReadonlyArray1<'py, f32>,
    ) -> PyResult<(Obs<'py>, f64, bool, bool, Bound<'py, PyDict>)> {
        let a = action.as_array();
        let s = guard("step", || {
            let s = match a.as_slice() {
                Some(a) => self.env.step(a),
                None => self.env.step(&a.to_vec()),
            };
            s.map_err(to_py)
        })?;
        let obs = PyArray1::from_slice(py, self.env.observation());
        Ok((obs, s.total(), s.terminated, s.truncated, step_info(py, &s)?))
    }

    /// End-effector position (m) and the target (m).
    fn positions(&self) -> ([f64; 3], [f64; 3]) {
        let (p, t) = (self.env.ee_pose().position, self.env.target());
        ([p.x, p.y, p.z], [t.x, t.y, t.z])
    }
}

/// The facts of an environment the Python side reads once: `obs_dim`, `act_dim`, `max_steps`,
/// `dt_s` (seconds), `beta_m` (metres), `joint_names`, and `observation_low` and
/// `observation_high` (float32 arrays, see [`obs_bounds`]).
pub(crate) fn describe<'py>(py: Python<'py>, env: &ReachEnv) -> PyResult<Bound<'py, PyDict>> {
    let (lo, hi) = guard("describe", || Ok(obs_bounds(env)))?;
    let d = PyDict::new(py);
    d.set_item("obs_dim", env.obs_dim())?;
    d.set_item("act_dim", env.act_dim())?;
    d.set_item("max_steps", env.task().max_steps)?;
    d.set_item("dt_s", env.task().dt_s)?;
    d.set_item("beta_m", env.reward_config().beta_m)?;
    d.set_item("joint_names", env.chain().joints().iter().map(|j| j.name.clone()).collect::<Vec<_>>())?;
    d.set_item("observation_low", PyArray1::from_vec(py, lo))?;
    d.set_item("observation_high", PyArray1::from_vec(py, hi))?;
    Ok(d)
}

/// The observation's bounds: those of its layout ([`stagerl::env::ObservationLayout::bounds`]).
fn obs_bounds(env: &ReachEnv) -> (Vec<f32>, Vec<f32>) {
    stagerl::env::ObservationLayout::of(env.task()).bounds(env.task(), env.chain())
}
