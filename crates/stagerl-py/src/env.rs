//! The reaching environment for `stagerl.envs.ReachEnv` (the Gymnasium wrapper lives in Python).

use numpy::{PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyString};
use std::path::Path;

use stagerl::config::Config;
use stagerl::env::{ReachEnv, Step};
use stagerl::reward::RewardFunction;

use crate::render::{EePath, Renderer, DEFAULT_SIZE, SIDE_RANGE};
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

/// The info keys of a step, in order: every reward term (`clearance`: the clearance penalty
/// taken off `total`, 0 without `[reward.clearance]`), then `collision` (1 when the step ended
/// with the arm in contact with the floor, itself or an obstacle, else 0); `is_success` follows
/// them in the info.
pub(crate) const STEP_KEYS: [&str; 20] = [
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
    "clearance",
    "shield",
    "collision",
];

/// The values of [`STEP_KEYS`] for a step.
pub(crate) fn step_values(s: &Step) -> [f64; 20] {
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
        t.clearance,
        t.shield,
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
    /// The renderer and the end effector's path, once [`ReachCore::enable_render`] is called.
    render: Option<Box<(Renderer, EePath)>>,
}

/// A frame's width and height, pixels, checked against [`SIDE_RANGE`] (None: the default).
pub(crate) fn frame_size(width: Option<i64>, height: Option<i64>) -> PyResult<(usize, usize)> {
    let (lo, hi) = SIDE_RANGE;
    let check = |name: &str, v: Option<i64>, default: usize| match v {
        None => Ok(default),
        Some(v) if (lo as i64..=hi as i64).contains(&v) => Ok(v as usize),
        Some(v) => Err(bad_arg(name, v, &format!("an integer from {lo} to {hi} (pixels)"))),
    };
    Ok((check("render_width", width, DEFAULT_SIZE.0)?, check("render_height", height, DEFAULT_SIZE.1)?))
}

/// A frame's bytes as a new `(height, width, 3)` uint8 array.
pub(crate) fn frame_array<'py>(
    py: Python<'py>,
    rgb: &[u8],
    width: usize,
    height: usize,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    PyArray1::from_slice(py, rgb).reshape([height, width, 3])
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
            Ok(ReachCore { env, render: None })
        })
    }

    /// What the environment is: see [`describe`].
    fn describe<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        describe(py, &self.env)
    }

    /// Draw frames of `width x height` pixels from now on (`render`), recording the end
    /// effector's path from the next episode on (and this one's current position).
    #[pyo3(signature = (width=None, height=None))]
    fn enable_render(&mut self, width: Option<i64>, height: Option<i64>) -> PyResult<()> {
        let (w, h) = frame_size(width, height)?;
        let env = &self.env;
        let (renderer, mut path) = guard("render", || {
            Ok((Renderer::new(env, w, h), EePath::new(env.task().max_steps as usize + 1)))
        })?;
        path.restart(env);
        self.render = Some(Box::new((renderer, path)));
        Ok(())
    }

    /// The current frame: a new `(height, width, 3)` uint8 array (RGB).
    fn render<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let Some(r) = self.render.as_deref_mut() else {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "`render_mode` = None: this environment renders nothing (make it with render_mode=\"rgb_array\")",
            ));
        };
        let (renderer, path) = (&mut r.0, &r.1);
        let env = &self.env;
        let (w, h) = renderer.size();
        let rgb = guard("render", || Ok(renderer.render(env, path)))?;
        frame_array(py, rgb, w, h)
    }

    /// Reseed the environment's random stream and start an episode (among `obstacles`, a list
    /// of dicts, when given: see [`ReachCore::use_obstacles`]); returns (obs, distance_m).
    #[pyo3(signature = (seed, obstacles=None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: u64,
        obstacles: Option<Bound<'py, PyAny>>,
    ) -> PyResult<(Obs<'py>, f64)> {
        let home = self.env.task().home_pose.clone();
        self.use_obstacles(obstacles.as_ref(), &home, None)?;
        let obs = guard("reset", || Ok(self.env.reset_with_seed(seed).to_vec()))?;
        self.restart_path();
        Ok((PyArray1::from_vec(py, obs), self.env.distance()))
    }

    /// Start an episode at joint positions `start` (radians; default: the home pose) with the
    /// given target (metres); the random stream is untouched. Returns (obs, distance_m).
    #[pyo3(signature = (target, start=None, obstacles=None))]
    fn reset_to<'py>(
        &mut self,
        py: Python<'py>,
        target: Vec<f64>,
        start: Option<Vec<f64>>,
        obstacles: Option<Bound<'py, PyAny>>,
    ) -> PyResult<(Obs<'py>, f64)> {
        if target.len() != 3 {
            return Err(bad_arg("target", format!("{target:?}"), "3 values x, y, z in metres"));
        }
        // The check of `stagerl plan`: finite, above the floor, within the arm's reach.
        let t = self.env.check_target(&target).map_err(to_py)?;
        let start = start.unwrap_or_else(|| self.env.task().home_pose.clone());
        self.use_obstacles(obstacles.as_ref(), &start, Some(t))?;
        let env = &mut self.env;
        let obs = guard("reset", || Ok(env.reset_to(&start, t).map_err(to_py)?.to_vec()))?;
        self.restart_path();
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
        if let Some(r) = self.render.as_deref_mut() {
            r.1.push(&self.env);
        }
        let obs = PyArray1::from_slice(py, self.env.observation());
        Ok((obs, s.total(), s.terminated, s.truncated, step_info(py, &s)?))
    }

    /// End-effector position (m) and the target (m).
    fn positions(&self) -> ([f64; 3], [f64; 3]) {
        let (p, t) = (self.env.ee_pose().position, self.env.target());
        ([p.x, p.y, p.z], [t.x, t.y, t.z])
    }
}

impl ReachCore {
    /// The scene of the next episodes: the task's fixed obstacles and `obstacles` (checked as
    /// `stagerl plan` checks a request's: the same messages), or the task's own scene when
    /// `None`.
    fn use_obstacles(
        &mut self,
        obstacles: Option<&Bound<'_, PyAny>>,
        start: &[f64],
        target: Option<stagerl::nalgebra::Vector3<f64>>,
    ) -> PyResult<()> {
        let Some(extra) = crate::obstacles::obstacles_of(obstacles)? else {
            self.env.set_request_obstacles(None);
            return Ok(());
        };
        crate::obstacles::check_scene(&self.env, &extra, start, target)?;
        self.env.set_request_obstacles(Some(&extra));
        Ok(())
    }

    /// A new episode began: its path starts at the end effector (when rendering).
    fn restart_path(&mut self) {
        if let Some(r) = self.render.as_deref_mut() {
            r.1.restart(&self.env);
        }
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
