//! The obstacle curriculum (`[train.curriculum]`, issue 34 item 4): training goes through stages
//! of rising difficulty, each with its probability that the first random obstacle is placed in
//! the way and its largest random obstacle count; it moves to the next stage when the success
//! rate of its last `window` training episodes reaches `advance_at`, and stays at the last.
//! [`CurriculumConfig`] is the section, [`CurriculumState`] the schedule a run keeps (and saves
//! in its checkpoints).

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// The largest `window` (episodes whose successes are kept).
pub const MAX_CURRICULUM_WINDOW: u32 = 1_000_000;

/// The most stages.
pub const MAX_CURRICULUM_STAGES: usize = 1000;

/// The obstacle curriculum (the `[train.curriculum]` section; off-policy agents, a task with
/// `[task.random_obstacles]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CurriculumConfig {
    /// Training episodes over which the success rate is measured, counted from the start of the
    /// stage (a stage lasts at least this many episodes).
    pub window: u32,
    /// The success rate over the last `window` episodes, in (0, 1], at which the next stage
    /// begins (with a new window).
    pub advance_at: f64,
    /// Per stage, the probability in [0, 1] that an episode's first random obstacle is placed in
    /// the way (`train.obstacles_in_path`'s placement).
    pub obstacles_in_path: Vec<f64>,
    /// Per stage, the largest random obstacle count: an episode draws its count uniformly from
    /// `task.random_obstacles.count[0]` to this (each within `task.random_obstacles.count`).
    pub max_obstacles: Vec<u32>,
}

impl Default for CurriculumConfig {
    fn default() -> Self {
        CurriculumConfig {
            window: 100,
            advance_at: 0.6,
            obstacles_in_path: vec![0.0, 0.125, 0.25, 0.375, 0.5],
            max_obstacles: vec![1, 1, 2, 2, 3],
        }
    }
}

impl CurriculumConfig {
    /// Check every value that does not depend on the task; the error names the field.
    pub fn validate_values(&self) -> Result<()> {
        let f = |name: &str| format!("train.curriculum.{name}");
        if !(1..=MAX_CURRICULUM_WINDOW).contains(&self.window) {
            return Err(Error::config(
                f("window"),
                self.window,
                format!("an integer from 1 to {MAX_CURRICULUM_WINDOW} (episodes)"),
            ));
        }
        if !(self.advance_at > 0.0 && self.advance_at <= 1.0) {
            return Err(Error::config(f("advance_at"), self.advance_at, "a success rate in (0, 1]"));
        }
        let stages = self.obstacles_in_path.len();
        if !(1..=MAX_CURRICULUM_STAGES).contains(&stages) {
            return Err(Error::config(
                f("obstacles_in_path"),
                format!("{:?}", self.obstacles_in_path),
                format!("a list of 1 to {MAX_CURRICULUM_STAGES} probabilities, one per stage"),
            ));
        }
        if let Some(p) = self.obstacles_in_path.iter().find(|p| !(0.0..=1.0).contains(*p)) {
            return Err(Error::config(
                f("obstacles_in_path"),
                format!("{:?}", self.obstacles_in_path),
                format!("probabilities in [0, 1] (not {p})"),
            ));
        }
        if self.max_obstacles.len() != stages {
            return Err(Error::config(
                f("max_obstacles"),
                format!("{:?}", self.max_obstacles),
                format!("a list of {stages} counts, one per stage of train.curriculum.obstacles_in_path"),
            ));
        }
        Ok(())
    }

    /// Check the stages' counts against the task's `[task.random_obstacles] count` (`None`: the
    /// task has none, which the curriculum needs).
    pub fn check_task(&self, random_count: Option<[u32; 2]>) -> Result<()> {
        let Some([lo, hi]) = random_count else {
            return Err(Error::config(
                "train.curriculum",
                "a curriculum section",
                "none for a task without [task.random_obstacles] (the curriculum sets how many \
                 random obstacles there are and where the first is placed)",
            ));
        };
        if let Some(m) = self.max_obstacles.iter().find(|m| !(lo..=hi).contains(*m)) {
            return Err(Error::config(
                "train.curriculum.max_obstacles",
                format!("{:?}", self.max_obstacles),
                format!("counts within task.random_obstacles.count = [{lo}, {hi}] (not {m})"),
            ));
        }
        Ok(())
    }

    /// Stages.
    pub fn stages(&self) -> usize {
        self.obstacles_in_path.len()
    }

    /// Stage `stage`'s settings: (the in-the-way probability, the largest obstacle count).
    pub fn stage(&self, stage: usize) -> (f64, u32) {
        (self.obstacles_in_path[stage], self.max_obstacles[stage])
    }
}

/// Where a run stands in its curriculum: the stage and the outcomes of the stage's latest
/// episodes (at most `window`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CurriculumState {
    /// The stage (0-based) of the next episode.
    pub stage: usize,
    /// The outcomes of the stage's latest episodes, oldest first, as `'1'` (success) and `'0'`
    /// (at most `window` of them).
    pub window: String,
}

/// A stage change, as [`CurriculumState::record`] reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageAdvance {
    /// The stage that begins (0-based).
    pub stage: usize,
    /// Stages in all.
    pub stages: usize,
    /// Successes among the `window` episodes that ended the previous stage.
    pub successes: u32,
    pub window: u32,
    /// The new stage's settings: the in-the-way probability and the largest obstacle count.
    pub obstacles_in_path: f64,
    pub max_obstacles: u32,
}

impl CurriculumState {
    /// Count an episode's outcome; the stage changes when the last `window` episodes of the
    /// stage hold a success rate of at least `advance_at` (not after the last stage).
    pub fn record(&mut self, cfg: &CurriculumConfig, success: bool) -> Option<StageAdvance> {
        self.window.push(if success { '1' } else { '0' });
        if self.window.len() > cfg.window as usize {
            self.window.remove(0);
        }
        let last = self.stage + 1 >= cfg.stages();
        if last || self.window.len() < cfg.window as usize {
            return None;
        }
        let successes = self.window.bytes().filter(|&b| b == b'1').count() as u32;
        if f64::from(successes) / f64::from(cfg.window) < cfg.advance_at {
            return None;
        }
        self.stage += 1;
        self.window.clear();
        let (obstacles_in_path, max_obstacles) = cfg.stage(self.stage);
        Some(StageAdvance {
            stage: self.stage,
            stages: cfg.stages(),
            successes,
            window: cfg.window,
            obstacles_in_path,
            max_obstacles,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn three_stages(window: u32, advance_at: f64) -> CurriculumConfig {
        CurriculumConfig {
            window,
            advance_at,
            obstacles_in_path: vec![0.0, 0.25, 0.5],
            max_obstacles: vec![1, 2, 3],
        }
    }

    /// The stage of every episode (before its outcome is counted) for `outcomes`, and the
    /// episodes (1-based) after which it changed.
    fn schedule(cfg: &CurriculumConfig, outcomes: &[bool]) -> (Vec<usize>, Vec<usize>) {
        let mut state = CurriculumState::default();
        let mut stages = Vec::new();
        let mut changes = Vec::new();
        for (i, &s) in outcomes.iter().enumerate() {
            stages.push(state.stage);
            if let Some(a) = state.record(cfg, s) {
                assert_eq!((a.stage, a.stages, a.window), (state.stage, 3, cfg.window));
                assert_eq!((a.obstacles_in_path, a.max_obstacles), cfg.stage(a.stage));
                changes.push(i + 1);
            }
        }
        (stages, changes)
    }

    #[test]
    fn the_stage_advances_exactly_when_the_windowed_success_rate_reaches_advance_at() {
        // Window 5, advance at 0.6: 3 successes among the stage's last 5 episodes.
        let cfg = three_stages(5, 0.6);
        let o = [true, false, false, true, false, true, true, false];
        // Windows: e5 = 1,0,0,1,0 (2) no; e6 = 0,0,1,0,1 (2) no; e7 = 0,1,0,1,1 (3) advance.
        let (_, changes) = schedule(&cfg, &o);
        assert_eq!(changes, vec![7]);
        // A window of 3 of 5 just below the threshold (0.8 needs 4 of 5) does not advance.
        let (_, changes) = schedule(&three_stages(5, 0.8), &o);
        assert!(changes.is_empty(), "{changes:?}");
    }

    #[test]
    fn the_window_restarts_at_each_stage_and_the_last_stage_stays() {
        let cfg = three_stages(4, 0.5);
        // Always successful: a stage lasts exactly `window` episodes, then the last one stays.
        let (stages, changes) = schedule(&cfg, &[true; 20]);
        assert_eq!(changes, vec![4, 8]);
        assert_eq!(&stages[..9], &[0, 0, 0, 0, 1, 1, 1, 1, 2]);
        assert!(stages[8..].iter().all(|&s| s == 2), "{stages:?}");
        // Never successful: stage 0 throughout.
        let (stages, changes) = schedule(&cfg, &[false; 50]);
        assert!(changes.is_empty() && stages.iter().all(|&s| s == 0));
        // advance_at = 1: only a window of successes advances.
        let (_, changes) = schedule(&three_stages(3, 1.0), &[true, true, false, true, true, true]);
        assert_eq!(changes, vec![6]);
        // A single-stage curriculum never advances.
        let one = CurriculumConfig { obstacles_in_path: vec![0.5], max_obstacles: vec![2], ..cfg };
        let mut state = CurriculumState::default();
        assert!((0..10).all(|_| state.record(&one, true).is_none()) && state.stage == 0);
        assert_eq!(state.window.len(), 4, "the window keeps its last `window` outcomes");
    }

    #[test]
    fn the_rate_is_compared_as_the_fraction_written() {
        // 60 of 100 is 0.6 exactly as written (60 / 100 rounds to the same double as 0.6).
        let cfg = three_stages(100, 0.6);
        let o: Vec<bool> = (0..100).map(|i| i < 60).collect();
        assert_eq!(schedule(&cfg, &o).1, vec![100]);
        let o: Vec<bool> = (0..100).map(|i| i < 59).collect();
        assert!(schedule(&cfg, &o).1.is_empty());
        // 0.7 = 7 of 10, and 0.3 = 3 of 10, though 0.1 * 3 != 0.3 in binary.
        for (at, needed) in [(0.7, 7), (0.3, 3), (0.1, 1)] {
            let cfg = three_stages(10, at);
            let o: Vec<bool> = (0..10).map(|i| i < needed).collect();
            assert_eq!(schedule(&cfg, &o).1, vec![10], "{at}");
            let o: Vec<bool> = (0..10).map(|i| i < needed - 1).collect();
            assert!(schedule(&cfg, &o).1.is_empty(), "{at}");
        }
    }

    #[test]
    fn bad_values_are_refused_naming_the_field() {
        let ok = CurriculumConfig::default();
        ok.validate_values().unwrap();
        ok.check_task(Some([1, 3])).unwrap();
        for (c, field) in [
            (CurriculumConfig { window: 0, ..ok.clone() }, "train.curriculum.window"),
            (CurriculumConfig { advance_at: 0.0, ..ok.clone() }, "train.curriculum.advance_at"),
            (CurriculumConfig { advance_at: 1.5, ..ok.clone() }, "train.curriculum.advance_at"),
            (CurriculumConfig { advance_at: f64::NAN, ..ok.clone() }, "train.curriculum.advance_at"),
            (
                CurriculumConfig { obstacles_in_path: vec![], max_obstacles: vec![], ..ok.clone() },
                "train.curriculum.obstacles_in_path",
            ),
            (
                CurriculumConfig {
                    obstacles_in_path: vec![0.0, 1.5],
                    max_obstacles: vec![1, 1],
                    ..ok.clone()
                },
                "train.curriculum.obstacles_in_path",
            ),
            (CurriculumConfig { max_obstacles: vec![1, 2], ..ok.clone() }, "train.curriculum.max_obstacles"),
        ] {
            let e = c.validate_values().unwrap_err().to_string();
            assert!(e.contains(&format!("`{field}`")), "{e}");
        }
        let e = ok.check_task(Some([2, 3])).unwrap_err().to_string();
        assert!(e.contains("`train.curriculum.max_obstacles`") && e.contains("[2, 3]"), "{e}");
        let e = ok.check_task(None).unwrap_err().to_string();
        assert!(e.contains("`train.curriculum`") && e.contains("[task.random_obstacles]"), "{e}");
    }
}
