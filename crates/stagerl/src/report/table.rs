//! Our Table 1: runs grouped by (algorithm, reward function, configuration) over seeds, the
//! paper's indicators per run and their mean ± std over seeds, rendered beside the paper's figures
//! as Markdown and CSV.

use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::paper::{self, PaperRow};
use super::runs::RunData;
use crate::config::Config;
use crate::io::csv::{to_csv, CsvRow};
use crate::report::method::Method;
use crate::report::metrics::{self, Convergence, ConvergenceCriterion, MeanStd, TrainMetrics};
use crate::reward::RewardFunction;
use crate::train::eval::EvalSummary;
use crate::Result;

/// Config keys that do not change what a run learns: runs that differ only in these are seeds of
/// one configuration.
const IGNORED_KEYS: [&str; 7] = [
    "agent.algo",
    "reward.function",
    "train.seed",
    "train.eval_every_episodes",
    "train.eval_trials",
    "train.eval_seed",
    "train.checkpoint_every_episodes",
];

fn flatten(prefix: &str, v: &toml::Value, out: &mut BTreeMap<String, String>) {
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                flatten(&key, v, out);
            }
        }
        other => {
            out.insert(prefix.to_string(), other.to_string());
        }
    }
}

fn flat_config(cfg: &Config) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    if let Ok(t) = cfg.to_toml_string().parse::<toml::Table>() {
        flatten("", &toml::Value::Table(t), &mut out);
    }
    out
}

/// The configuration's identity apart from algorithm, reward function, seed and evaluation
/// settings: the settings that differ from the defaults, `key=value` sorted by key, or
/// `"defaults"` (of its algorithm). Equal labels mean equal configurations (given the same
/// defaults).
pub fn variant_label(cfg: &Config) -> String {
    let mut defaults = Config::default();
    defaults.agent.algo = cfg.agent.algo;
    let base = flat_config(&defaults);
    let this = flat_config(cfg);
    let keys: std::collections::BTreeSet<&String> = base.keys().chain(this.keys()).collect();
    // Hindsight relabelling is named as such, first.
    let her = cfg.agent.her.map(|h| format!("HER ({}, k={})", h.strategy.name(), h.k));
    let diffs: Vec<String> = her
        .into_iter()
        .chain(
            keys.into_iter()
                .filter(|k| !IGNORED_KEYS.contains(&k.as_str()) && !k.starts_with("agent.her."))
                .filter(|k| base.get(*k) != this.get(*k))
                .map(|k| format!("{k}={}", this.get(k).map(String::as_str).unwrap_or("(unset)"))),
        )
        .collect();
    if diffs.is_empty() {
        "defaults".into()
    } else {
        diffs.join(", ")
    }
}

/// A run left out of a group's figures, with the reason.
#[derive(Clone, Debug, Serialize)]
pub struct Excluded {
    pub name: String,
    pub seed: u64,
    pub reason: String,
}

/// Runs of one (algorithm, reward function, configuration), one per seed.
#[derive(Clone, Debug)]
pub struct Group {
    pub algo: Method,
    pub reward: RewardFunction,
    /// See [`variant_label`].
    pub variant: String,
    /// The configuration Table 1 shows for this (algorithm, reward function): the one with the
    /// most seeds; the others are listed apart.
    pub primary: bool,
    /// The runs the indicators are computed from, sorted by seed.
    pub runs: Vec<RunData>,
    pub excluded: Vec<Excluded>,
}

/// Group runs by (algorithm, reward function, configuration). Incomplete runs (fewer episodes
/// than configured, e.g. still training) are excluded unless `include_incomplete`; of runs with
/// the same seed, the first by name is kept.
pub fn group_runs(runs: Vec<RunData>, include_incomplete: bool) -> Vec<Group> {
    let mut map: BTreeMap<(usize, usize, String), Group> = BTreeMap::new();
    for run in runs {
        let (algo, reward) = (Method::of(&run.config), run.config.reward.function);
        let variant = variant_label(&run.config);
        let ai = ALGO_ORDER.iter().position(|a| *a == algo).unwrap_or(usize::MAX);
        let ri = RewardFunction::ALL.iter().position(|r| *r == reward).unwrap_or(usize::MAX);
        let g = map.entry((ai, ri, variant.clone())).or_insert_with(|| Group {
            algo,
            reward,
            variant,
            primary: false,
            runs: Vec::new(),
            excluded: Vec::new(),
        });
        let exclude = |reason: String| Excluded { name: run.name.clone(), seed: run.seed(), reason };
        if run.episodes.is_empty() {
            let why = run.notes.first().cloned().unwrap_or_else(|| "episodes.csv holds no episode".into());
            g.excluded.push(exclude(format!("no episodes read ({why})")));
        } else if !run.complete && !include_incomplete {
            g.excluded.push(exclude(format!(
                "incomplete: {} of {} episodes",
                run.episodes.len(),
                run.config.train.episodes
            )));
        } else if let Some(other) = g.runs.iter().find(|r| r.seed() == run.seed()) {
            g.excluded.push(exclude(format!("same seed as {}", other.name)));
        } else {
            g.runs.push(run);
        }
    }
    let mut groups: Vec<Group> = map.into_values().collect();
    for g in &mut groups {
        g.runs.sort_by_key(|r| r.seed());
    }
    // The primary configuration of each (algorithm, reward): most runs, then most episodes,
    // then "defaults", then label order.
    let mut best: BTreeMap<(usize, usize), usize> = BTreeMap::new();
    for (i, g) in groups.iter().enumerate() {
        let k = (g.algo as usize, g.reward as usize);
        let score = |g: &Group| {
            (
                g.runs.len(),
                g.runs.first().map_or(0, |r| r.config.train.episodes),
                g.variant == "defaults",
                std::cmp::Reverse(g.variant.clone()),
            )
        };
        match best.get(&k) {
            Some(&j) if score(&groups[j]) >= score(g) => {}
            _ => {
                best.insert(k, i);
            }
        }
    }
    for i in best.into_values() {
        groups[i].primary = true;
    }
    groups
}

/// The algorithms in Table 1's order (the paper's SAC and DDPG, then ours).
pub const ALGO_ORDER: [Method; 7] = Method::ORDER;

/// One run's indicators.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub name: String,
    pub seed: u64,
    /// Episodes in `episodes.csv`.
    pub episodes: u64,
    pub convergence: Convergence,
    /// Eq. 17 and steps from `E_start`; `None` when the run did not converge.
    pub train: Option<TrainMetrics>,
    /// Mean reward of the tail (the converged level, or where the run ended up).
    pub tail_mean_reward: f64,
    /// From the per-trial evaluation CSV, when there is one.
    pub eval: Option<EvalSummary>,
    /// The final checkpoint's closing evaluation on the same targets (the paper's protocol),
    /// when the run has one.
    pub eval_final_checkpoint: Option<EvalSummary>,
    pub eval_file: Option<String>,
    pub notes: Vec<String>,
}

/// A group's indicators: per run and mean ± std over seeds.
#[derive(Clone, Debug, Serialize)]
pub struct GroupSummary {
    pub algo: Method,
    pub reward: RewardFunction,
    pub variant: String,
    pub primary: bool,
    /// Configured training episodes (on a budget of environment steps, `train.env_steps`: the
    /// most episodes a seed trained).
    pub episodes: u64,
    pub runs: Vec<RunSummary>,
    pub excluded: Vec<Excluded>,
    pub seeds: usize,
    pub converged: usize,
    /// Mean ± std over the converged seeds.
    pub e_start: Option<MeanStd>,
    pub train_reward: Option<MeanStd>,
    pub train_steps: Option<MeanStd>,
    pub v_stdev: Option<MeanStd>,
    /// Mean ± std over the seeds with a per-trial evaluation.
    pub eval_reward: Option<MeanStd>,
    pub eval_steps: Option<MeanStd>,
    /// In [0, 1].
    pub success_rate: Option<MeanStd>,
    /// Fraction of evaluation trials with a contact, in [0, 1] (seeds whose evaluation records
    /// contacts).
    pub collision_rate: Option<MeanStd>,
    pub eval_trials: Option<u64>,
    /// Caveats for the reader (partial convergence, missing files, excluded runs).
    pub notes: Vec<String>,
}

fn seeds_list(seeds: &[u64]) -> String {
    seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", ")
}

/// One run's indicators (problems met become its notes).
fn summarize_run(run: &RunData, criterion: &ConvergenceCriterion) -> RunSummary {
    let rewards: Vec<f64> = run.episodes.iter().map(|r| r.reward).collect();
    let mut notes = run.notes.clone();
    let convergence = metrics::convergence(&rewards, criterion).unwrap_or_else(|e| {
        notes.push(format!("episodes.csv: {e}"));
        Convergence {
            outcome: metrics::ConvergenceOutcome::InvalidData,
            e_start: None,
            tail_mean: f64::NAN,
            tail_std: f64::NAN,
            band: f64::NAN,
            first_window_mean: f64::NAN,
        }
    });
    let train = convergence
        .e_start
        .and_then(|i| run.episodes.get(i as usize - 1))
        .and_then(|r| metrics::train_metrics(&run.episodes, r.episode));
    let tail = &rewards[rewards.len() - criterion.tail_len(rewards.len()).min(rewards.len())..];
    let eval = run.final_eval.as_ref().and_then(|f| EvalSummary::of(&f.trials));
    let eval_file =
        run.final_eval.as_ref().and_then(|f| f.path.file_name()).map(|n| n.to_string_lossy().into_owned());
    if !run.complete {
        notes.push(match run.config.train.env_steps {
            Some(n) => format!(
                "incomplete: {} of {n} environment steps",
                run.episodes.last().map_or(0, |r| r.env_steps)
            ),
            None => format!("incomplete: {} of {} episodes", run.episodes.len(), run.config.train.episodes),
        });
    }
    RunSummary {
        name: run.name.clone(),
        seed: run.seed(),
        episodes: run.episodes.len() as u64,
        convergence,
        train,
        tail_mean_reward: crate::base::math::mean(tail).unwrap_or(f64::NAN),
        eval,
        eval_final_checkpoint: run.final_checkpoint_eval.as_ref().and_then(|f| EvalSummary::of(&f.trials)),
        eval_file,
        notes,
    }
}

/// Compute a group's indicators.
pub fn summarize(group: &Group, criterion: &ConvergenceCriterion) -> Result<GroupSummary> {
    criterion.validate()?;
    let runs: Vec<RunSummary> = group.runs.iter().map(|run| summarize_run(run, criterion)).collect();
    let conv: Vec<&RunSummary> = runs.iter().filter(|r| r.train.is_some()).collect();
    let tm = |f: &dyn Fn(&TrainMetrics) -> Option<f64>| {
        MeanStd::of_present(conv.iter().map(|r| r.train.as_ref().and_then(f)))
    };
    let em = |f: &dyn Fn(&EvalSummary) -> Option<f64>| {
        MeanStd::of_present(runs.iter().map(|r| r.eval.as_ref().and_then(f)))
    };
    let n = runs.len();
    let (notes, eval_trials) = group_notes(group, &runs, conv.len());
    Ok(GroupSummary {
        algo: group.algo,
        reward: group.reward,
        variant: group.variant.clone(),
        primary: group.primary,
        // On a budget of environment steps, the most episodes a seed took to spend it.
        episodes: match group.runs.first() {
            Some(r) if r.config.train.env_steps.is_some() => {
                group.runs.iter().filter_map(|r| r.episodes.last().map(|e| e.episode)).max().unwrap_or(0)
            }
            r => r.map_or(0, |r| r.config.train.episodes),
        },
        seeds: n,
        converged: conv.len(),
        e_start: tm(&|t| Some(t.e_start as f64)),
        train_reward: tm(&|t| Some(t.mean_reward)),
        train_steps: tm(&|t| t.mean_steps_success),
        v_stdev: tm(&|t| t.v_stdev),
        eval_reward: em(&|e| Some(e.mean_reward)),
        eval_steps: em(&|e| e.mean_steps),
        success_rate: em(&|e| Some(e.success_rate)),
        collision_rate: em(&|e| e.collision_rate),
        eval_trials,
        excluded: group.excluded.clone(),
        runs,
        notes,
    })
}

/// The caveats of a group (convergence, missing or uneven evaluations, excluded runs, the runs'
/// own notes) and its evaluation trials.
fn group_notes(group: &Group, runs: &[RunSummary], converged: usize) -> (Vec<String>, Option<u64>) {
    let mut notes = Vec::new();
    let n = runs.len();
    if n == 0 {
        notes.push("no complete run".to_string());
    } else if converged == 0 {
        let why: Vec<String> =
            runs.iter().map(|r| format!("seed {}: {}", r.seed, r.convergence.outcome.describe())).collect();
        notes.push(format!("no seed converged ({}); no E_start or training columns", why.join("; ")));
    } else if converged < n {
        let why: Vec<String> = runs
            .iter()
            .filter(|r| r.train.is_none())
            .map(|r| format!("seed {}: {}", r.seed, r.convergence.outcome.describe()))
            .collect();
        notes.push(format!(
            "{} of {n} seeds converged ({}); E_start and the training columns average the converged seeds",
            converged,
            why.join("; ")
        ));
    }
    let no_eval: Vec<u64> = runs.iter().filter(|r| r.eval.is_none()).map(|r| r.seed).collect();
    if !no_eval.is_empty() && n > 0 {
        if no_eval.len() == n {
            notes.push("no per-trial evaluation CSV (eval-final-seed<N>.csv, eval-seed<N>.csv or one of stagerl eval)".into());
        } else {
            notes.push(format!(
                "no per-trial evaluation CSV for seed(s) {}; the evaluation columns average the others",
                seeds_list(&no_eval)
            ));
        }
    }
    let trials: Vec<u64> = runs.iter().filter_map(|r| r.eval.map(|e| u64::from(e.trials))).collect();
    let eval_trials = trials.first().copied();
    if trials.iter().any(|t| Some(*t) != eval_trials) {
        notes.push(format!("evaluation trials differ between seeds: {}", seeds_list(&trials)));
    }
    for ex in &group.excluded {
        notes.push(format!("{} (seed {}) excluded: {}", ex.name, ex.seed, ex.reason));
    }
    for r in runs {
        for note in &r.notes {
            notes.push(format!("{} (seed {}): {note}", r.name, r.seed));
        }
    }
    (notes, eval_trials)
}

/// The primary group of `(algo, reward)`, if any.
pub fn primary(groups: &[GroupSummary], algo: Method, reward: RewardFunction) -> Option<&GroupSummary> {
    groups.iter().find(|g| g.primary && g.algo == algo && g.reward == reward)
}

/// Method names as the papers print them.
pub fn algo_title(a: Method) -> &'static str {
    a.title()
}

/// Reward-function names as the paper prints them.
pub fn reward_title(r: RewardFunction) -> &'static str {
    match r {
        RewardFunction::Basic => "Basic",
        RewardFunction::Posture => "Posture",
        RewardFunction::Stride => "Stride",
        RewardFunction::Har => "HAR",
        RewardFunction::Sar => "SAR",
    }
}

const DASH: &str = "—";

fn ms(v: &Option<MeanStd>, scale: f64, decimals: usize) -> String {
    match v {
        None => DASH.into(),
        Some(m) => match m.std {
            Some(s) => format!("{:.*} ± {:.*}", decimals, m.mean * scale, decimals, s * scale),
            None => format!("{:.*}", decimals, m.mean * scale),
        },
    }
}

fn opt(v: Option<f64>, scale: f64, decimals: usize) -> String {
    v.map_or_else(|| DASH.into(), |x| format!("{:.*}", decimals, x * scale))
}

fn pair(v: Option<(f64, f64)>, decimals: usize) -> String {
    v.map_or_else(|| DASH.into(), |(m, s)| format!("{m:.decimals$} ± {s:.decimals$}"))
}

/// A rate in [0, 1] as a percentage cell, mean ± std over seeds.
fn pct(v: &Option<MeanStd>) -> String {
    ms(v, 100.0, 1) + if v.is_some() { " %" } else { "" }
}

/// Markdown cells of our row: E_start, train reward, train steps, V_STDEV, eval reward, eval
/// steps, success rate, collision rate.
fn our_cells(g: &GroupSummary) -> [String; 8] {
    let no_conv = g.seeds > 0 && g.converged == 0;
    let train = |v: &Option<MeanStd>, d| if no_conv { "n.c.".to_string() } else { ms(v, 1.0, d) };
    [
        if no_conv { "did not converge".into() } else { ms(&g.e_start, 1.0, 0) },
        train(&g.train_reward, 3),
        train(&g.train_steps, 1),
        train(&g.v_stdev, 3),
        ms(&g.eval_reward, 1.0, 3),
        ms(&g.eval_steps, 1.0, 1),
        pct(&g.success_rate),
        collision_cell(g.success_rate.is_some(), &g.collision_rate),
    ]
}

/// The collision-rate cell: "not checked" for evaluations without a collision count (an arm
/// without collision shapes, or evaluations recorded before contacts were), never a silent 0 %.
fn collision_cell(evaluated: bool, rate: &Option<MeanStd>) -> String {
    if evaluated && rate.is_none() {
        NOT_CHECKED.into()
    } else {
        pct(rate)
    }
}

const NOT_CHECKED: &str = "not checked";

/// The paper's cells (it reports no collisions: the last is always a dash).
fn paper_cells(p: &PaperRow) -> [String; 8] {
    if !p.converged() {
        return [
            "did not converge".into(),
            DASH.into(),
            DASH.into(),
            DASH.into(),
            DASH.into(),
            DASH.into(),
            DASH.into(),
            DASH.into(),
        ];
    }
    [
        opt(p.e_start, 1.0, 0),
        pair(p.train_reward, 3),
        opt(p.train_steps, 1.0, 0),
        pair(p.v_stdev, 3),
        opt(p.eval_reward, 1.0, 3),
        opt(p.eval_steps, 1.0, 0),
        p.success_rate.map_or_else(|| DASH.into(), |s| format!("{:.1} %", 100.0 * s)),
        DASH.into(),
    ]
}

fn seeds_cell(g: &GroupSummary) -> String {
    format!("{} ({} conv.)", g.seeds, g.converged)
}

/// Notes numbered across the document.
struct Notes(Vec<String>);

impl Notes {
    fn refs(&mut self, notes: &[String]) -> String {
        let mut r = Vec::new();
        for n in notes {
            let i = match self.0.iter().position(|x| x == n) {
                Some(i) => i,
                None => {
                    self.0.push(n.clone());
                    self.0.len() - 1
                }
            };
            r.push(format!("[{}]", i + 1));
        }
        r.join(" ")
    }
}

const HEADER: &str = "| Method | Reward | Source | Seeds | Episodes | E_start | Train reward R̄ (eq. 17) | Train steps | V_STDEV (eq. 17) | Eval reward | Eval steps | Success rate | Collision rate | Notes |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";

/// Table 1 as Markdown: for every algorithm and reward function, our row (mean ± std over seeds)
/// above the paper's; then the other configurations found and every run.
pub fn render_markdown(
    groups: &[GroupSummary],
    paper_rows: &[PaperRow],
    criterion: &ConvergenceCriterion,
    input: &str,
) -> String {
    let mut s = String::new();
    let mut notes = Notes(Vec::new());
    intro_markdown(&mut s, groups, criterion, input);
    primary_markdown(&mut s, groups, paper_rows, &mut notes);
    others_markdown(&mut s, groups, &mut notes);
    per_run_markdown(&mut s, groups);
    if !notes.0.is_empty() {
        let _ = writeln!(s, "\n## Notes\n");
        for (i, n) in notes.0.iter().enumerate() {
            let _ = writeln!(s, "{}. {n}", i + 1);
        }
    }
    s
}

/// The title and the paragraphs that explain the columns.
fn intro_markdown(s: &mut String, groups: &[GroupSummary], criterion: &ConvergenceCriterion, input: &str) {
    let _ = writeln!(s, "# Table 1: ours beside the paper's\n");
    let total_runs: usize = groups.iter().map(|g| g.seeds).sum();
    let _ = writeln!(
        s,
        "Runs read from `{input}`: {total_runs} in {} configuration group(s). Ours: mean ± sample std over seeds \
         (paper: over {} runs of {} episodes, {} evaluation trials). E_start and the training columns are over the \
         converged seeds only; train/eval steps are the mean steps of successful episodes; success rate and \
         evaluation reward come from each run's per-trial evaluation CSV. Checkpoint: the evaluation columns \
         evaluate the checkpoint each run's closing evaluation selected, the best periodic evaluation (our \
         addition; else the final one); the final checkpoint, the paper's protocol (\"the trained model\"), \
         is evaluated on the same targets in \"Best and final checkpoint\" below. Collision rate (our addition; \
         the paper has no collision measure): the fraction of evaluation trials in which the arm touched the \
         floor, itself or an obstacle at the end of some step; \"not checked\" where no contact was looked for \
         (an arm without collision shapes, or evaluations recorded before contacts were).\n",
        groups.len(),
        paper::PAPER_RUNS,
        paper::PAPER_EPISODES,
        paper::PAPER_EVAL_TRIALS,
    );
    let _ = writeln!(
        s,
        "E_start (the paper gives no formula): the first episode from which every {w}-episode window mean stays \
         within ± max({k} × std, {f}) of the mean of the last {t:.0} % of episodes (see `stagerl::report::metrics::ConvergenceCriterion`). \
         \"n.c.\": no seed converged.\n",
        w = criterion.window,
        k = criterion.band_k,
        f = criterion.band_floor,
        t = 100.0 * criterion.tail_fraction,
    );
}

/// The selected (best) and the final checkpoint of each primary group side by side, on the same
/// targets: mean ± std over the seeds that have both evaluations.
pub fn checkpoints_markdown(groups: &[GroupSummary]) -> String {
    let rows: Vec<&GroupSummary> = groups
        .iter()
        .filter(|g| g.primary && g.runs.iter().any(|r| r.eval_final_checkpoint.is_some()))
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "\n## Best and final checkpoint\n\nThe closing evaluation's targets for both: \"best\" is the checkpoint of \
         the best periodic evaluation (our addition, used by the table above and the claims), \"final\" the \
         trained model at the last episode (the paper's protocol).\n\n\
         | Method | Reward | Seeds | Success best | Success final | Eval reward best | Eval reward final | Eval steps best | Eval steps final |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let ms = |m: Option<MeanStd>, pct: bool| match m {
        None => "—".to_string(),
        Some(m) if pct => format!("{:.1} ± {:.1} %", 100.0 * m.mean, 100.0 * m.std.unwrap_or(0.0)),
        Some(m) => format!("{:.3} ± {:.3}", m.mean, m.std.unwrap_or(0.0)),
    };
    for g in rows {
        let both: Vec<(&EvalSummary, &EvalSummary)> = g
            .runs
            .iter()
            .filter_map(|r| Some((r.eval.as_ref()?, r.eval_final_checkpoint.as_ref()?)))
            .collect();
        let col = |f: &dyn Fn(&EvalSummary) -> Option<f64>, which: usize| {
            MeanStd::of_present(both.iter().map(|(b, l)| f(if which == 0 { b } else { l })))
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            algo_title(g.algo),
            reward_title(g.reward),
            both.len(),
            ms(col(&|e| Some(e.success_rate), 0), true),
            ms(col(&|e| Some(e.success_rate), 1), true),
            ms(col(&|e| Some(e.mean_reward), 0), false),
            ms(col(&|e| Some(e.mean_reward), 1), false),
            ms(col(&|e| e.mean_steps, 0), false),
            ms(col(&|e| e.mean_steps, 1), false),
        );
    }
    s
}

/// Our row above the paper's, for every algorithm and reward function.
fn primary_markdown(s: &mut String, groups: &[GroupSummary], paper_rows: &[PaperRow], notes: &mut Notes) {
    s.push_str(HEADER);
    let algos: Vec<Method> = ALGO_ORDER
        .into_iter()
        .filter(|a| {
            groups.iter().any(|g| g.algo == *a) || paper_rows.iter().any(|p| Method::from(p.algo) == *a)
        })
        .collect();
    for algo in algos {
        for reward in RewardFunction::ALL {
            let ours = primary(groups, algo, reward);
            let paper_row = paper::row(paper_rows, algo, reward);
            if ours.is_none() && paper_row.is_none() {
                continue;
            }
            let (m, r) = (algo_title(algo), reward_title(reward));
            match ours {
                Some(g) => {
                    let c = our_cells(g);
                    let mut ns = g.notes.clone();
                    if g.variant != "defaults" {
                        ns.insert(0, format!("configuration: {}", g.variant));
                    }
                    let _ = writeln!(
                        s,
                        "| {m} | {r} | ours | {} | {} | {} | {} |",
                        seeds_cell(g),
                        g.episodes,
                        c.join(" | "),
                        notes.refs(&ns)
                    );
                }
                None => {
                    let _ =
                        writeln!(s, "| {m} | {r} | ours | 0 | {DASH} | not run |  |  |  |  |  |  |  |  |");
                }
            }
            if let Some(p) = paper_row {
                let _ = writeln!(
                    s,
                    "| {m} | {r} | paper | {} | {} | {} |  |",
                    paper::PAPER_RUNS,
                    paper::PAPER_EPISODES,
                    paper_cells(p).join(" | ")
                );
            }
        }
    }
}

/// The groups of other configurations than the primary ones.
fn others_markdown(s: &mut String, groups: &[GroupSummary], notes: &mut Notes) {
    let others: Vec<&GroupSummary> = groups.iter().filter(|g| !g.primary).collect();
    if !others.is_empty() {
        let _ = writeln!(
            s,
            "\n## Other configurations\n\nGroups whose configuration differs from the one shown above for the same \
             algorithm and reward function (settings that differ from the defaults are listed).\n"
        );
        let _ = writeln!(
            s,
            "| Method | Reward | Configuration | Seeds | Episodes | E_start | Train reward R̄ | Train steps | V_STDEV | Eval reward | Eval steps | Success rate | Collision rate | Notes |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        );
        for g in others {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} |",
                algo_title(g.algo),
                reward_title(g.reward),
                g.variant,
                seeds_cell(g),
                g.episodes,
                our_cells(g).join(" | "),
                notes.refs(&g.notes)
            );
        }
    }
}

/// Every run's indicators.
fn per_run_markdown(s: &mut String, groups: &[GroupSummary]) {
    let _ = writeln!(s, "\n## Per run\n");
    let _ = writeln!(
        s,
        "| Run | Method | Reward | Seed | Episodes | Convergence | E_start | R̄ | V_STDEV | Train steps | Tail mean reward | Eval reward | Eval steps | Success rate | Collision rate |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for g in groups {
        for r in &g.runs {
            let t = r.train.as_ref();
            let e = r.eval.as_ref();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.3} | {} | {} | {} | {} |",
                r.name,
                algo_title(g.algo),
                reward_title(g.reward),
                r.seed,
                r.episodes,
                r.convergence.outcome.describe(),
                opt(t.map(|t| t.e_start as f64), 1.0, 0),
                opt(t.map(|t| t.mean_reward), 1.0, 3),
                opt(t.and_then(|t| t.v_stdev), 1.0, 3),
                opt(t.and_then(|t| t.mean_steps_success), 1.0, 1),
                r.tail_mean_reward,
                opt(e.map(|e| e.mean_reward), 1.0, 3),
                opt(e.and_then(|e| e.mean_steps), 1.0, 1),
                e.map_or_else(|| DASH.into(), |e| format!("{:.1} % of {}", 100.0 * e.success_rate, e.trials)),
                e.map_or_else(
                    || DASH.into(),
                    |e| match e.collision_rate {
                        Some(c) => format!("{:.1}", 100.0 * c),
                        None => NOT_CHECKED.into(),
                    }
                ),
            );
        }
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn csv_ms(v: &Option<MeanStd>, scale: f64) -> String {
    match v {
        None => ",".into(),
        Some(m) => {
            format!("{},{}", m.mean * scale, m.std.map(|s| (s * scale).to_string()).unwrap_or_default())
        }
    }
}

fn csv_opt(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// The CSV header of [`render_csv`].
pub const CSV_HEADER: &str = "source,algorithm,reward,configuration,primary,seeds,converged,episodes,e_start,e_start_std,train_reward,train_reward_std,train_steps,train_steps_std,v_stdev,v_stdev_std,eval_reward,eval_reward_std,eval_steps,eval_steps_std,success_rate_pct,success_rate_pct_std,collision_rate_pct,collision_rate_pct_std,notes";

/// A row of `table1.csv`: a group of ours (`source = ours`) or a row of the paper
/// (`source = paper`); empty fields are unknown or not applicable.
pub enum Table1Row<'a> {
    Ours(&'a GroupSummary),
    Paper(&'a PaperRow),
}

impl CsvRow for Table1Row<'_> {
    const HEADER: &'static str = CSV_HEADER;

    fn write_row(&self, s: &mut String) {
        match self {
            Table1Row::Ours(g) => write_ours(s, g),
            Table1Row::Paper(p) => write_paper(s, p),
        }
    }
}

fn write_ours(s: &mut String, g: &GroupSummary) {
    let _ = write!(
        s,
        "ours,{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        g.algo,
        g.reward,
        csv_field(&g.variant),
        u8::from(g.primary),
        g.seeds,
        g.converged,
        g.episodes,
        csv_ms(&g.e_start, 1.0),
        csv_ms(&g.train_reward, 1.0),
        csv_ms(&g.train_steps, 1.0),
        csv_ms(&g.v_stdev, 1.0),
        csv_ms(&g.eval_reward, 1.0),
        csv_ms(&g.eval_steps, 1.0),
        csv_ms(&g.success_rate, 100.0),
        csv_ms(&g.collision_rate, 100.0),
        csv_field(&g.notes.join("; "))
    );
}

fn write_paper(s: &mut String, p: &PaperRow) {
    let (tr, ts) = p.train_reward.unzip();
    let (vm, vs) = p.v_stdev.unzip();
    let _ = write!(
        s,
        "paper,{},{},paper,1,{},{},{},{},,{},{},{},,{},{},{},,{},,{},,,,{}",
        p.algo,
        p.reward,
        paper::PAPER_RUNS,
        if p.converged() { paper::PAPER_RUNS } else { 0 },
        paper::PAPER_EPISODES,
        csv_opt(p.e_start),
        csv_opt(tr),
        csv_opt(ts),
        csv_opt(p.train_steps),
        csv_opt(vm),
        csv_opt(vs),
        csv_opt(p.eval_reward),
        csv_opt(p.eval_steps),
        csv_opt(p.success_rate.map(|x| 100.0 * x)),
        if p.converged() { "" } else { "did not converge" }
    );
}

/// Table 1 as CSV: one row per group of ours, then one per row of the paper.
pub fn render_csv(groups: &[GroupSummary], paper_rows: &[PaperRow]) -> String {
    let rows: Vec<Table1Row<'_>> =
        groups.iter().map(Table1Row::Ours).chain(paper_rows.iter().map(Table1Row::Paper)).collect();
    to_csv(&rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_labels() {
        let mut c = Config::default();
        assert_eq!(variant_label(&c), "defaults");
        c.train.seed = 9;
        c.agent.algo = crate::agent::Algo::Ddpg;
        c.train.eval_trials = 7;
        assert_eq!(variant_label(&c), "defaults");
        c.agent.gamma = 0.99;
        c.train.episodes = 1500;
        assert_eq!(variant_label(&c), "agent.gamma=0.99, train.episodes=1500");
        c.agent.her = Some(crate::agent::HerConfig::default());
        assert_eq!(variant_label(&c), "HER (future, k=4), agent.gamma=0.99, train.episodes=1500");
    }

    #[test]
    fn csv_header_and_rows_have_the_same_width() {
        let rows = paper::table1();
        let text = render_csv(&[], &rows);
        let width = CSV_HEADER.split(',').count();
        for line in text.lines() {
            assert_eq!(line.split(',').count(), width, "{line}");
        }
    }
}
