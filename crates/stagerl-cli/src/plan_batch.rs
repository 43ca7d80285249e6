//! Batch planning, shared by `stagerl plan --targets` and `stagerl bench plan`: JSON lines of
//! requests in, one line per plan out.

use anyhow::Result;
use stagerl::plan::{BatchLine, PlanRequest, Planner};
use stagerl::view::{self, View};
use std::io::{BufRead, Write};

/// Plan every JSON line of `input` ([`PlanRequest`]), one [`BatchLine`] out per line; warnings
/// on standard error. The first [`view::MAX_TRAJECTORIES`] plans also go into `view`. Returns
/// the number of control steps planned.
pub fn batch(
    planner: &mut Planner,
    input: impl BufRead,
    output: impl Write,
    mut view: Option<&mut View>,
) -> Result<u64> {
    let (mut k, mut steps) = (0u64, 0u64);
    crate::jsonl::process(input, output, |req: PlanRequest| {
        k += 1;
        let plan = planner.plan_request(&req)?;
        if let Some(w) = &plan.warning {
            errln!("stagerl: warning: plan {k}: {w}")?;
        }
        steps += u64::from(plan.summary.steps);
        if let Some(v) = view.as_deref_mut().filter(|v| v.trajectories.len() < view::MAX_TRAJECTORIES) {
            let t = &req.target;
            v.push_planned(planner, &format!("plan {k}"), [t[0], t[1], t[2]], &plan)?;
        }
        Ok(BatchLine(plan))
    })?;
    if view.is_some() && k > view::MAX_TRAJECTORIES as u64 {
        errln!(
            "stagerl: warning: the view holds the first {} of the {k} plans (its limit); the output has all of them",
            view::MAX_TRAJECTORIES
        )?;
    }
    Ok(steps)
}
