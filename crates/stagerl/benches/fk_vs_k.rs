//! Hand-run timing of the UR5's forward kinematics and Jacobian against the `k` crate's (the
//! oracle of tests/it/robot_k_oracle.rs) on 1024 seeded random configurations, one thread:
//! nanoseconds per call, the best of 300 batches of 4096 calls (robust to other load), 3 rounds.
//!
//! `cargo bench -p stagerl --bench fk_vs_k`

use std::hint::black_box;

use stagerl::base::rng::Rng;
use stagerl::robot::{Chain, UR5_URDF};

#[path = "../tests/it/k_oracle.rs"]
mod k_oracle;
use k_oracle::{k_chain, random_q};

/// Nanoseconds per call: the best of 300 batches of 4096 calls.
fn best_ns(mut f: impl FnMut(usize)) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..300 {
        let t = std::time::Instant::now();
        for i in 0..4096 {
            f(i);
        }
        best = best.min(t.elapsed().as_nanos() as f64 / 4096.0);
    }
    best
}

fn main() {
    let ours = Chain::ur5();
    let theirs = k_chain(UR5_URDF, "tool0");
    let mut rng = Rng::new(1);
    let qs: Vec<Vec<f64>> = (0..1024).map(|_| random_q(&ours, &mut rng)).collect();
    let mut jac = [0.0; 36];
    for round in 0..3 {
        let fk = best_ns(|i| {
            black_box(ours.fk(black_box(&qs[i & 1023])));
        });
        let jn = best_ns(|i| {
            black_box(ours.jacobian(black_box(&qs[i & 1023]), &mut jac));
            black_box(&mut jac);
        });
        let kn = best_ns(|i| {
            theirs.set_joint_positions_unchecked(black_box(&qs[i & 1023]));
            black_box(theirs.end_transform());
        });
        println!(
            "round {round}: UR5 fk {fk:.1} ns/call, jacobian {jn:.1} ns/call; \
             k set_joint_positions_unchecked + end_transform {kn:.1} ns/call"
        );
    }
}
