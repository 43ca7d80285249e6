//! A checkpoint carries what is needed to run its policy without stagerl: the `policy` metadata
//! entry. Here the policy is reimplemented from the safetensors file and that entry alone (plain
//! loops, no stagerl code) and compared with stagerl's own observation, action and joint
//! velocities, for every algorithm and every checkpoint kind.

use safetensors::SafeTensors;
use serde_json::Value;
use stagerl::agent::obs_norm::ObsNormConfig;
use stagerl::agent::{Algo, PpoConfig};
use stagerl::base::rng::Rng;
use stagerl::config::Config;
use stagerl::env::ReachEnv;
use stagerl::nalgebra::Vector3;
use std::collections::HashMap;
use std::path::Path;

/// The policy of one checkpoint file, read without stagerl.
struct Portable {
    spec: Value,
    tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
}

impl Portable {
    fn load(path: &Path) -> Portable {
        let bytes = std::fs::read(path).unwrap();
        let (_, header) = SafeTensors::read_metadata(&bytes).unwrap();
        let meta = header.metadata().clone().unwrap();
        let spec: Value = serde_json::from_str(&meta["policy"]).unwrap();
        let st = SafeTensors::deserialize(&bytes).unwrap();
        let tensors = st
            .names()
            .into_iter()
            .map(|n| {
                let t = st.tensor(n).unwrap();
                let data =
                    t.data().chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
                (n.to_string(), (t.shape().to_vec(), data))
            })
            .collect();
        Portable { spec, tensors }
    }

    fn floats(&self, key: &[&str]) -> Vec<f64> {
        let mut v = &self.spec;
        for k in key {
            v = &v[k];
        }
        v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
    }

    /// The observation from joint positions (rad), end effector and target (m), by the layout.
    fn observation(&self, q: &[f64], ee: [f64; 3], target: [f64; 3]) -> Vec<f32> {
        let obs = &self.spec["observation"];
        let k = obs["obs_delta_scale"].as_f64().unwrap();
        let mut out = vec![0.0f32; obs["dim"].as_u64().unwrap() as usize];
        let delta: Vec<f64> = (0..3).map(|i| (target[i] - ee[i]) * k).collect();
        let dist = delta.iter().map(|d| d * d).sum::<f64>().sqrt();
        for entry in obs["layout"].as_array().unwrap() {
            let start = entry["start"].as_u64().unwrap() as usize;
            let values: Vec<f64> = match entry["name"].as_str().unwrap() {
                "q_over_pi" => q.iter().map(|x| x / std::f64::consts::PI).collect(),
                "ee_pos" => ee.to_vec(),
                "target" => target.to_vec(),
                "scaled_delta" => delta.clone(),
                "scaled_distance" => vec![dist],
                other => panic!("unknown observation entry {other}"),
            };
            assert_eq!(values.len() as u64, entry["size"].as_u64().unwrap());
            for (i, v) in values.into_iter().enumerate() {
                out[start + i] = v as f32;
            }
        }
        out
    }

    /// The deterministic action, in [-1, 1].
    fn action(&self, obs: &[f32]) -> Vec<f32> {
        let mut x = obs.to_vec();
        let norm = &self.spec["observation"]["normalization"];
        if !norm.is_null() {
            assert_eq!(self.spec["format_version"], 2, "a normalised observation is format 2");
            let (_, mean) = &self.tensors[norm["mean"].as_str().unwrap()];
            let (_, std) = &self.tensors[norm["std"].as_str().unwrap()];
            let c = norm["clip"].as_f64().unwrap() as f32;
            for i in 0..x.len() {
                x[i] = ((x[i] - mean[i]) / std[i]).clamp(-c, c);
            }
        }
        for layer in self.spec["actor"]["layers"].as_array().unwrap() {
            let (wshape, w) = &self.tensors[layer["weight"].as_str().unwrap()];
            let (_, b) = &self.tensors[layer["bias"].as_str().unwrap()];
            let (rows, cols) = (wshape[0], wshape[1]);
            assert_eq!(cols, x.len());
            let mut y = vec![0.0f32; rows];
            for r in 0..rows {
                let mut acc = 0.0f64;
                for c in 0..cols {
                    acc += f64::from(w[r * cols + c]) * f64::from(x[c]);
                }
                let z = acc + f64::from(b[r]);
                y[r] = match layer["activation"].as_str().unwrap() {
                    "relu" => z.max(0.0),
                    "tanh" => z.tanh(),
                    "identity" => z,
                    other => panic!("unknown activation {other}"),
                } as f32;
            }
            x = y;
        }
        let n = self.spec["action"]["dim"].as_u64().unwrap() as usize;
        match self.spec["action"]["rule"].as_str().unwrap() {
            "tanh_of_mean" => x[..n].iter().map(|m| m.tanh()).collect(),
            "actor_output" => x,
            other => panic!("unknown rule {other}"),
        }
    }

    /// The joint velocity command for an action, rad/s.
    fn joint_velocity(&self, action: &[f32]) -> Vec<f64> {
        let limits = self.floats(&["action", "speed_limits"]);
        action.iter().zip(&limits).map(|(a, v)| f64::from(a.clamp(-1.0, 1.0)) * v).collect()
    }
}

fn small_run(dir: &Path, algo: Algo, norm_obs: bool) -> Config {
    let mut cfg = Config::default();
    cfg.agent.algo = algo;
    cfg.agent.hidden = vec![24, 16];
    cfg.agent.batch_size = 16;
    cfg.agent.buffer_size = 2000;
    cfg.agent.learning_starts = 60;
    cfg.train.episodes = 4;
    cfg.train.eval_every_episodes = 2;
    cfg.train.eval_trials = 3;
    cfg.train.checkpoint_every_episodes = 3;
    // PPO: a rollout that updates within the 4 episodes (and, as asked, normalised observations).
    let norm_obs = norm_obs.then(ObsNormConfig::default);
    cfg.agent.ppo = (algo == Algo::Ppo).then(|| PpoConfig {
        num_envs: 2,
        num_steps: 16,
        norm_obs,
        ..PpoConfig::default()
    });
    std::fs::remove_dir_all(dir).ok();
    stagerl::train::train(&cfg, dir, |_| {}).unwrap();
    cfg
}

#[test]
fn the_policy_runs_from_the_checkpoint_and_its_metadata_alone() {
    let root = std::env::temp_dir().join(format!("stagerl-portable-{}", std::process::id()));
    let variants = Algo::ALL.into_iter().map(|a| (a, false)).chain([(Algo::Ppo, true)]);
    for (algo, norm_obs) in variants {
        let dir = root.join(format!("{algo}-{norm_obs}"));
        let cfg = small_run(&dir, algo, norm_obs);
        for kind in ["latest", "final", "best"] {
            let path = dir.join("checkpoints").join(format!("{kind}.safetensors"));
            let p = Portable::load(&path);
            assert_eq!(p.spec["algorithm"], algo.name());
            assert_eq!(p.spec["observation"]["normalization"].is_null(), !norm_obs);
            assert_eq!(p.spec["format_version"], if norm_obs { 2 } else { 1 });
            let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
            let mut agent = stagerl::train::load_agent(&cfg, &env, &path).unwrap();
            let (lo, hi) = (p.floats(&["action", "lower_limits"]), p.floats(&["action", "upper_limits"]));
            let dt = p.spec["action"]["dt_s"].as_f64().unwrap();
            let mut rng = Rng::new(11);
            let mut action = vec![0.0f32; 6];
            let mut worst: f64 = 0.0;
            for trial in 0..1000 {
                // Joint positions well inside the limits (|q| < 2), a target anywhere in front.
                let q: Vec<f64> = (0..6).map(|_| rng.uniform_range(-2.0, 2.0)).collect();
                let t =
                    [rng.uniform_range(-0.8, 0.8), rng.uniform_range(-0.8, 0.8), rng.uniform_range(0.0, 0.9)];
                env.reset_to(&q, Vector3::from(t)).unwrap();
                let ee = env.ee_pose().position;
                let obs = p.observation(&q, [ee.x, ee.y, ee.z], t);
                assert_eq!(obs, env.observation(), "observation of trial {trial}");
                // Step 4 clips the action to [-1, 1] (PPO's mean can leave it; a tanh output cannot).
                let mine: Vec<f32> = p.action(&obs).iter().map(|a| a.clamp(-1.0, 1.0)).collect();
                agent.predict(env.observation(), &mut action);
                for (a, b) in mine.iter().zip(&action) {
                    worst = worst.max(f64::from((a - b).abs()));
                }
                // The velocity the environment applies for that action (no limit reached from |q| < 2).
                let v = p.joint_velocity(&action);
                env.step(&action).unwrap();
                for i in 0..6 {
                    assert!(env.joint_positions()[i] > lo[i] && env.joint_positions()[i] < hi[i]);
                    assert!(
                        (env.joint_velocities()[i] - v[i]).abs() <= 1e-9 * (1.0 + v[i].abs()),
                        "{algo} {kind}"
                    );
                    assert!((env.joint_positions()[i] - (q[i] + v[i] * dt)).abs() <= 1e-12);
                }
            }
            assert!(worst <= 1e-5, "{algo} {kind}: largest action difference {worst}");
        }
    }
    std::fs::remove_dir_all(&root).ok();
}
