//! The `k` crate as an oracle of stagerl's kinematics: its chain read from the same URDF, and
//! seeded random configurations within the limits. Shared by tests/it/robot_k_oracle.rs and
//! benches/fk_vs_k.rs (there through `#[path]`).

use std::f64::consts::PI;

use stagerl::base::rng::Rng;
use stagerl::robot::Chain;

/// `k`'s serial chain from the root to the joint whose child is `tip`.
pub fn k_chain(xml: &str, tip: &str) -> k::SerialChain<f64> {
    let robot = urdf_rs::read_from_string(xml).expect("URDF parses");
    let chain = k::Chain::<f64>::from(&robot);
    let end = chain.find_link(tip).expect("tip link in k's chain");
    k::SerialChain::from_end(end)
}

/// A random configuration within the limits (continuous joints: within +-2 pi).
pub fn random_q(chain: &Chain, rng: &mut Rng) -> Vec<f64> {
    chain
        .lower_limits()
        .iter()
        .zip(chain.upper_limits())
        .map(
            |(&lo, &hi)| {
                if lo.is_finite() {
                    rng.uniform_range(lo, hi)
                } else {
                    rng.uniform_range(-2.0 * PI, 2.0 * PI)
                }
            },
        )
        .collect()
}
