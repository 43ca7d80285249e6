//! The paper's Table 1, kept as reference data in `assets/paper/table1.csv` and compiled in.

use serde::Serialize;

use crate::agent::Algo;
use crate::reward::RewardFunction;
use crate::{Error, Result};

/// The CSV text of the paper's Table 1.
pub const TABLE1_CSV: &str = include_str!("../../../../assets/paper/table1.csv");

/// The paper's training episodes, repeated runs and evaluation trials (section VI).
pub const PAPER_EPISODES: u64 = 10_000;
pub const PAPER_RUNS: u64 = 20;
pub const PAPER_EVAL_TRIALS: u64 = 500;

/// One row of the paper's Table 1. `None` fields are "----" in the paper.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PaperRow {
    pub algo: Algo,
    pub reward: RewardFunction,
    /// E_start (the paper's "Episode" column).
    pub e_start: Option<f64>,
    /// Eq. 17's R_bar, mean and std over the 20 runs.
    pub train_reward: Option<(f64, f64)>,
    /// Average steps in training.
    pub train_steps: Option<f64>,
    /// Eq. 17's V_STDEV, mean and std over the 20 runs.
    pub v_stdev: Option<(f64, f64)>,
    /// Evaluation reward.
    pub eval_reward: Option<f64>,
    /// Evaluation steps.
    pub eval_steps: Option<f64>,
    /// Evaluation success rate, in [0, 1].
    pub success_rate: Option<f64>,
}

impl PaperRow {
    /// The paper reports the row as not converged ("----").
    pub fn converged(&self) -> bool {
        self.e_start.is_some()
    }
}

/// Parse a Table 1 CSV (the format of `assets/paper/table1.csv`; `#` lines are comments).
pub fn parse_table1(text: &str) -> Result<Vec<PaperRow>> {
    const HEADER: &str = "algorithm,reward,e_start,train_reward_mean,train_reward_std,train_steps,v_stdev_mean,v_stdev_std,eval_reward,eval_steps,success_rate_pct";
    let mut lines = text.lines().filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    if lines.next().map(str::trim) != Some(HEADER) {
        return Err(Error::InvalidInput(format!("paper table: expected the header {HEADER:?}")));
    }
    lines
        .map(|line| {
            let bad = |what: &str| Error::InvalidInput(format!("paper table: {what} in row {line:?}"));
            let f: Vec<&str> = line.split(',').map(str::trim).collect();
            if f.len() != 11 {
                return Err(bad("11 fields expected"));
            }
            let num = |i: usize| -> Result<Option<f64>> {
                if f[i].is_empty() {
                    Ok(None)
                } else {
                    f[i].parse::<f64>().map(Some).map_err(|_| bad("a malformed number"))
                }
            };
            let pair = |i: usize| -> Result<Option<(f64, f64)>> { Ok(num(i)?.zip(num(i + 1)?)) };
            Ok(PaperRow {
                algo: f[0].parse().map_err(|_| bad("an unknown algorithm"))?,
                reward: f[1].parse().map_err(|_| bad("an unknown reward function"))?,
                e_start: num(2)?,
                train_reward: pair(3)?,
                train_steps: num(5)?,
                v_stdev: pair(6)?,
                eval_reward: num(8)?,
                eval_steps: num(9)?,
                success_rate: num(10)?.map(|p| p / 100.0),
            })
        })
        .collect()
}

/// The paper's Table 1 (compiled in; its parse is checked by a test).
pub fn table1() -> Vec<PaperRow> {
    parse_table1(TABLE1_CSV).unwrap_or_default()
}

/// The paper's row for `(algo, reward)`, if the paper has one.
pub fn row(
    rows: &[PaperRow],
    method: crate::report::method::Method,
    reward: RewardFunction,
) -> Option<&PaperRow> {
    rows.iter().find(|r| crate::report::method::Method::from(r.algo) == method && r.reward == reward)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_compiled_table_parses() {
        let rows = parse_table1(TABLE1_CSV).unwrap();
        assert_eq!(rows.len(), 10);
        let sar = row(&rows, Algo::Ddpg.into(), RewardFunction::Sar).unwrap();
        assert_eq!(sar.e_start, Some(4781.0));
        assert_eq!(sar.train_reward, Some((18.076, 0.166)));
        assert_eq!(sar.success_rate, Some(0.996));
        let basic = row(&rows, Algo::Sac.into(), RewardFunction::Basic).unwrap();
        assert!(!basic.converged() && basic.eval_reward.is_none());
        assert!(row(&rows, Algo::Td3.into(), RewardFunction::Sar).is_none());
        assert!(parse_table1("nope\n").is_err());
        assert!(parse_table1(&TABLE1_CSV.replace("sac,sar,3593", "sac,sar,x")).is_err());
    }
}
