//! What a run prints as it goes and when it ends: the progress bar (or log lines), the training
//! summary and the evaluation's summary line.

use indicatif::{ProgressBar, ProgressStyle};
use stagerl::train::eval::EvalSummary;
use stagerl::train::{self, Progress};
use std::collections::VecDeque;
use std::io::IsTerminal;
use std::time::{Duration, Instant};

use crate::out::RunOutput;

pub fn print_summary(summary: &train::TrainSummary, output: &RunOutput) {
    output.line(format_args!(
        "trained {} episodes, {} env steps, {} updates in {:.1} s ({:.0} env steps/s)",
        summary.episodes,
        summary.env_steps,
        summary.updates,
        summary.wall_s,
        summary.env_steps as f64 / summary.wall_s
    ));
}

pub fn summary_line(s: &EvalSummary, json: bool) -> String {
    if json {
        serde_json::json!({
            "success_rate": s.success_rate,
            "mean_reward": s.mean_reward,
            "mean_steps": s.mean_steps,
            "trials": s.trials,
            "median_final_distance_m": s.median_final_distance_m,
            "collision_rate": s.collision_rate,
        })
        .to_string()
    } else {
        format!(
            "evaluation: success {:.1} % of {} trials, mean episode reward {:.3}, mean steps (successful) {}, median final distance {:.4} m, {}",
            100.0 * s.success_rate,
            s.trials,
            s.mean_reward,
            s.mean_steps.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into()),
            s.median_final_distance_m,
            // None: the arm has no collision shape (or the trials predate contact recording).
            s.collision_rate
                .map_or_else(|| "collisions not checked".into(), |c| format!("collisions in {:.1} % of the trials", 100.0 * c))
        )
    }
}

/// An evaluation's summary line with what the safety shield did, if it was on: the
/// `shield_*` keys in JSON, a clause in text.
pub fn with_shield(line: String, shield: Option<stagerl::sim::shield::ShieldStats>, json: bool) -> String {
    let Some(s) = shield else { return line };
    let keys = stagerl::sim::shield::ShieldSummary::from(s);
    if json {
        let mut v: serde_json::Value = serde_json::from_str(&line).unwrap_or_default();
        if let (Some(m), Ok(serde_json::Value::Object(k))) = (v.as_object_mut(), serde_json::to_value(keys)) {
            m.extend(k);
        }
        v.to_string()
    } else {
        format!(
            "{line}; shield: {} interventions ({} stops) in {} steps, change mean {:.3} rad/s, max {:.3} rad/s",
            s.interventions,
            s.stops,
            s.steps,
            s.mean_change_rad_per_s(),
            s.max_change_rad_per_s
        )
    }
}

/// A progress bar on a terminal; plain log lines every 10 s otherwise.
pub struct Reporter<'a> {
    output: &'a RunOutput,
    bar: Option<ProgressBar>,
    last_log: Instant,
    recent: VecDeque<(f64, bool)>,
    last_eval: Option<(u64, f64)>,
}

impl<'a> Reporter<'a> {
    /// A progress bar (on a terminal) or a line every 10 s, over the run's episodes or, under a
    /// budget in environment steps, its environment steps.
    pub fn new(train: &stagerl::config::TrainConfig, output: &'a RunOutput) -> Reporter<'a> {
        let (len, unit) = match train.env_steps {
            Some(n) => (n, "env steps"),
            None => (train.episodes, "episodes"),
        };
        let bar = std::io::stdout().is_terminal().then(|| {
            let b = ProgressBar::new(len);
            b.set_style(
                ProgressStyle::with_template(&format!(
                    "{{bar:30}} {{pos}}/{{len}} {unit} {{elapsed_precise}} (eta {{eta}}) {{msg}}"
                ))
                .expect("valid template"),
            );
            b
        });
        Reporter { output, bar, last_log: Instant::now(), recent: VecDeque::new(), last_eval: None }
    }

    pub fn episode(&mut self, p: &Progress<'_>) {
        let r = p.record;
        if let Some(d) = &p.demonstrations {
            let contacts =
                d.collided.map_or("contacts not checked".to_string(), |c| format!("{c} with a contact"));
            let line = format!(
                "demonstrations: {} episode(s) planned by RRT-Connect, {} solved and stored ({} reached the \
                 target, {contacts}): {} transitions in the replay buffer",
                d.episodes, d.solved, d.reached, d.transitions
            );
            match &self.bar {
                Some(b) => b.println(line),
                None => self.output.line(format_args!("{line}")),
            }
        }
        if let Some(a) = &p.stage_advance {
            let line = format!(
                "episode {}: curriculum stage {} of 0-{} from the next episode ({}/{} successes over \
                 the stage's last {} episodes): obstacles in the way with probability {}, at most {} \
                 random obstacles",
                r.episode,
                a.stage,
                a.stages - 1,
                a.successes,
                a.window,
                a.window,
                a.obstacles_in_path,
                a.max_obstacles
            );
            match &self.bar {
                Some(b) => b.println(line),
                None => self.output.line(format_args!("{line}")),
            }
        }
        self.recent.push_back((r.reward, r.success));
        if self.recent.len() > 100 {
            self.recent.pop_front();
        }
        if let Some(e) = p.eval {
            self.last_eval = Some((r.episode, e.success_rate));
        }
        let n = self.recent.len() as f64;
        let mean_r = self.recent.iter().map(|x| x.0).sum::<f64>() / n;
        let succ = self.recent.iter().filter(|x| x.1).count() as f64 / n;
        let mut msg = format!("reward(100) {mean_r:.2} success(100) {:.0}%", 100.0 * succ);
        if let Some((ep, s)) = self.last_eval {
            msg.push_str(&format!(" eval@{ep} {:.0}%", 100.0 * s));
        }
        if let Some(st) = &p.stats {
            msg.push_str(&format!(" critic {:.3}", st.critic_loss));
            if let Some(a) = st.alpha {
                msg.push_str(&format!(" alpha {a:.3}"));
            }
        }
        match &self.bar {
            Some(b) => {
                b.set_position(if p.env_steps.is_some() {
                    r.env_steps.min(b.length().unwrap_or(0))
                } else {
                    r.episode
                });
                b.set_message(msg);
            }
            None => {
                if self.last_log.elapsed() >= Duration::from_secs(10) || p.eval.is_some() || p.last {
                    match p.env_steps {
                        Some(n) => self.output.line(format_args!(
                            "episode {} env steps {}/{n} {:.0} s {msg}",
                            r.episode, r.env_steps, r.wall_s
                        )),
                        None => self.output.line(format_args!(
                            "episode {}/{} env steps {} {:.0} s {msg}",
                            r.episode, p.episodes, r.env_steps, r.wall_s
                        )),
                    }
                    self.last_log = Instant::now();
                }
            }
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish();
        }
    }
}
