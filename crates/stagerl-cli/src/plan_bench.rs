//! `stagerl bench plan` among obstacles (`--obstacles-in-path`, `--shield`, `--controller`):
//! one random obstacle per plan, across the straight line from the start end effector to the
//! target with probability P (the placement of `eval --obstacles-in-path`), and per plan set:
//! 1. reached %: plans that ended within beta of the target;
//! 2. contact %: plans with a step that ended in contact (the contact test after every step);
//! 3. the shield's interventions and stops per plan;
//! 4. plan time: the fastest of three timed passes over the same plans, one thread, per plan
//!    and per 50 control steps (`1000 t / steps * 50` ms).

use anyhow::{Context, Result};
use stagerl::base::rng::Rng;
use stagerl::plan::Planner;
use std::time::Instant;

/// What a pass over the plans measured.
#[derive(Debug, Default, Clone, Copy, serde::Serialize)]
pub struct SceneBench {
    pub plans: u32,
    pub reached_rate: f64,
    pub contact_rate: f64,
    pub steps_per_plan: f64,
    pub interventions_per_plan: f64,
    pub stops_per_plan: f64,
    pub ms_per_plan: f64,
    pub ms_per_50_steps: f64,
}

/// Time `plans` plans of `planner` to targets of its task's distribution (seeded), each with
/// its random obstacles.
pub fn scene_bench(planner: &mut Planner, plans: u32) -> Result<SceneBench> {
    let targets: Vec<[f64; 3]> = {
        let env = planner.env();
        let mut rng = Rng::new(2);
        let mut q = vec![0.0; env.act_dim()];
        (0..plans)
            .map(|_| {
                let t = env.task().sample_target(env.chain(), &mut rng, &mut q);
                [t.x, t.y, t.z]
            })
            .collect()
    };
    let mut best = f64::INFINITY;
    let mut out = SceneBench { plans, ..Default::default() };
    for _ in 0..3 {
        // The same obstacles every pass: the environment's stream from the same seed.
        planner.reseed(7);
        let (mut reached, mut contact, mut steps, mut interventions, mut stops) =
            (0u32, 0u32, 0u64, 0u64, 0u64);
        let start = Instant::now();
        for t in &targets {
            let p = planner.plan(t, None).context("planning")?;
            reached += u32::from(p.summary.reached);
            contact += u32::from(p.summary.collision_steps > 0);
            steps += u64::from(p.summary.steps);
            if let Some(s) = p.summary.shield {
                (interventions, stops) = (interventions + s.shield_interventions, stops + s.shield_stops);
            }
        }
        let secs = start.elapsed().as_secs_f64();
        best = best.min(secs);
        let n = f64::from(plans);
        out = SceneBench {
            plans,
            reached_rate: f64::from(reached) / n,
            contact_rate: f64::from(contact) / n,
            steps_per_plan: steps as f64 / n,
            interventions_per_plan: interventions as f64 / n,
            stops_per_plan: stops as f64 / n,
            ms_per_plan: 1e3 * best / n,
            ms_per_50_steps: 1e3 * best / steps as f64 * 50.0,
        };
    }
    Ok(out)
}
