//! The batch of reaching environments for `stagerl.vector.ReachVectorEnv` (the Gymnasium
//! `VectorEnv` lives in Python): the library's `VecEnv` with next-step autoreset.

use numpy::PyUntypedArrayMethods;
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

use stagerl::env::VecEnv;

use crate::env::{build_config, describe, frame_array, frame_size, step_values, STEP_KEYS};
use crate::render::{EePath, Renderer};
use crate::{bad_arg, contiguous, guard, to_py};

type F64s<'py> = Bound<'py, PyArray1<f64>>;
type Bools<'py> = Bound<'py, PyArray1<bool>>;

/// What a step returns: observations (N, obs_dim), rewards, terminated, truncated, the info
/// dict and the environments whose seed pool to refill.
type StepOut<'py> =
    (Bound<'py, PyArray2<f32>>, F64s<'py>, Bools<'py>, Bools<'py>, Bound<'py, PyDict>, Vec<usize>);

/// `num_envs` reaching environments stepped together (see `stagerl::env::VecEnv`).
///
/// Every episode of environment `i` starts from the next seed of its pool, a block of seeds the
/// Python side draws from the sub-environment's generator ([`VecCore::refill`]); a call that
/// uses a pool's last seed returns the environments to refill.
#[pyclass(module = "stagerl._core")]
pub struct VecCore {
    env: VecEnv,
    pools: Vec<Vec<u64>>,
    used: Vec<usize>,
    next_seeds: Vec<u64>,
    /// The info keys (`STEP_KEYS`) and their mask keys (`_` + key) as Python strings.
    keys: Vec<(Py<PyString>, Py<PyString>)>,
    /// A read-only all-true mask, shared by every key that every environment holds.
    all: Py<PyArray1<bool>>,
    /// One renderer for every environment (they share the arm and the frame size) and each
    /// environment's end-effector path, once [`VecCore::enable_render`] is called.
    renderer: Option<Box<Renderer>>,
    paths: Vec<EePath>,
    /// Environments whose episode is among the scene given to `reset` (`obstacles`): their
    /// next autoreset goes back to the task's scene, as a `SyncVectorEnv`'s does.
    scene: Vec<bool>,
    /// The threads `step` splits the environments over (none: the calling thread alone).
    pool: Option<stagerl::base::par::Pool>,
}

impl VecCore {
    fn observations<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        array2(py, self.env.len(), self.env.obs_dim(), |out| out.copy_from_slice(self.env.observations()))
    }

    /// Take the next seed of environment `i`'s pool into `next_seeds[i]`.
    fn take_seed(&mut self, i: usize) -> PyResult<()> {
        let seed = self.pools[i].get(self.used[i]).copied().ok_or_else(|| {
            pyo3::exceptions::PyRuntimeError::new_err(format!(
                "internal error in stagerl: the seed pool of environment {i} is empty; please report it"
            ))
        })?;
        self.next_seeds[i] = seed;
        self.used[i] += 1;
        Ok(())
    }

    /// Vector info (Gymnasium's convention): every key of `STEP_KEYS` with its `_key` mask (the
    /// environments stepped; an environment reset in this step holds only `distance`), and
    /// `is_success`. The masks are read-only; one array serves several keys.
    fn info<'py>(&self, py: Python<'py>, success: Vec<bool>) -> PyResult<Bound<'py, PyDict>> {
        let env = &self.env;
        let n = env.len();
        let resets = env.autoreset().iter().filter(|&&r| r).count();
        let all = self.all.bind(py);
        let stepped = match resets {
            0 => Some(all.clone()),
            r if r == n => None,
            _ => {
                let m = PyArray1::from_vec(py, env.autoreset().iter().map(|r| !r).collect());
                m.getattr(intern!(py, "flags"))?.setattr(intern!(py, "writeable"), false)?;
                Some(m)
            }
        };
        // Row k: the values of STEP_KEYS[k]; after a reset only the distance is known (the rest 0).
        let mut table = vec![0.0; STEP_KEYS.len() * n];
        for (i, (s, e)) in env.last_steps().iter().zip(env.envs()).enumerate() {
            if env.autoreset()[i] {
                table[i] = e.distance();
            } else {
                step_values(s).iter().enumerate().for_each(|(k, &v)| table[k * n + i] = v);
            }
        }
        let info = PyDict::new(py);
        for (k, ((key, mask_key), row)) in self.keys.iter().zip(table.chunks_exact(n)).enumerate() {
            let mask = match (k, &stepped) {
                (0, _) => all,
                (_, Some(m)) => m,
                (_, None) => continue,
            };
            info.set_item(key.bind(py), PyArray1::from_slice(py, row))?;
            info.set_item(mask_key.bind(py), mask)?;
        }
        info.set_item(intern!(py, "is_success"), PyArray1::from_vec(py, success))?;
        info.set_item(intern!(py, "_is_success"), all)?;
        Ok(info)
    }

    /// The environments whose pool is used up.
    fn exhausted(&self) -> Vec<usize> {
        (0..self.env.len()).filter(|&i| self.used[i] >= self.pools[i].len()).collect()
    }

    /// The actions as a slice of `num_envs x act_dim` values.
    fn actions<'a>(&self, actions: &'a PyReadonlyArray2<'_, f32>) -> PyResult<&'a [f32]> {
        let (n, a) = (self.env.len(), self.env.act_dim());
        let shape = actions.shape();
        if shape != [n, a] {
            return Err(bad_arg(
                "actions.shape",
                format!("({}, {})", shape[0], shape[1]),
                &format!("({n}, {a}): one action per environment, one value per joint"),
            ));
        }
        contiguous("actions", actions)
    }
}

/// A new `rows x cols` array whose values `fill` writes (all of them).
pub(crate) fn array2<'py, T: numpy::Element>(
    py: Python<'py>,
    rows: usize,
    cols: usize,
    fill: impl FnOnce(&mut [T]),
) -> Bound<'py, PyArray2<T>> {
    // SAFETY: a new C-contiguous array that nothing else refers to yet; `fill` writes every
    // value before Python sees it (the callers copy a whole slice or write every index).
    unsafe {
        let a = PyArray2::<T>::new(py, [rows, cols], false);
        fill(a.as_slice_mut().expect("a new array is contiguous"));
        a
    }
}

#[pymethods]
impl VecCore {
    #[new]
    #[pyo3(signature = (num_envs, config_path=None, config_json=None, reward=None, robot=None, threads=1))]
    fn new(
        py: Python<'_>,
        num_envs: usize,
        config_path: Option<&str>,
        config_json: Option<&str>,
        reward: Option<&str>,
        robot: Option<&str>,
        threads: i64,
    ) -> PyResult<Self> {
        let max = stagerl::base::par::MAX_THREADS;
        let threads = usize::try_from(threads).ok().filter(|t| (1..=max).contains(t)).ok_or_else(|| {
            bad_arg(
                "threads",
                threads,
                &format!("an integer from 1 to {max} (threads stepping the environments)"),
            )
        })?;
        if num_envs == 0 || num_envs > stagerl::env::MAX_VEC_ENVS {
            // Checked before anything is allocated for them.
            return Err(bad_arg(
                "num_envs",
                num_envs,
                &format!("an integer from 1 to {}", stagerl::env::MAX_VEC_ENVS),
            ));
        }
        let env = guard("ReachVectorEnv", || {
            let cfg = build_config(config_path, config_json, reward, robot)?;
            let mut env = VecEnv::from_config(num_envs, &cfg, 0).map_err(to_py)?;
            env.set_obstacles_in_path(cfg.train.obstacles_in_path).map_err(to_py)?;
            Ok(env)
        })?;
        let keys = STEP_KEYS
            .iter()
            .map(|k| (PyString::new(py, k).unbind(), PyString::new(py, &format!("_{k}")).unbind()))
            .collect();
        let all = PyArray1::from_vec(py, vec![true; num_envs]);
        all.getattr("flags")?.setattr("writeable", false)?;
        let (pools, used, next_seeds) = (vec![Vec::new(); num_envs], vec![0; num_envs], vec![0; num_envs]);
        let (renderer, paths) = (None, Vec::new());
        let scene = vec![false; num_envs];
        let pool = match threads {
            1 => None,
            t => Some(stagerl::base::par::Pool::new(t).map_err(to_py)?),
        };
        Ok(VecCore { env, pools, used, next_seeds, keys, all: all.unbind(), renderer, paths, scene, pool })
    }

    #[getter]
    fn num_envs(&self) -> usize {
        self.env.len()
    }

    /// What one environment is: see `env::describe`.
    fn describe<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        describe(py, &self.env.envs()[0])
    }

    /// Draw frames of `width x height` pixels from now on (`render`), recording each
    /// environment's end-effector path.
    #[pyo3(signature = (width=None, height=None))]
    fn enable_render(&mut self, width: Option<i64>, height: Option<i64>) -> PyResult<()> {
        let (w, h) = frame_size(width, height)?;
        let envs = self.env.envs();
        let (renderer, paths) = guard("render", || {
            let paths = envs
                .iter()
                .map(|e| {
                    let mut p = EePath::new(e.task().max_steps as usize + 1);
                    p.restart(e);
                    p
                })
                .collect();
            Ok((Renderer::new(&envs[0], w, h), paths))
        })?;
        (self.renderer, self.paths) = (Some(Box::new(renderer)), paths);
        Ok(())
    }

    /// Environment `i`'s current frame: a new `(height, width, 3)` uint8 array (RGB).
    fn render<'py>(&mut self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let n = self.env.len();
        let Some(renderer) = self.renderer.as_deref_mut() else {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "`render_mode` = None: this environment renders nothing (make it with render_mode=\"rgb_array\")",
            ));
        };
        if i >= n {
            return Err(bad_arg("i", i, &format!("an environment index, 0 to {}", n - 1)));
        }
        let (env, path) = (&self.env.envs()[i], &self.paths[i]);
        let (w, h) = renderer.size();
        let rgb = guard("render", || Ok(renderer.render(env, path)))?;
        frame_array(py, rgb, w, h)
    }

    /// Replace environment `i`'s seed pool (its next episodes' seeds, in order).
    fn refill(&mut self, i: usize, seeds: PyReadonlyArray1<'_, u64>) -> PyResult<()> {
        let n = self.env.len();
        if i >= n {
            return Err(bad_arg("i", i, &format!("an environment index, 0 to {}", n - 1)));
        }
        let s = contiguous("seeds", &seeds)?;
        if s.is_empty() {
            return Err(bad_arg("seeds.shape", "(0,)", "(K,) with K >= 1 seeds"));
        }
        self.pools[i] = s.to_vec();
        self.used[i] = 0;
        Ok(())
    }

    /// Start a new episode in every environment from its pool's next seed, among `obstacles`
    /// (a list of dicts, checked as `ReachEnv.reset`'s) when given, for this episode only;
    /// (observations, distances_m, environments to refill).
    #[allow(clippy::type_complexity)]
    #[pyo3(signature = (obstacles=None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        obstacles: Option<Bound<'py, PyAny>>,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, F64s<'py>, Vec<usize>)> {
        let extra = crate::obstacles::obstacles_of(obstacles.as_ref())?;
        if let Some(extra) = &extra {
            let env = &self.env.envs()[0];
            crate::obstacles::check_scene(env, extra, &env.task().home_pose, None)?;
        }
        for i in 0..self.env.len() {
            self.env.set_request_obstacles(i, extra.as_deref()).map_err(to_py)?;
            self.scene[i] = extra.is_some();
            self.take_seed(i)?;
        }
        let (env, seeds) = (&mut self.env, &self.next_seeds);
        guard("reset", || {
            for (i, &s) in seeds.iter().enumerate() {
                env.reset_env_with_seed(i, s).map_err(to_py)?;
            }
            Ok(())
        })?;
        for (p, e) in self.paths.iter_mut().zip(self.env.envs()) {
            p.restart(e);
        }
        let d: Vec<f64> = self.env.envs().iter().map(|e| e.distance()).collect();
        Ok((self.observations(py), PyArray1::from_vec(py, d), self.exhausted()))
    }

    /// One step with next-step autoreset (`VecEnv::step_next_step_reset`): an environment whose
    /// episode ended in the previous step starts a new one from its pool's next seed.
    fn step<'py>(&mut self, py: Python<'py>, actions: PyReadonlyArray2<'py, f32>) -> PyResult<StepOut<'py>> {
        let actions = self.actions(&actions)?;
        for i in 0..self.env.len() {
            if self.env.envs()[i].is_done() {
                self.take_seed(i)?;
                if self.scene[i] {
                    self.env.set_request_obstacles(i, None).map_err(to_py)?;
                    self.scene[i] = false;
                }
            }
        }
        let (env, seeds, pool) = (&mut self.env, &self.next_seeds, self.pool.as_ref());
        py.detach(|| {
            guard("step", || {
                stagerl::base::par::install(pool, || env.step_next_step_reset(actions, seeds)).map_err(to_py)
            })
        })?;
        let env = &self.env;
        for ((p, e), &reset) in self.paths.iter_mut().zip(env.envs()).zip(env.autoreset()) {
            if reset {
                p.restart(e);
            } else {
                p.push(e);
            }
        }
        let success = env
            .last_steps()
            .iter()
            .zip(env.envs())
            .zip(env.autoreset())
            .map(
                |((s, e), &reset)| {
                    if reset {
                        e.distance() < e.reward_config().beta_m
                    } else {
                        s.terms.reached
                    }
                },
            )
            .collect();
        Ok((
            self.observations(py),
            PyArray1::from_slice(py, env.rewards()),
            PyArray1::from_slice(py, env.terminated()),
            PyArray1::from_slice(py, env.truncated()),
            self.info(py, success)?,
            self.exhausted(),
        ))
    }

    /// Seconds taken by `steps` calls of the Rust `VecEnv::step` (same-step autoreset, no
    /// Python in the loop) on a copy of this batch, with the actions `actions[k % K]` of a
    /// (K, num_envs, act_dim) array: the native speed the Python vector env is compared with.
    fn time_native_steps(
        &self,
        py: Python<'_>,
        actions: PyReadonlyArray3<'_, f32>,
        steps: usize,
    ) -> PyResult<f64> {
        let shape = actions.shape();
        let (n, a) = (self.env.len(), self.env.act_dim());
        if shape[1..] != [n, a] || shape[0] == 0 {
            return Err(bad_arg(
                "actions.shape",
                format!("{shape:?}"),
                &format!("(K, {n}, {a}) with K >= 1: K batches of actions"),
            ));
        }
        let flat = contiguous("actions", &actions)?;
        let (mut env, pool) = (self.env.clone(), self.pool.as_ref());
        for i in 0..n {
            if env.envs()[i].is_done() {
                env.reset_env_with_seed(i, i as u64).map_err(to_py)?;
            }
        }
        py.detach(|| {
            guard("time_native_steps", || {
                stagerl::base::par::install(pool, || {
                    let t = std::time::Instant::now();
                    for (k, batch) in flat.chunks_exact(n * a).cycle().take(steps).enumerate() {
                        env.step(batch)
                            .map_err(|e| pyo3::exceptions::PyValueError::new_err(format!("step {k}: {e}")))?;
                    }
                    Ok(t.elapsed().as_secs_f64())
                })
            })
        })
    }
}
