"""Reference values for stagerl's IQM and its stratified-bootstrap CI, from the `rliable`
package (Agarwal et al., NeurIPS 2021). Run: pip install rliable "pandas<3" && python rliable_iqm.py
(arch 7.2, which rliable uses, fails to import with pandas 3).
The printed numbers are pinned in crates/stagerl/src/report/aggregate.rs (test
`iqm_matches_rliable`)."""
import numpy as np
from rliable import library as rly
from rliable import metrics

# 20 seeds' success rates, one task (the shape rliable expects: runs x tasks).
SUCCESS = [0.962, 0.998, 0.974, 0.990, 0.912, 0.996, 0.984, 0.978, 1.0, 0.956,
           0.988, 0.934, 0.994, 0.970, 0.982, 0.998, 0.946, 0.992, 0.968, 0.986]
# 10 seeds' evaluation rewards and a second task of 10 seeds (stratified over two tasks).
REWARD = [17.91, 18.40, 16.95, 18.77, 18.02, 17.35, 18.93, 18.11, 16.48, 18.56]

for name, data in [("success", np.array(SUCCESS)[:, None]), ("reward", np.array(REWARD)[:, None])]:
    point, ci = rly.get_interval_estimates({"x": data}, lambda s: np.array([metrics.aggregate_iqm(s)]),
                                           reps=50000, confidence_interval_size=0.95)
    print(f"{name}: iqm {point['x'][0]:.15f} ci {ci['x'][0][0]:.6f} {ci['x'][1][0]:.6f}")
