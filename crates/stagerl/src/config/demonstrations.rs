//! Demonstrations from the reference planner (`[train.demonstrations]`, issue 34 item 4): before
//! its first episode, an off-policy run plans `episodes` episodes of its task with RRT-Connect
//! ([`crate::sim::rrt_connect`]), plays each plan in the environment and stores its transitions
//! in the replay buffer, where the agent learns from them as from its own (they are not counted
//! as training environment steps). [`crate::train`] does the work.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// The most demonstration episodes.
pub const MAX_DEMONSTRATION_EPISODES: u32 = 1_000_000;

/// The most RRT-Connect iterations of one demonstration.
pub const MAX_DEMONSTRATION_ITERATIONS: u32 = 10_000_000;

/// The planner that demonstrates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum DemoPlanner {
    /// RRT-Connect, the reference planner of `stagerl plan --planner rrt-connect`.
    #[default]
    #[serde(rename = "rrt-connect")]
    RrtConnect,
}

/// The `[train.demonstrations]` section (off-policy agents).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DemonstrationsConfig {
    /// Episodes planned and stored before training (an unsolved plan stores nothing; a plan
    /// longer than `task.max_steps` is stored up to the step limit).
    pub episodes: u32,
    /// The planner: `"rrt-connect"`.
    pub planner: DemoPlanner,
    /// The probability in [0, 1] that a demonstration's first random obstacle is placed across
    /// the straight line from the start pose's end effector to the target (as
    /// `train.obstacles_in_path` places it); needs `[task.random_obstacles]` when above 0. The
    /// demonstrations draw up to the task's largest obstacle count, whatever a curriculum's
    /// stage.
    pub obstacles_in_path: f64,
    /// RRT-Connect's iterations per plan. There is no wall-time budget: the same seed gives the
    /// same demonstrations on any machine.
    pub max_iterations: u32,
    /// How far the planned paths keep from every obstacle, metres: the search sees the
    /// obstacles grown by this much (less where the start pose is closer; at least the
    /// planner's own 1.25 mm margin). In [0, 0.5].
    pub clearance_m: f64,
    /// The planned paths' speed as a fraction of the joints' speed limits, in (0, 1]: every
    /// demonstrated action is at most this in magnitude (1: the plans of `stagerl plan`, the
    /// fastest joint at its limit throughout).
    pub speed_fraction: f64,
}

impl Default for DemonstrationsConfig {
    fn default() -> Self {
        DemonstrationsConfig {
            episodes: 200,
            planner: DemoPlanner::RrtConnect,
            obstacles_in_path: 0.0,
            max_iterations: crate::sim::rrt_connect::DEFAULT_ITERATIONS,
            clearance_m: 0.0,
            speed_fraction: 1.0,
        }
    }
}

impl DemonstrationsConfig {
    /// Check every value; `random_obstacles`: the task has `[task.random_obstacles]`. The error
    /// names the field.
    pub fn validate(&self, random_obstacles: bool) -> Result<()> {
        let f = |name: &str| format!("train.demonstrations.{name}");
        if !(1..=MAX_DEMONSTRATION_EPISODES).contains(&self.episodes) {
            return Err(Error::config(
                f("episodes"),
                self.episodes,
                format!("an integer from 1 to {MAX_DEMONSTRATION_EPISODES} (or leave the section out)"),
            ));
        }
        if !(1..=MAX_DEMONSTRATION_ITERATIONS).contains(&self.max_iterations) {
            return Err(Error::config(
                f("max_iterations"),
                self.max_iterations,
                format!("an integer from 1 to {MAX_DEMONSTRATION_ITERATIONS}"),
            ));
        }
        if !(0.0..=0.5).contains(&self.clearance_m) {
            return Err(Error::config(f("clearance_m"), self.clearance_m, "metres in [0, 0.5]"));
        }
        if !(self.speed_fraction > 0.0 && self.speed_fraction <= 1.0) {
            return Err(Error::config(f("speed_fraction"), self.speed_fraction, "a fraction in (0, 1]"));
        }
        crate::env::check_in_path_probability(
            &f("obstacles_in_path"),
            self.obstacles_in_path,
            random_obstacles,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_values_are_refused_naming_the_field() {
        let ok = DemonstrationsConfig::default();
        ok.validate(false).unwrap();
        for (c, random, field, allowed) in [
            (DemonstrationsConfig { episodes: 0, ..ok.clone() }, true, "episodes", "from 1 to"),
            (DemonstrationsConfig { max_iterations: 0, ..ok.clone() }, true, "max_iterations", "from 1 to"),
            (
                DemonstrationsConfig { obstacles_in_path: 1.5, ..ok.clone() },
                true,
                "obstacles_in_path",
                "[0, 1]",
            ),
            (
                DemonstrationsConfig { obstacles_in_path: f64::NAN, ..ok.clone() },
                true,
                "obstacles_in_path",
                "[0, 1]",
            ),
            (
                DemonstrationsConfig { obstacles_in_path: 0.5, ..ok.clone() },
                false,
                "obstacles_in_path",
                "without",
            ),
        ] {
            let e = c.validate(random).unwrap_err().to_string();
            assert!(e.contains(&format!("`train.demonstrations.{field}`")) && e.contains(allowed), "{e}");
        }
        DemonstrationsConfig { obstacles_in_path: 1.0, ..ok }.validate(true).unwrap();
    }

    #[test]
    fn a_run_config_refuses_them_for_ppo_and_reads_them_back() {
        let parse = |t: &str| {
            let c = crate::config::Config::from_toml_str(t, std::path::Path::new("c.toml"))?;
            c.validate().map(|()| c)
        };
        let e =
            parse("[agent]\nalgo = \"ppo\"\n[train.demonstrations]\nepisodes = 5\n").unwrap_err().to_string();
        assert!(e.contains("`train.demonstrations`") && e.contains("off-policy"), "{e}");
        let e = parse("[train.demonstrations]\nobstacles_in_path = 1.0\n").unwrap_err().to_string();
        assert!(e.contains("`train.demonstrations.obstacles_in_path`"), "{e}");
        let e = parse("[train.demonstrations]\nplanner = \"prm\"\n").unwrap_err().to_string();
        assert!(e.contains("rrt-connect"), "{e}");
        let e = parse("[agent.sac]\nbc_weight = 2.0\n").unwrap_err().to_string();
        assert!(e.contains("`agent.sac.bc_weight`") && e.contains("without [train.demonstrations]"), "{e}");
        parse("[agent.sac]\nbc_weight = 2.0\n[train.demonstrations]\n").unwrap();
        let c = parse("[train.demonstrations]\nepisodes = 7\nmax_iterations = 500\n").unwrap();
        let d = c.train.demonstrations.clone().unwrap();
        assert_eq!((d.episodes, d.max_iterations, d.planner), (7, 500, DemoPlanner::RrtConnect));
        // Written out (a run's config.toml) and read back the same.
        assert_eq!(parse(&c.to_toml_string()).unwrap(), c);
    }
}
