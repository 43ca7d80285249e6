//! `stagerl.train`: the run `stagerl train` makes (the same config resolution, run directory
//! lock, run files and closing evaluation), with the GIL released while it trains, a callback at
//! every periodic evaluation (and every N episodes when asked), and Ctrl-C honoured within about
//! a second: the run is saved as SIGINT saves it, then `KeyboardInterrupt` is raised.

use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use stagerl::config::Config;
use stagerl::run::dir::RunDir;
use stagerl::train as trainer;
use stagerl::train::{final_eval, Progress, Resumed, TrainOptions};

use crate::{bad_arg, guard, to_py};

/// How often the training thread looks for Ctrl-C (it takes the GIL to ask Python).
const SIGNAL_POLL: Duration = Duration::from_millis(100);

/// The config of a run: `json` (a dict in the TOML file's shape), else the file `path`, else
/// the defaults; then the keyword arguments, as the CLI's flags are applied.
#[allow(clippy::too_many_arguments)]
fn config(
    json: Option<&str>,
    path: Option<&str>,
    algo: Option<&str>,
    reward: Option<&str>,
    seed: Option<u64>,
    episodes: Option<u64>,
    env_steps: Option<u64>,
    eval_every_episodes: Option<u64>,
) -> PyResult<Config> {
    let mut cfg = match (json, path) {
        (Some(j), _) => {
            // A dict in the TOML file's shape, given as JSON: written as TOML and read as a file
            // is, so that its checks and messages are the CLI's.
            let value: serde_json::Value = serde_json::from_str(j)
                .map_err(|e| bad_arg("config", "a dict", &format!("JSON-serialisable: {e}")))?;
            let text = toml::to_string(&value).map_err(|e| {
                bad_arg(
                    "config",
                    "a dict",
                    &format!("the shape of a config file (tables of values, no None): {e}"),
                )
            })?;
            Config::from_toml_str(&text, Path::new("config (dict)")).map_err(to_py)?
        }
        (None, Some(p)) => Config::load(Path::new(p)).map_err(to_py)?,
        (None, None) => Config::default(),
    };
    if let Some(a) = algo {
        cfg.agent.algo = a.parse().map_err(to_py)?;
    }
    if let Some(r) = reward {
        cfg.reward.function = r.parse().map_err(to_py)?;
    }
    if let Some(s) = seed {
        cfg.train.seed = s;
    }
    if episodes.is_some() && env_steps.is_some() {
        return Err(bad_arg("episodes", episodes.unwrap_or(0), "not with env_steps: a run has one budget"));
    }
    if let Some(e) = episodes {
        cfg.train.episodes = e;
    }
    if let Some(n) = env_steps {
        cfg.train.env_steps = Some(n);
    }
    if let Some(e) = eval_every_episodes {
        cfg.train.eval_every_episodes = e;
    }
    Ok(cfg)
}

/// What the callback is given: the episode's counters (and its curriculum stage, with a
/// curriculum), the training success and reward over the last 100 episodes, and the periodic
/// evaluation's figures when one ran.
fn progress_report<'py>(
    py: Python<'py>,
    p: &Progress<'_>,
    recent: &VecDeque<(f64, bool)>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let r = p.record;
    d.set_item("episode", r.episode)?;
    d.set_item("env_steps", r.env_steps)?;
    d.set_item("wall_s", r.wall_s)?;
    d.set_item("episode_reward", r.reward)?;
    // None without a curriculum (`train.curriculum`), as episodes.csv then has no such column.
    d.set_item("curriculum_stage", r.curriculum_stage)?;
    let n = recent.len().max(1) as f64;
    d.set_item("train_success_rate", recent.iter().filter(|x| x.1).count() as f64 / n)?;
    d.set_item("train_mean_reward", recent.iter().map(|x| x.0).sum::<f64>() / n)?;
    d.set_item("last", p.last)?;
    match p.eval {
        Some(e) => {
            d.set_item("eval_success_rate", e.success_rate)?;
            d.set_item("eval_mean_reward", e.mean_reward)?;
            d.set_item("eval_mean_steps", e.mean_steps)?;
            d.set_item("eval_median_final_distance_m", e.median_final_distance_m)?;
        }
        None => {
            for k in
                ["eval_success_rate", "eval_mean_reward", "eval_mean_steps", "eval_median_final_distance_m"]
            {
                d.set_item(k, py.None())?;
            }
        }
    }
    Ok(d)
}

/// What the training thread keeps between episodes to report and to stop: the last 100
/// episodes, when it last looked for Ctrl-C, and why it asked the loop to stop (Ctrl-C or
/// another signal Python raised, the callback raised, or it returned False).
struct Watch {
    callback: Option<Py<PyAny>>,
    every: u64,
    flag: AtomicBool,
    recent: VecDeque<(f64, bool)>,
    last_poll: Instant,
    signal: Option<PyErr>,
    callback_error: Option<PyErr>,
    by_callback: bool,
}

impl Watch {
    fn on_episode(&mut self, p: &Progress<'_>) {
        self.recent.push_back((p.record.reward, p.record.success));
        if self.recent.len() > 100 {
            self.recent.pop_front();
        }
        let due = p.eval.is_some() || (self.every > 0 && p.record.episode.is_multiple_of(self.every));
        if !due && self.last_poll.elapsed() < SIGNAL_POLL {
            return;
        }
        self.last_poll = Instant::now();
        Python::attach(|py| {
            if let Err(e) = py.check_signals() {
                self.signal = Some(e);
                self.flag.store(true, Ordering::SeqCst);
                return;
            }
            let Some(cb) = self.callback.as_ref().filter(|_| due) else { return };
            match progress_report(py, p, &self.recent).and_then(|d| cb.call1(py, (d,))) {
                Ok(v) if v.bind(py).is(pyo3::types::PyBool::new(py, false)) => {
                    self.by_callback = true;
                    self.flag.store(true, Ordering::SeqCst);
                }
                Ok(_) => {}
                Err(e) => {
                    self.callback_error = Some(e);
                    self.flag.store(true, Ordering::SeqCst);
                }
            }
        });
    }
}

/// Train (or resume) the run in `out`; returns `(run directory, how it ended)`: "finished",
/// "already finished" or "stopped by the callback".
#[pyfunction]
#[pyo3(signature = (out, json=None, path=None, algo=None, reward=None, seed=None, episodes=None, env_steps=None, eval_every_episodes=None, closing_trials=500, threads=1, resume=false, callback=None, callback_every_episodes=0))]
#[allow(clippy::too_many_arguments)]
pub fn train(
    py: Python<'_>,
    out: PathBuf,
    json: Option<&str>,
    path: Option<&str>,
    algo: Option<&str>,
    reward: Option<&str>,
    seed: Option<u64>,
    episodes: Option<u64>,
    env_steps: Option<u64>,
    eval_every_episodes: Option<u64>,
    closing_trials: u32,
    threads: u32,
    resume: bool,
    callback: Option<Py<PyAny>>,
    callback_every_episodes: u64,
) -> PyResult<(String, String)> {
    if !(1..=64).contains(&threads) {
        return Err(bad_arg("threads", threads, "an integer from 1 to 64"));
    }
    if closing_trials > stagerl::config::MAX_EVAL_TRIALS {
        let allowed = format!("0 to {}", stagerl::config::MAX_EVAL_TRIALS);
        return Err(bad_arg("eval_trials", closing_trials, &allowed));
    }
    let dir = RunDir::new(&out);
    let cfg = if resume {
        if json.is_some() || path.is_some() || algo.is_some() || reward.is_some() || seed.is_some() {
            let allowed = "without config or settings: a resumed run keeps its own config";
            return Err(bad_arg("resume", "True", allowed));
        }
        dir.load_config().map_err(to_py)?
    } else {
        config(json, path, algo, reward, seed, episodes, env_steps, eval_every_episodes)?
    };
    let run = if resume { None } else { Some(cfg.resolve().map_err(to_py)?) };
    let taken = "a directory without a run (its config.toml exists): choose another, or pass resume=True to continue it";
    if !resume && dir.holds_run() {
        stagerl::run::lock::DirLock::check_free(&out).map_err(to_py)?;
        return Err(bad_arg("out", out.display(), taken));
    }
    let pool = stagerl::base::par::Pool::new(threads as usize).map_err(to_py)?;
    let mut watch = Watch {
        callback,
        every: callback_every_episodes,
        flag: AtomicBool::new(false),
        recent: VecDeque::with_capacity(101),
        last_poll: Instant::now(),
        signal: None,
        callback_error: None,
        by_callback: false,
    };
    let outcome = py.detach(|| {
        guard("train", || {
            let _lock = stagerl::run::lock::DirLock::run(&out).map_err(to_py)?;
            if !resume && dir.holds_run() {
                return Err(bad_arg("out", out.display(), taken));
            }
            if run.is_some() {
                dir.ensure_writable().map_err(to_py)?;
            }
            let flag = AtomicBool::new(false);
            let trained = {
                let opts = TrainOptions { stop: Some(&flag) };
                let mut on_episode = |p: &Progress<'_>| {
                    watch.on_episode(p);
                    if watch.flag.load(Ordering::SeqCst) {
                        flag.store(true, Ordering::SeqCst);
                    }
                };
                stagerl::base::par::install(Some(&pool), || match &run {
                    Some(run) => trainer::train_with(run, &out, &opts, &mut on_episode).map(|_| "finished"),
                    None => trainer::resume(&out, &opts, &mut on_episode).map(|r| match r {
                        Resumed::Finished(_) => "finished",
                        Resumed::AlreadyFinished(_) => "already finished",
                    }),
                })
            };
            match trained {
                Err(stagerl::Error::Interrupted { .. } | stagerl::Error::Stopped { .. }) => Ok("stopped"),
                Err(e) => Err(to_py(e)),
                Ok(how) => closing_evaluation(&out, &cfg, closing_trials, how),
            }
        })
    })?;
    if let Some(e) = watch.callback_error.take().or(watch.signal.take()) {
        return Err(e);
    }
    match outcome {
        "stopped" if watch.by_callback => Ok((out.display().to_string(), "stopped by the callback".into())),
        "stopped" => Err(PyKeyboardInterrupt::new_err(format!(
            "training stopped; the run is saved in {}: continue with stagerl.train(out=..., resume=True)",
            out.display()
        ))),
        how => Ok((out.display().to_string(), how.into())),
    }
}

/// The CLI's closing evaluation of a run that finished now (or before, without one).
fn closing_evaluation(out: &Path, cfg: &Config, trials: u32, how: &'static str) -> PyResult<&'static str> {
    let seed = trainer::eval::DEFAULT_EVAL_SEED;
    if trials > 0 && (how == "finished" || final_eval::recorded(out, seed).is_none()) {
        let stop = AtomicBool::new(false);
        final_eval::run(out, cfg, trials, seed, Some(&stop)).map_err(to_py)?;
    }
    Ok(how)
}

/// The checkpoint `checkpoint` names in the run `dir`: "best" (the best periodic evaluation's,
/// else the final one: `None` to the library), "final", "latest", or a file's path.
fn checkpoint_of(dir: &RunDir, checkpoint: &str) -> Option<PathBuf> {
    match checkpoint {
        "best" => None,
        "final" => Some(dir.final_checkpoint()),
        "latest" => Some(dir.latest()),
        path => Some(PathBuf::from(path)),
    }
}

/// Evaluate a run's policy (deterministic) under its config on `trials` targets of `seed`, the
/// first obstacle in the way with probability `obstacles_in_path` when set; the summary as JSON
/// (`stagerl eval`'s figures; nothing is written). The GIL is released meanwhile.
#[pyfunction]
#[pyo3(signature = (run, trials=500, seed=0, checkpoint="best", obstacles_in_path=None))]
pub fn evaluate_run(
    py: Python<'_>,
    run: PathBuf,
    trials: u32,
    seed: u64,
    checkpoint: &str,
    obstacles_in_path: Option<f64>,
) -> PyResult<String> {
    if !(1..=stagerl::config::MAX_EVAL_TRIALS).contains(&trials) {
        let allowed = format!("1 to {}", stagerl::config::MAX_EVAL_TRIALS);
        return Err(bad_arg("trials", trials, &allowed));
    }
    py.detach(|| {
        guard("Run.evaluate", || {
            let dir = RunDir::new(&run);
            let cfg = dir.load_config().map_err(to_py)?;
            let ckpt = checkpoint_of(&dir, checkpoint);
            let (_, mut env, mut agent, _) =
                trainer::eval::load_run_agent_noting(&dir, &cfg, ckpt.as_deref()).map_err(to_py)?;
            if let Some(p) = obstacles_in_path.filter(|&p| p != 0.0) {
                env.set_obstacles_in_path(p).map_err(to_py)?;
            }
            let opts = trainer::eval::EvalOptions::new(trials, seed);
            let policy = &mut stagerl::env::Policy(trainer::eval::deterministic(agent.as_mut()));
            let (summary, _) = trainer::eval::evaluate(&mut env, policy, &opts).map_err(to_py)?;
            serde_json::to_string(&summary).map_err(|e| bad_arg("run", run.display(), &e.to_string()))
        })
    })
}

/// Write a run's policy as an ONNX model to `out` (`stagerl export`: the same checks of the
/// output path; an existing file is replaced only with `force`); the checkpoint exported.
#[pyfunction]
#[pyo3(signature = (run, out, checkpoint="best", force=false))]
pub fn export_onnx(run: PathBuf, out: PathBuf, checkpoint: &str, force: bool) -> PyResult<String> {
    guard("Run.export_onnx", || {
        let dir = RunDir::new(&run);
        let ckpt = checkpoint_of(&dir, checkpoint);
        let inputs: Vec<&Path> = ckpt.as_deref().into_iter().collect();
        stagerl::run::dir::check_output_path(&out, "path", &inputs).map_err(to_py)?;
        let (used, bytes) = stagerl::export::onnx_of_run(&dir, ckpt.as_deref()).map_err(to_py)?;
        stagerl::run::dir::check_output_path(&out, "path", &[&used]).map_err(to_py)?;
        stagerl::io::write_new(&out, &bytes, force).map_err(to_py)?;
        Ok(used.display().to_string())
    })
}

/// `stagerl report`: the report of the runs under `dir` (a folder of runs or a study's
/// `runs.tar.xz`) written into `out`; the files written. The GIL is released meanwhile.
#[pyfunction]
#[pyo3(signature = (dir, out, trajectories=5, include_incomplete=false))]
pub fn report(
    py: Python<'_>,
    dir: PathBuf,
    out: PathBuf,
    trajectories: u32,
    include_incomplete: bool,
) -> PyResult<Vec<String>> {
    py.detach(|| {
        guard("report", || {
            let mut opts = stagerl::report::ReportOptions::new(&out);
            opts.trajectories = trajectories;
            opts.include_incomplete = include_incomplete;
            opts.command = vec!["stagerl.report (Python)".into(), dir.display().to_string()];
            let r = stagerl::report::generate(&dir, &opts).map_err(to_py)?;
            Ok(r.files.iter().map(|f| out.join(f).display().to_string()).collect())
        })
    })
}

/// `stagerl reproduce`: the runs of `preset` (a bundled preset's name or a preset file) into
/// `out`, `jobs` at once, with its shard (`task_index` of `task_count`); finished runs are
/// skipped and interrupted ones resume, as the CLI does. The sweep runs on its own threads while
/// this one, without the GIL, looks for Ctrl-C every 100 ms: the runs are then saved and
/// `KeyboardInterrupt` raised. Returns `(runs in this shard, taken by other processes, wall
/// seconds)`; failed runs raise `RuntimeError` naming each.
#[pyfunction]
#[pyo3(signature = (preset, out, jobs=1, task_index=None, task_count=None))]
pub fn reproduce(
    py: Python<'_>,
    preset: &str,
    out: PathBuf,
    jobs: usize,
    task_index: Option<usize>,
    task_count: Option<usize>,
) -> PyResult<(usize, usize, f64)> {
    use stagerl::sweep;
    if jobs == 0 {
        return Err(bad_arg("jobs", 0, "at least 1"));
    }
    let (spec, text) = sweep::Preset::resolve(preset).map_err(to_py)?;
    spec.check_shared().map_err(to_py)?;
    let (index, count) =
        sweep::resolve_shard(task_index, task_count, &|name| std::env::var(name).ok()).map_err(to_py)?;
    let runs = sweep::shard(spec.runs(), index, count).map_err(to_py)?;
    sweep::check_all_existing(&runs, &out).map_err(to_py)?;
    sweep::write_preset(&out, &text).map_err(to_py)?;
    let argv = vec!["stagerl.reproduce (Python)".to_string(), preset.to_string(), out.display().to_string()];
    let recorder = stagerl::run::provenance::Recorder::start(&out, argv).map_err(to_py)?;
    let stop = AtomicBool::new(false);
    let mut signal: Option<PyErr> = None;
    let outcome = py.detach(|| {
        std::thread::scope(|scope| {
            let sweep = scope.spawn(|| sweep::run_sweep(&runs, &out, &spec.sweep, jobs, &stop, &|_| {}));
            while !sweep.is_finished() {
                std::thread::sleep(SIGNAL_POLL);
                if signal.is_none() {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        signal = Some(e);
                        stop.store(true, Ordering::SeqCst);
                    }
                }
            }
            sweep.join().map_err(|_| pyo3::exceptions::PyRuntimeError::new_err("the sweep's thread panicked"))
        })
    })?;
    let ended = if outcome.interrupted || signal.is_some() {
        "interrupted".to_string()
    } else if !outcome.failures.is_empty() {
        format!("{} of {} runs failed", outcome.failures.len(), runs.len())
    } else {
        format!("finished ({} runs taken by other processes)", outcome.taken)
    };
    recorder.finish(&out, &ended).map_err(to_py)?;
    if let Some(e) = signal {
        return Err(e);
    }
    if !outcome.failures.is_empty() {
        return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
            "{} of {} runs failed:\n  {}",
            outcome.failures.len(),
            runs.len(),
            outcome.failures.join("\n  ")
        )));
    }
    Ok((runs.len(), outcome.taken, outcome.wall_s))
}
