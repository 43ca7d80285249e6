//! The reporting layer: from finished run directories alone (no training), our version of the
//! paper's Table 1 beside the paper's figures, the verdict on each claim of its section VI, and
//! Figures 7 and 8 and evaluation trajectories as PNG and SVG.
//!
//! - [`runs`]: finding and reading run directories;
//! - [`table`]: grouping over seeds, the indicators of [`crate::report::metrics`], Table 1 as Markdown/CSV;
//! - [`claims`]: the claims of section VI and our statistical verdicts;
//! - [`aggregate`]: IQM, probability of improvement and performance profiles over seeds;
//! - [`plot`], [`trajectory`]: the figures;
//! - [`paper`]: the paper's Table 1 (compiled in from `assets/paper/table1.csv`).
//!
//! [`generate`] does all of it and writes into one output directory.

pub mod aggregate;
pub mod archive;
pub mod claims;
pub mod method;
pub mod metrics;
pub mod paper;
pub mod plot;
pub mod reference;
pub mod runs;
pub mod sample_efficiency;
pub mod stats;
pub mod table;
pub mod trajectory;

use serde::Serialize;
use std::path::{Path, PathBuf};

use crate::report::metrics::ConvergenceCriterion;
use crate::{Error, Result};
use claims::Claim;
use paper::PaperRow;
use runs::SkippedRun;
use table::{Group, GroupSummary};
use trajectory::Rollouts;

/// What [`generate`] does.
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// Output directory (created if needed).
    pub out: PathBuf,
    pub criterion: ConvergenceCriterion,
    /// Evaluation trajectories to roll out for the best and the worst reward function; 0: none.
    pub trajectories: u32,
    /// Include runs with fewer episodes than configured (still training, or stopped).
    pub include_incomplete: bool,
    /// The command that asked for the report, recorded in `provenance.json` (the CLI's
    /// arguments; empty: a library call).
    pub command: Vec<String>,
}

impl ReportOptions {
    /// Defaults, writing into `out`.
    pub fn new(out: impl Into<PathBuf>) -> ReportOptions {
        ReportOptions {
            out: out.into(),
            criterion: ConvergenceCriterion::default(),
            trajectories: 5,
            include_incomplete: false,
            command: Vec::new(),
        }
    }
}

/// The rollouts drawn, without their paths.
#[derive(Clone, Debug, Serialize)]
pub struct TrajectorySummary {
    pub title: String,
    pub run: String,
    pub checkpoint: String,
    pub eval_seed: u64,
    pub trials: usize,
    pub reached: usize,
}

/// E_start of one group under another band width `band_k` (the other criterion fields as given).
#[derive(Clone, Debug, Serialize)]
pub struct Sensitivity {
    pub algo: crate::report::method::Method,
    pub reward: crate::reward::RewardFunction,
    pub variant: String,
    /// `(band_k, mean E_start over the converged seeds, converged seeds)`.
    pub e_start: Vec<(f64, Option<f64>, usize)>,
    pub seeds: usize,
}

/// The band widths of the sensitivity table.
pub const SENSITIVITY_BAND_K: [f64; 3] = [0.5, 1.0, 2.0];

/// E_start of every primary group for each of [`SENSITIVITY_BAND_K`].
pub fn sensitivity(groups: &[Group], criterion: &ConvergenceCriterion) -> Result<Vec<Sensitivity>> {
    criterion.validate()?;
    let mut out = Vec::new();
    for g in groups.iter().filter(|g| g.primary) {
        let mut row = Vec::new();
        for k in SENSITIVITY_BAND_K {
            let c = ConvergenceCriterion { band_k: k, ..*criterion };
            let mut starts = Vec::new();
            for r in &g.runs {
                let rewards: Vec<f64> = r.episodes.iter().map(|e| e.reward).collect();
                // Invalid rewards are reported by the table; here they count as not converged.
                if let Ok(Some(i)) = crate::report::metrics::e_start(&rewards, &c) {
                    starts.push(r.episodes[i as usize - 1].episode as f64);
                }
            }
            row.push((k, crate::base::math::mean(&starts), starts.len()));
        }
        out.push(Sensitivity {
            algo: g.algo,
            reward: g.reward,
            variant: g.variant.clone(),
            e_start: row,
            seeds: g.runs.len(),
        });
    }
    Ok(out)
}

/// The sensitivity table as Markdown.
pub fn render_sensitivity(rows: &[Sensitivity], criterion: &ConvergenceCriterion) -> String {
    let mut s = format!(
        "\n## Sensitivity of E_start to the band\n\nMean E_start over the converged seeds (converged/seeds) \
         with the band half-width max(k × std, {}) for other k; Table 1 and the claims use k = {}.\n\n| Method | Reward |",
        criterion.band_floor, criterion.band_k
    );
    for k in SENSITIVITY_BAND_K {
        s.push_str(&format!(" k = {k} |"));
    }
    s.push_str("\n|---|---|");
    s.push_str(&"---|".repeat(SENSITIVITY_BAND_K.len()));
    s.push('\n');
    for r in rows {
        s.push_str(&format!("| {} | {} |", table::algo_title(r.algo), table::reward_title(r.reward)));
        for (_, m, n) in &r.e_start {
            match m {
                Some(m) => s.push_str(&format!(" {m:.0} ({n}/{}) |", r.seeds)),
                None => s.push_str(&format!(" — (0/{}) |", r.seeds)),
            }
        }
        s.push('\n');
    }
    s
}

/// Everything the report found, as written to `table1.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub input: PathBuf,
    pub criterion: ConvergenceCriterion,
    /// Every (algorithm, reward function, configuration) group, per run and over seeds.
    pub groups: Vec<GroupSummary>,
    pub paper: Vec<PaperRow>,
    pub claims: Vec<Claim>,
    /// IQM, probability of improvement and performance profiles over seeds.
    pub aggregates: aggregate::Aggregates,
    /// Environment steps to 95 % success, for runs on a budget of environment steps.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sample_efficiency: Vec<sample_efficiency::Row>,
    /// The study in one line: regime, seeds, episodes.
    pub study: String,
    /// The scripted Jacobian controller on the same targets, per reward function.
    pub reference: Vec<reference::ReferenceRow>,
    /// E_start of the primary groups under other band widths.
    pub sensitivity: Vec<Sensitivity>,
    /// Directories that looked like runs but could not be read.
    pub skipped: Vec<SkippedRun>,
    pub trajectories: Vec<TrajectorySummary>,
    /// Problems that did not stop the report (a trajectory that could not be computed, ...).
    pub warnings: Vec<String>,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Read every run under `dir` and group them (see [`table::group_runs`]).
pub fn load_groups(dir: &Path, include_incomplete: bool) -> Result<(Vec<Group>, Vec<SkippedRun>)> {
    let mut loaded = Vec::new();
    let mut skipped = Vec::new();
    for run_dir in runs::discover(dir)? {
        match runs::load_run(&run_dir, dir) {
            Ok(r) => loaded.push(r),
            Err(e) => skipped.push(SkippedRun {
                name: run_dir.strip_prefix(dir).unwrap_or(&run_dir).display().to_string(),
                reason: e.to_string(),
            }),
        }
    }
    Ok((table::group_runs(loaded, include_incomplete), skipped))
}

/// The analysis without writing anything: groups, their indicators and the claims.
pub fn analyze(
    dir: &Path,
    criterion: &ConvergenceCriterion,
    include_incomplete: bool,
) -> Result<(Vec<Group>, Report)> {
    analyze_named(dir, &dir_name(dir), criterion, include_incomplete)
}

/// How outputs name an input directory: by its own name, not an absolute path of this machine.
fn dir_name(dir: &Path) -> String {
    dir.file_name().map_or_else(|| ".".into(), |n| n.to_string_lossy().into_owned())
}

/// [`analyze`], the input named `name` in the outputs (an archive's unpacked folder is named
/// after the archive, not after the folder inside it).
fn analyze_named(
    dir: &Path,
    name: &str,
    criterion: &ConvergenceCriterion,
    include_incomplete: bool,
) -> Result<(Vec<Group>, Report)> {
    criterion.validate()?;
    let (groups, skipped) = load_groups(dir, include_incomplete)?;
    let summaries = groups.iter().map(|g| table::summarize(g, criterion)).collect::<Result<Vec<_>>>()?;
    let paper_rows = paper::table1();
    let claims = claims::evaluate(&summaries, &paper_rows);
    let aggregates = aggregate::compute(&summaries);
    let sample_efficiency = sample_efficiency::compute(&groups);
    let sensitivity = sensitivity(&groups, criterion)?;
    let study = reference::study_line(&groups, name);
    let reference = reference::evaluate(&groups, &summaries)?;
    let report = Report {
        input: PathBuf::from(name),
        criterion: *criterion,
        groups: summaries,
        paper: paper_rows,
        aggregates,
        sample_efficiency,
        study,
        reference,
        claims,
        sensitivity,
        skipped,
        trajectories: Vec::new(),
        warnings: Vec::new(),
        files: Vec::new(),
    };
    Ok((groups, report))
}

/// `table1.md`: the table, the study line, the reference rows, the E_start sensitivity, the
/// directories not read and the provenance.
fn table1_markdown(dir: &Path, report: &Report, opts: &ReportOptions) -> Result<String> {
    // Outputs name the input by its directory name, not an absolute path of this machine.
    let input = report.input.display().to_string();
    let mut md = table::render_markdown(&report.groups, &report.paper, &opts.criterion, &input);
    md.insert_str(md.find('\n').map_or(0, |i| i + 1), &format!("\n{}\n", report.study));
    md.push_str(&table::checkpoints_markdown(&report.groups));
    md.push_str(&reference::render_markdown(&report.reference));
    if !report.sensitivity.is_empty() {
        md.push_str(&render_sensitivity(&report.sensitivity, &opts.criterion));
    }
    if !report.skipped.is_empty() {
        md.push_str("\n## Directories not read\n\n");
        for s in &report.skipped {
            md.push_str(&format!("- `{}`: {}\n", s.name, s.reason));
        }
    }
    md.push_str(&provenance_markdown(dir)?);
    Ok(md)
}

/// Where the runs came from (the sweep's `provenance.json`, if any) and what writes this report.
fn provenance_markdown(dir: &Path) -> Result<String> {
    let sweep = crate::run::provenance::Provenance::load(dir)?;
    let mut s = if sweep.sessions.is_empty() {
        "\n## Provenance\n\nThe input directory has no `provenance.json` (not written by `stagerl reproduce`): \
         the code version of its runs is unknown.\n"
            .to_string()
    } else {
        sweep.render_markdown()
    };
    s.push_str(&format!(
        "\nThis report: `{}`; `provenance.json` beside it lists every command with its times.\n",
        crate::run::provenance::Code::current().describe()
    ));
    Ok(s)
}

/// Most evaluation trajectories a report draws per figure ([`ReportOptions::trajectories`]).
pub const MAX_TRAJECTORIES: u32 = 1000;

/// The runs whose trajectories are drawn: for the algorithm with the most reward functions run,
/// the lowest seed of its best and of its worst reward function (by evaluation success rate, then
/// evaluation reward, then the tail's mean training reward), among runs with a checkpoint.
/// Each pick is `(run, "best" or "worst", the group's mean evaluation success rate)`.
pub fn pick_trajectory_runs<'a>(
    groups: &'a [Group],
    summaries: &[GroupSummary],
) -> Vec<(&'a runs::RunData, &'static str, Option<f64>)> {
    fn has_ckpt(g: &Group) -> Option<&runs::RunData> {
        g.runs.iter().find(|r| crate::run::dir::RunDir::new(&r.dir).best_available_checkpoint().is_some())
    }
    let candidates: Vec<(&Group, &GroupSummary)> =
        groups.iter().zip(summaries).filter(|(g, _)| g.primary && has_ckpt(g).is_some()).collect();
    let algo = table::ALGO_ORDER
        .into_iter()
        .enumerate()
        .max_by_key(|(i, a)| (candidates.iter().filter(|(g, _)| g.algo == *a).count(), std::cmp::Reverse(*i)))
        .map(|(_, a)| a);
    let Some(algo) = algo else { return Vec::new() };
    let score = |s: &GroupSummary| {
        let tail = crate::base::math::mean(&s.runs.iter().map(|r| r.tail_mean_reward).collect::<Vec<_>>());
        (
            s.success_rate.map_or(-1.0, |m| m.mean),
            s.eval_reward.map_or(f64::NEG_INFINITY, |m| m.mean),
            tail.unwrap_or(f64::NEG_INFINITY),
        )
    };
    let mut ranked: Vec<&(&Group, &GroupSummary)> =
        candidates.iter().filter(|(g, _)| g.algo == algo).collect();
    ranked.sort_by(|a, b| score(b.1).partial_cmp(&score(a.1)).unwrap_or(std::cmp::Ordering::Equal));
    let mut out: Vec<(&runs::RunData, &'static str, Option<f64>)> = Vec::new();
    for (role, pick) in [("best", ranked.first()), ("worst", ranked.last())] {
        if let Some((g, s)) = pick {
            if let Some(r) = has_ckpt(g) {
                if !out.iter().any(|o| o.0.dir == r.dir) {
                    out.push((r, role, s.success_rate.map(|m| m.mean)));
                }
            }
        }
    }
    out
}

/// Read the runs under `dir` and write the report into `opts.out`: `table1.md`, `table1.csv`,
/// `table1.json`, `claims.md`, `figure7.{png,svg}`, `figure8.{png,svg}` and, when
/// `opts.trajectories > 0` and a checkpoint exists, `trajectories.{png,svg,csv}` and
/// `view-best.html`, `view-worst.html` (animated 3D views of those runs' plans).
///
/// `dir` may also be a study's `runs.tar.xz` ([`archive`]): it is unpacked into a temporary
/// directory, reported on as the folder it holds, and removed.
pub fn generate(dir: &Path, opts: &ReportOptions) -> Result<Report> {
    let clock = crate::run::provenance::Clock::now();
    check_options(dir, opts)?;
    if archive::is_archive(dir) && !dir.is_dir() {
        let unpacked = archive::unpack(dir)?;
        return generate_from(&unpacked.root, &archive::display_name(dir), opts, clock);
    }
    generate_from(dir, &dir_name(dir), opts, clock)
}

/// The report of the runs under `dir`, named `name` in its outputs.
fn generate_from(
    dir: &Path,
    name: &str,
    opts: &ReportOptions,
    clock: crate::run::provenance::Clock,
) -> Result<Report> {
    let (groups, mut report) = analyze_named(dir, name, &opts.criterion, opts.include_incomplete)?;
    if groups.is_empty() {
        return Err(no_runs(dir, &report));
    }
    std::fs::create_dir_all(&opts.out).map_err(|e| Error::io(&opts.out, e))?;
    let out = |name: &str| opts.out.join(name);
    let mut files = Vec::new();
    let mut write = |name: &str, text: &str| -> Result<()> {
        let p = out(name);
        crate::io::write_atomic(&p, text.as_bytes())?;
        files.push(p);
        Ok(())
    };
    let md = table1_markdown(dir, &report, opts)?;
    write("table1.md", &md)?;
    write("table1.csv", &table::render_csv(&report.groups, &report.paper))?;
    let mut claims_md = claims::render_markdown(&report.claims);
    claims_md.insert_str(claims_md.find('\n').map_or(0, |i| i + 1), &format!("\n{}\n", report.study));
    claims_md.push_str(&reference::render_markdown(&report.reference));
    write("claims.md", &claims_md)?;
    write("aggregates.md", &aggregate::render_markdown(&report.aggregates))?;
    if !report.sample_efficiency.is_empty() {
        write(
            "sample_efficiency.md",
            &sample_efficiency::render_markdown(&report.sample_efficiency, &report.study),
        )?;
    }

    let figure7 = plot::figure7(&groups, &report.groups, opts.criterion.window, &report.study);
    files.extend(plot::save(&figure7, &out("figure7"))?);
    let controller = report
        .reference
        .iter()
        .find(|r| r.reward == crate::reward::RewardFunction::Sar)
        .or(report.reference.first());
    files.extend(plot::save(
        &plot::figure8(&groups, &report.study, controller.map(|r| &r.summary)),
        &out("figure8"),
    )?);
    files.extend(plot::save(
        &plot::profile_figure(&report.aggregates, &report.study),
        &out("performance_profile"),
    )?);

    if opts.trajectories > 0 {
        files.extend(write_trajectories(dir, &groups, &mut report, opts)?);
    }
    let command =
        if opts.command.is_empty() { vec!["(library call)".to_string()] } else { opts.command.clone() };
    crate::run::provenance::record_report(dir, &opts.out, command, clock)?;
    files.push(out(crate::run::provenance::FILE));
    let json_path = out("table1.json");
    files.push(json_path.clone());
    // Named relative to the output directory, as the trajectories' checkpoints are relative to
    // the input directory: the outputs hold no path of the machine that wrote them.
    report.files = files.iter().map(|p| p.strip_prefix(&opts.out).unwrap_or(p).to_path_buf()).collect();
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::InvalidInput(format!("report JSON: {e}")))?;
    crate::io::write_atomic(&json_path, json.as_bytes())?;
    Ok(report)
}

/// The evaluation trajectories of the best and the worst run (`trajectories.{png,svg,csv}`) and
/// their animated 3D views (`view-best.html`, `view-worst.html`, the same targets planned from
/// the home pose, at most [`crate::view::MAX_TRAJECTORIES`]); the files written.
fn write_trajectories(
    dir: &Path,
    groups: &[Group],
    report: &mut Report,
    opts: &ReportOptions,
) -> Result<Vec<PathBuf>> {
    let out = |name: &str| opts.out.join(name);
    let mut files = Vec::new();
    let mut sets: Vec<Rollouts> = Vec::new();
    for (run, role, success) in pick_trajectory_runs(groups, &report.groups) {
        let seed = run.final_eval.as_ref().map_or(run.config.train.eval_seed, |f| f.seed);
        match trajectory::rollout(run, opts.trajectories, seed) {
            Ok(mut r) => {
                let rate = success
                    .map(|s| format!(", group's evaluation success {:.1} %", 100.0 * s))
                    .unwrap_or_default();
                r.title = format!("{role}: {}{rate}", r.title);
                let count = opts.trajectories.min(crate::view::MAX_TRAJECTORIES as u32);
                let source = crate::view::ViewSource::Targets { count, seed };
                let ckpt = dir.join(&r.checkpoint);
                match crate::view::view_of_run(&crate::run::dir::RunDir::new(&run.dir), Some(&ckpt), &source)
                {
                    Ok(mut v) => {
                        v.title = r.title.clone();
                        let p = out(&format!("view-{role}.html"));
                        crate::io::write_atomic(&p, v.to_html()?.as_bytes())?;
                        files.push(p);
                    }
                    Err(e) => report.warnings.push(format!("3D view of {}: {e}", run.name)),
                }
                sets.push(r)
            }
            Err(e) => report.warnings.push(format!("trajectories of {}: {e}", run.name)),
        }
    }
    if sets.is_empty() {
        report.warnings.push("no trajectories drawn: no run with a loadable checkpoint".into());
        return Ok(files);
    }
    crate::io::write_atomic(&out("trajectories.csv"), trajectory::to_csv(&sets).as_bytes())?;
    files.push(out("trajectories.csv"));
    files.extend(plot::save(&plot::TrajectoryFigure { sets: sets.clone() }, &out("trajectories"))?);
    report.trajectories = sets
        .iter()
        .map(|s| TrajectorySummary {
            title: s.title.clone(),
            run: s.run.clone(),
            checkpoint: s.checkpoint.clone(),
            eval_seed: s.eval_seed,
            trials: s.paths.len(),
            reached: s.paths.iter().filter(|p| p.success).count(),
        })
        .collect();
    Ok(files)
}

/// The checks of [`generate`] made before anything is written, so that a report is written whole
/// or not at all: UTF-8 paths, a bounded number of trajectories.
fn check_options(dir: &Path, opts: &ReportOptions) -> Result<()> {
    for (what, p) in [("output directory", opts.out.as_path()), ("run directory", dir)] {
        if p.to_str().is_none() {
            return Err(Error::InvalidInput(format!(
                "the report's {what} {} is not valid UTF-8 (the report records its paths as text); choose another",
                p.display()
            )));
        }
    }
    if opts.trajectories > MAX_TRAJECTORIES {
        return Err(Error::config(
            "trajectories",
            opts.trajectories,
            format!("0 to {MAX_TRAJECTORIES} evaluation trajectories per figure"),
        ));
    }
    Ok(())
}

/// The error for a directory without any run.
fn no_runs(dir: &Path, report: &Report) -> Error {
    let skipped = match report.skipped.first() {
        None => String::new(),
        Some(first) => format!(
            " ({} directories not read, e.g. `{}`: {})",
            report.skipped.len(),
            first.name,
            first.reason
        ),
    };
    Error::InvalidInput(format!(
        "{}: no runs to report on: a run directory holds config.toml and episodes.csv, at depth 1 or 2{skipped}",
        dir.display()
    ))
}
