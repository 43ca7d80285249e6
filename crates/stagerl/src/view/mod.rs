//! The HTML 3D view of planned trajectories: one self-contained file (no network access, no
//! JavaScript library: the renderer, a hand-written canvas-2D one, is in `template.html`,
//! included at build time) that draws the arm as capsules between its joint frames (from the
//! URDF chain, [`Chain::joint_origins`]), the target ball of radius beta and the end-effector
//! path, and animates each plan at real time (one step per control period) with play/pause, a
//! step slider, a trajectory selector and an orbit camera (drag; wheel to zoom).
//!
//! Positions in the embedded JSON are rounded to 0.1 mm (the drawing needs no more; the file
//! stays small): [`View::trajectories`] holds them at full precision.

use serde::Serialize;
use std::path::Path;

use crate::config::Config;
use crate::env::ReachEnv;
use crate::plan::{Plan, PlanRequest, Planner};
use crate::robot::Chain;
use crate::run::dir::RunDir;
use crate::sim::collision::{ArmCollider, Checks};
use crate::sim::scene::Obstacle;
use crate::{Error, Result};

/// The page, with `/*STAGERL_DATA*/` where the JSON goes.
const TEMPLATE: &str = include_str!("template.html");
const DATA_MARK: &str = "/*STAGERL_DATA*/";

/// Most trajectories one view holds (a plan of 200 steps on a 6-joint arm is ~30 kB of JSON).
pub const MAX_TRAJECTORIES: usize = 500;

/// The largest plans file read, bytes (1 MiB holds thousands of requests, more than a view shows).
pub const MAX_PLANS_FILE_BYTES: u64 = 1 << 20;

/// Radius of the capsules drawn for the links, metres.
pub const LINK_RADIUS_M: f64 = 0.035;

/// One planned trajectory of a view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewTrajectory {
    pub label: String,
    /// Metres, base frame.
    pub target: [f64; 3],
    pub reached: bool,
    pub steps: u32,
    pub final_distance: f64,
    /// Rows of the plan per frame: 1, or more for a plan of over [`MAX_FRAMES`] rows, of which
    /// every `stride`-th row is kept (and the last).
    pub stride: usize,
    /// Per kept row of the plan, the arm's skeleton: the joint-frame origins then the tip (metres).
    pub frames: Vec<Vec<[f64; 3]>>,
    /// Distance to the target per kept row, metres.
    pub distance: Vec<f64>,
    /// The plan's scene (the schema of `[[task.obstacles]]`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<Obstacle>,
    /// The plan's collision report (see [`crate::plan::PlanSummary`]).
    pub collision: bool,
    pub min_clearance_m: Option<f64>,
    /// The closest approach of the arm to the obstacles over the kept rows: the frame (index
    /// into `frames`) and its points.
    pub closest: Option<ViewClosest>,
    /// The first contact along the path: the first frame at or after it and what touched what
    /// (links named as in the URDF).
    pub contact: Option<ViewContact>,
}

/// The closest approach of a trajectory (see [`ViewTrajectory::closest`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewClosest {
    pub frame: usize,
    pub distance_m: f64,
    pub arm_point_m: [f64; 3],
    pub obstacle_point_m: [f64; 3],
}

/// The first contact of a trajectory (see [`ViewTrajectory::contact`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewContact {
    pub frame: usize,
    pub step: usize,
    pub what: String,
}

/// Most frames a trajectory of a view keeps (a longer plan is shown every `stride`-th row): what
/// a view holds stays bounded whatever `--max-steps` a plan ran with (500 trajectories of 8
/// joint frames: about 100 MB at most, where every row of 500 plans of 10^6 steps would be
/// hundreds of GB).
pub const MAX_FRAMES: usize = 1000;

/// The rows of a plan of `rows` rows a view keeps: every `stride`-th, and the last.
fn kept_rows(rows: usize) -> (usize, Vec<usize>) {
    let stride = rows.div_ceil(MAX_FRAMES).max(1);
    let mut kept: Vec<usize> = (0..rows).step_by(stride).collect();
    if rows > 0 && kept.last() != Some(&(rows - 1)) {
        kept.push(rows - 1);
    }
    (stride, kept)
}

/// What a view shows (serialised into the page).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct View {
    pub title: String,
    /// Control period, seconds: the animation shows one row per period.
    pub dt_s: f64,
    /// Radius of the target ball, metres.
    pub beta_m: f64,
    pub link_radius_m: f64,
    /// The point the camera orbits (the middle of the arm's reach), metres.
    pub center: [f64; 3],
    /// The arm's reach, metres (the camera's scale).
    pub extent_m: f64,
    /// The arm's chain: its root and tip links, named as in the URDF.
    pub arm: String,
    pub trajectories: Vec<ViewTrajectory>,
}

fn round_mm10(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

impl View {
    /// An empty view of `chain` for plans with control period `dt_s` and success radius `beta_m`.
    pub fn new(title: &str, chain: &Chain, dt_s: f64, beta_m: f64) -> View {
        let o = chain.first_joint_origin();
        let reach = chain.reach_m();
        View {
            title: title.into(),
            dt_s,
            beta_m,
            link_radius_m: LINK_RADIUS_M.min(reach / 20.0),
            center: [o.x, o.y, (o.z + reach / 4.0).max(0.0)],
            extent_m: reach,
            arm: format!("{} to {}", chain.base_link(), chain.tip_link()),
            trajectories: Vec::new(),
        }
    }

    /// An empty view of the plans of `planner` (its arm, control period and success radius).
    pub fn for_planner(title: &str, planner: &Planner) -> View {
        let env = planner.env();
        View::new(title, env.chain(), env.task().dt_s, env.reward_config().beta_m)
    }

    /// Add `plan` (to `target`, metres) under `label`, without obstacles, contacts looked for
    /// with the default checks; at most [`MAX_TRAJECTORIES`].
    pub fn push(&mut self, chain: &Chain, label: &str, target: [f64; 3], plan: &Plan) -> Result<()> {
        self.push_in_scene(chain, Checks::default(), &[], label, target, plan)
    }

    /// Add a plan of `planner` (its last): its scene and the task's checks.
    pub fn push_planned(
        &mut self,
        planner: &Planner,
        label: &str,
        target: [f64; 3],
        plan: &Plan,
    ) -> Result<()> {
        let env = planner.env();
        self.push_in_scene(env.chain(), env.task().collision, env.obstacles(), label, target, plan)
    }

    /// Add `plan` (to `target`, metres) among `obstacles`, contacts looked for with `checks`,
    /// under `label`; at most [`MAX_TRAJECTORIES`].
    pub fn push_in_scene(
        &mut self,
        chain: &Chain,
        checks: Checks,
        obstacles: &[Obstacle],
        label: &str,
        target: [f64; 3],
        plan: &Plan,
    ) -> Result<()> {
        if self.trajectories.len() >= MAX_TRAJECTORIES {
            return Err(Error::InvalidInput(format!(
                "a view holds at most {MAX_TRAJECTORIES} trajectories; `{label}` would be one more"
            )));
        }
        let (stride, kept) = kept_rows(plan.rows());
        let frames = kept
            .iter()
            .map(|&k| chain.joint_origins(&plan.q[k * plan.dof..(k + 1) * plan.dof]))
            .collect::<Result<_>>()?;
        let mut c = ArmCollider::new(chain, checks);
        c.set_obstacles(obstacles);
        let row = |k: usize| &plan.q[k * plan.dof..(k + 1) * plan.dof];
        let closest = kept
            .iter()
            .enumerate()
            .filter_map(|(f, &k)| c.closest_obstacle(chain, row(k)).map(|x| (f, x)))
            .min_by(|a, b| a.1.distance_m.total_cmp(&b.1.distance_m))
            .map(|(frame, x)| ViewClosest {
                frame,
                distance_m: x.distance_m,
                arm_point_m: x.arm_point_m,
                obstacle_point_m: x.obstacle_point_m,
            });
        let contact = (0..plan.rows())
            .find_map(|k| {
                let hit =
                    if k == 0 { c.check(chain, row(0)) } else { c.check_motion(chain, row(k - 1), row(k)) };
                hit.map(|h| (k, h))
            })
            .map(|(step, h)| ViewContact {
                frame: kept.iter().position(|&r| r >= step).unwrap_or(kept.len() - 1),
                step,
                what: h.describe(chain),
            });
        self.trajectories.push(ViewTrajectory {
            label: label.into(),
            target,
            reached: plan.summary.reached,
            steps: plan.summary.steps,
            final_distance: plan.summary.final_distance,
            stride,
            frames,
            distance: kept.iter().map(|&k| plan.distance[k]).collect(),
            obstacles: obstacles.to_vec(),
            collision: plan.summary.collision,
            min_clearance_m: plan.summary.min_clearance_m,
            closest,
            contact,
        });
        Ok(())
    }

    /// The page: the template with this view as JSON (positions rounded to 0.1 mm).
    pub fn to_html(&self) -> Result<String> {
        let mut rounded = self.clone();
        for t in &mut rounded.trajectories {
            t.frames.iter_mut().flatten().flatten().for_each(|v| *v = round_mm10(*v));
            t.distance.iter_mut().for_each(|v| *v = round_mm10(*v));
            if let Some(c) = &mut t.closest {
                c.arm_point_m.iter_mut().chain(&mut c.obstacle_point_m).for_each(|v| *v = round_mm10(*v));
            }
        }
        let json = serde_json::to_string(&rounded)
            .map_err(|e| Error::InvalidInput(format!("the view's data does not serialise: {e}")))?;
        // `<` only occurs inside JSON strings, where `\u003c` means the same: no `</script>`.
        Ok(TEMPLATE.replacen(DATA_MARK, &json.replace('<', "\\u003c"), 1))
    }
}

/// Where the plans of a run's view come from.
#[derive(Clone, Debug, PartialEq)]
pub enum ViewSource {
    /// The first `count` targets of evaluation seed `seed` (those `stagerl eval --seed` uses),
    /// each from the home pose.
    Targets { count: u32, seed: u64 },
    /// Plan requests, one JSON object per line as `stagerl plan --targets` reads them; the
    /// path names the file in errors.
    Requests { text: String, origin: String },
}

/// The first `count` targets of evaluation seed `seed` on the task of `cfg`, metres.
pub fn eval_targets(cfg: &Config, count: u32, seed: u64) -> Result<Vec<[f64; 3]>> {
    let mut env = ReachEnv::from_config(cfg, 0)?;
    let mut out = Vec::with_capacity(count as usize);
    for i in 0..count {
        if i == 0 {
            env.reset_with_seed(seed);
        } else {
            env.reset();
        }
        let t = env.target();
        out.push([t.x, t.y, t.z]);
    }
    Ok(out)
}

/// Parse plan requests, one JSON object per non-blank line, each with its 1-based line number;
/// an error names the line.
pub fn parse_requests(text: &str, origin: &str) -> Result<Vec<(usize, PlanRequest)>> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let r: PlanRequest = serde_json::from_str(line).map_err(|e| {
            let text = e.to_string();
            let what = text.rsplit_once(" at line ").map_or(text.as_str(), |(w, _)| w);
            Error::InvalidInput(format!(
                "{origin} line {}, column {}: {what} (expected {{\"target\":[x,y,z]}} or \
                 {{\"target\":[x,y,z],\"start\":[q1,..]}})",
                i + 1,
                e.column()
            ))
        })?;
        out.push((i + 1, r));
    }
    if out.is_empty() {
        return Err(Error::InvalidInput(format!(
            "{origin} holds no plan request (one JSON object per line)"
        )));
    }
    Ok(out)
}

/// The view of a run's policy (its `checkpoint`, else the best available) on `source`'s plans.
pub fn view_of_run(run: &RunDir, checkpoint: Option<&Path>, source: &ViewSource) -> Result<View> {
    let cfg = run.load_config()?;
    let requests = match source {
        ViewSource::Targets { count, seed } => {
            let n = *count as usize;
            if n == 0 || n > MAX_TRAJECTORIES {
                return Err(Error::InvalidInput(format!(
                    "{count} targets: a view shows 1 to {MAX_TRAJECTORIES} trajectories"
                )));
            }
            let targets = eval_targets(&cfg, *count, *seed)?;
            let requests =
                targets.into_iter().map(|t| PlanRequest { target: t.to_vec(), start: None, obstacles: None });
            requests.enumerate().map(|(i, r)| (i + 1, r)).collect()
        }
        ViewSource::Requests { text, origin } => parse_requests(text, origin)?,
    };
    if requests.len() > MAX_TRAJECTORIES {
        return Err(Error::InvalidInput(format!(
            "{} plan requests: a view shows 1 to {MAX_TRAJECTORIES} trajectories",
            requests.len()
        )));
    }
    let (path, mut planner) = Planner::from_run(run, checkpoint, None)?;
    let title = format!("{} {} ({})", cfg.agent.algo.name(), cfg.reward.function.name(), path.display());
    let mut view = View::for_planner(&title, &planner);
    for (line, r) in &requests {
        let (label, plan) = match source {
            ViewSource::Requests { origin, .. } => (
                format!("line {line}"),
                planner.plan_request(r).map_err(|e| match e {
                    Error::InvalidInput(m) => Error::InvalidInput(format!("{origin} line {line}: {m}")),
                    other => other,
                })?,
            ),
            ViewSource::Targets { .. } => (format!("target {line}"), planner.plan_request(r)?),
        };
        view.push_planned(&planner, &label, [r.target[0], r.target[1], r.target[2]], &plan)?;
    }
    Ok(view)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn a_view_embeds_its_plans_as_json_and_nothing_closes_the_script_early() {
        let cfg = Config::default();
        let mut planner = Planner::jacobian(&cfg, None).unwrap();
        let target = [0.4, 0.2, 0.3];
        let plan = planner.plan(&target, None).unwrap();
        let chain = planner.env().chain().clone();
        let mut view = View::for_planner("a </script><b> title", &planner);
        view.push(&chain, "plan", target, &plan).unwrap();
        let t = &view.trajectories[0];
        assert_eq!(t.frames.len(), plan.rows());
        for (f, ee) in t.frames.iter().zip(&plan.ee_pos) {
            assert_eq!(f.len(), chain.dof() + 1);
            assert!((Vector3::from(f[chain.dof()]) - Vector3::from(*ee)).norm() < 1e-12);
        }
        assert_eq!((view.dt_s, view.beta_m), (cfg.task.dt_s, cfg.reward.beta_m));
        let html = view.to_html().unwrap();
        assert_eq!(html.matches("</script>").count(), TEMPLATE.matches("</script>").count());
        assert!(!html.contains(DATA_MARK));
        let start = html.find("application/json\">").unwrap() + "application/json\">".len();
        let end = start + html[start..].find("</script>").unwrap();
        let data: serde_json::Value = serde_json::from_str(&html[start..end]).unwrap();
        assert_eq!(data["title"], "a </script><b> title");
        let x = data["trajectories"][0]["frames"][3][6][0].as_f64().unwrap();
        assert!((x - t.frames[3][6][0]).abs() <= 0.5e-4 && (x * 1e4 - (x * 1e4).round()).abs() < 1e-6);
        // At most MAX_TRAJECTORIES.
        view.trajectories = vec![t.clone(); MAX_TRAJECTORIES];
        let e = view.push(&chain, "one more", target, &plan).unwrap_err().to_string();
        assert!(e.contains("at most 500") && e.contains("one more"), "{e}");
    }

    #[test]
    fn a_long_plan_is_kept_as_at_most_max_frames_frames() {
        let cfg = Config::default();
        let mut planner = Planner::jacobian(&cfg, None).unwrap();
        let target = [0.4, 0.2, 0.3];
        let short = planner.plan(&target, None).unwrap();
        // A plan of 100 001 rows (the short one's rows over and over), 100 000 steps.
        let rows = 100_001;
        let mut long = short.clone();
        let (dof, n) = (short.dof, short.rows());
        long.q = (0..rows).flat_map(|k| short.q[(k % n) * dof..(k % n + 1) * dof].to_vec()).collect();
        long.joint_vel = long.q.clone();
        long.distance = (0..rows).map(|k| k as f64).collect();
        long.reward = vec![0.0; rows];
        long.ee_pos = (0..rows).map(|k| short.ee_pos[k % n]).collect();
        long.ee_quat = (0..rows).map(|k| short.ee_quat[k % n]).collect();
        long.summary.steps = (rows - 1) as u32;
        assert_eq!(long.rows(), rows);
        let chain = planner.env().chain().clone();
        let mut view = View::for_planner("long", &planner);
        view.push(&chain, "long", target, &long).unwrap();
        view.push(&chain, "short", target, &short).unwrap();
        let t = &view.trajectories[0];
        assert_eq!(t.stride, 101, "100 001 rows in frames of 101 rows");
        assert!(t.frames.len() <= MAX_FRAMES + 1 && t.frames.len() == t.distance.len(), "{}", t.frames.len());
        // Every 101st row, then the last.
        assert_eq!(&t.distance[..3], [0.0, 101.0, 202.0]);
        assert_eq!(*t.distance.last().unwrap(), 100_000.0);
        // A short plan keeps every row.
        let s = &view.trajectories[1];
        assert_eq!((s.stride, s.frames.len()), (1, short.rows()));
        let html = view.to_html().unwrap();
        assert!(html.len() < 1 << 20, "{} bytes", html.len());
    }

    #[test]
    fn requests_are_read_with_their_line_numbers() {
        let text = "{\"target\":[0.4,0.2,0.3]}\n\n  \n{\"target\":[0.1,0.2,0.3],\"start\":[0,0,0,0,0,0]}\n";
        let r = parse_requests(text, "p.jsonl").unwrap();
        assert_eq!(r.iter().map(|(l, _)| *l).collect::<Vec<_>>(), [1, 4]);
        assert_eq!(r[1].1.start.as_deref(), Some(&[0.0; 6][..]));
        let e =
            parse_requests("{\"target\":[1,2,3]}\n{\"target\":[1,2,\n", "p.jsonl").unwrap_err().to_string();
        assert!(e.contains("p.jsonl line 2, column") && !e.contains(" at line "), "{e}");
        let e = parse_requests("\n", "p.jsonl").unwrap_err().to_string();
        assert!(e.contains("holds no plan request"), "{e}");
    }

    #[test]
    fn eval_targets_are_the_evaluations_targets() {
        let cfg = Config::default();
        let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
        let ts = eval_targets(&cfg, 3, 42).unwrap();
        let mut driver = crate::env::Policy(|_: &ReachEnv, a: &mut [f32]| {
            a.fill(0.0);
            Ok(())
        });
        let opts = crate::train::eval::EvalOptions::new(3, 42);
        let (_, records) = crate::train::eval::evaluate(&mut env, &mut driver, &opts).unwrap();
        let want: Vec<[f64; 3]> = records.iter().map(|r| r.target).collect();
        assert_eq!(ts, want);
    }
}
