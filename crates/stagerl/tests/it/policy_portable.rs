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
use stagerl::env::{ObstacleObservation, ReachEnv};
use stagerl::nalgebra::Vector3;
use stagerl::sim::scene::{Obstacle, ObstacleShape, RandomObstacles};
use std::collections::HashMap;
use std::path::Path;

/// An obstacle as the world shows it: centre and half size (m), shape, and the end effector's
/// distance to its surface (m).
struct Seen {
    centre: [f64; 3],
    half: [f64; 3],
    sphere: bool,
    distance: f64,
}

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

    /// The obstacle slots' values, 7 per slot, by `observation.obstacles`, from each obstacle's
    /// centre (m), half size (m), whether it is a sphere and the end effector's distance to its
    /// surface (m), in the episode's order.
    fn obstacle_slots(&self, obstacles: &[Seen], ee: [f64; 3]) -> Vec<Vec<f64>> {
        let spec = &self.spec["observation"]["obstacles"];
        let k = self.spec["observation"]["obs_delta_scale"].as_f64().unwrap();
        let slots = spec["slots"].as_u64().unwrap() as usize;
        match spec["encoding"].as_str().unwrap() {
            "absolute" => (0..slots)
                .map(|i| match obstacles.get(i) {
                    Some(o) => {
                        [o.centre.to_vec(), o.half.to_vec(), vec![f64::from(u8::from(o.sphere))]].concat()
                    }
                    None => vec![0.0; 7],
                })
                .collect(),
            "nearest" => {
                let range = spec["range_m"].as_f64().unwrap_or(f64::INFINITY);
                let mut order: Vec<usize> =
                    (0..obstacles.len()).filter(|&i| obstacles[i].distance <= range).collect();
                order.sort_by(|&a, &b| {
                    obstacles[a].distance.total_cmp(&obstacles[b].distance).then(a.cmp(&b))
                });
                let empty = spec["empty_slot_distance"].as_f64().unwrap();
                (0..slots)
                    .map(|i| match order.get(i).map(|&j| &obstacles[j]) {
                        Some(o) => (0..3)
                            .map(|a| k * (o.centre[a] - ee[a]))
                            .chain(o.half.iter().map(|h| k * h))
                            .chain([k * o.distance])
                            .collect(),
                        None => [vec![0.0; 6], vec![empty]].concat(),
                    })
                    .collect()
            }
            other => panic!("unknown obstacle encoding {other}"),
        }
    }

    /// The observation from joint positions (rad), end effector and target (m) and the
    /// obstacles, by the layout. The `per_link` slots need the arm's collision shapes, which the
    /// description does not hold: they are taken from `env_obs` (checked within [-1, 1]).
    fn observation(
        &self,
        q: &[f64],
        ee: [f64; 3],
        target: [f64; 3],
        obstacles: &[Seen],
        env_obs: &[f32],
    ) -> Vec<f32> {
        let obs = &self.spec["observation"];
        let per_link = obs["obstacles"]["encoding"] == "per_link";
        let k = obs["obs_delta_scale"].as_f64().unwrap();
        let mut out = vec![0.0f32; obs["dim"].as_u64().unwrap() as usize];
        let delta: Vec<f64> = (0..3).map(|i| (target[i] - ee[i]) * k).collect();
        let dist = delta.iter().map(|d| d * d).sum::<f64>().sqrt();
        let slots = if obs["obstacles"].is_null() || per_link {
            Vec::new()
        } else {
            self.obstacle_slots(obstacles, ee)
        };
        let mut size = 0;
        for entry in obs["layout"].as_array().unwrap() {
            let start = entry["start"].as_u64().unwrap() as usize;
            let values: Vec<f64> = match entry["name"].as_str().unwrap() {
                "q_over_pi" => q.iter().map(|x| x / std::f64::consts::PI).collect(),
                "ee_pos" => ee.to_vec(),
                "target" => target.to_vec(),
                "scaled_delta" => delta.clone(),
                "scaled_distance" => vec![dist],
                other => match other.strip_prefix("obstacle_") {
                    Some(_) if per_link => {
                        let size = entry["size"].as_u64().unwrap() as usize;
                        assert_eq!(size as u64, obs["obstacles"]["values_per_slot"].as_u64().unwrap());
                        let v: Vec<f64> =
                            env_obs[start..start + size].iter().map(|&x| f64::from(x)).collect();
                        assert!(v.iter().all(|x| (-1.0..=1.0).contains(x)), "{v:?}");
                        v
                    }
                    Some(i) => slots[i.parse::<usize>().unwrap()].clone(),
                    None => panic!("unknown observation entry {other}"),
                },
            };
            size += values.len();
            assert_eq!(values.len() as u64, entry["size"].as_u64().unwrap());
            for (i, v) in values.into_iter().enumerate() {
                out[start + i] = v as f32;
            }
        }
        assert_eq!(size, out.len(), "the layout describes every value");
        out
    }

    /// The deterministic action, in [-1, 1].
    fn action(&self, obs: &[f32]) -> Vec<f32> {
        let mut x = obs.to_vec();
        let norm = &self.spec["observation"]["normalization"];
        if !norm.is_null() {
            assert!(
                self.spec["format_version"].as_u64() >= Some(2),
                "a normalised observation is format 2 or later"
            );
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

fn small_run(dir: &Path, algo: Algo, norm_obs: bool, obstacles: Option<ObstacleObservation>) -> Config {
    let mut cfg = Config::default();
    if let Some(encoding) = obstacles {
        // A fixed sphere and 1-3 random obstacles, observed; "nearest" within 30 cm.
        cfg.task.obstacles = vec![Obstacle::sphere(0.05, [0.0, 0.6, 0.3])];
        cfg.task.random_obstacles = Some(RandomObstacles { count: [1, 3], ..RandomObstacles::default() });
        cfg.task.observe_obstacles = true;
        cfg.task.obstacle_observation = encoding;
        cfg.task.obstacle_range_m = (encoding == ObstacleObservation::Nearest).then_some(0.3);
    }
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
    // The off-policy agents: `agent.norm_obs`.
    cfg.agent.norm_obs = norm_obs.filter(|_| algo != Algo::Ppo);
    std::fs::remove_dir_all(dir).ok();
    stagerl::train::train(&cfg, dir, |_| {}).unwrap();
    cfg
}

#[test]
fn the_policy_runs_from_the_checkpoint_and_its_metadata_alone() {
    let root = std::env::temp_dir().join(format!("stagerl-portable-{}", std::process::id()));
    let variants = Algo::ALL.into_iter().map(|a| (a, false, None)).chain([
        (Algo::Ppo, true, None),
        (Algo::Sac, true, None),
        (Algo::Ddpg, true, None),
        (Algo::Td3, true, Some(ObstacleObservation::Nearest)),
        (Algo::Sac, false, Some(ObstacleObservation::Nearest)),
        (Algo::Td3, false, Some(ObstacleObservation::Absolute)),
        (Algo::Ppo, true, Some(ObstacleObservation::Nearest)),
        (Algo::Sac, true, Some(ObstacleObservation::PerLink)),
    ]);
    for (algo, norm_obs, obstacles) in variants {
        let dir = root.join(format!("{algo}-{norm_obs}-{obstacles:?}"));
        let cfg = small_run(&dir, algo, norm_obs, obstacles);
        for kind in ["latest", "final", "best"] {
            let path = dir.join("checkpoints").join(format!("{kind}.safetensors"));
            let p = Portable::load(&path);
            assert_eq!(p.spec["algorithm"], algo.name());
            assert_eq!(p.spec["observation"]["normalization"].is_null(), !norm_obs);
            let version = match (obstacles, norm_obs) {
                (Some(_), _) => 3,
                (None, true) => 2,
                (None, false) => 1,
            };
            assert_eq!(p.spec["format_version"], version);
            assert_eq!(p.spec["observation"]["obstacles"].is_null(), obstacles.is_none());
            let mut env = ReachEnv::from_config(&cfg, 0).unwrap();
            if obstacles == Some(ObstacleObservation::PerLink) {
                // One slot of 4 per collision shape of the arm, R the default 0.1 m.
                let (o, shapes) = (&p.spec["observation"]["obstacles"], env.chain().collision_shapes().len());
                assert_eq!(
                    (&o["encoding"], &o["slots"], &o["values_per_slot"]),
                    (&"per_link".into(), &shapes.into(), &4.into())
                );
                assert_eq!(
                    (&o["range_m"], &p.spec["observation"]["dim"]),
                    (&0.1.into(), &(16 + 4 * shapes).into())
                );
            }
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
                let seen: Vec<Seen> = env
                    .obstacles()
                    .iter()
                    .map(|o| Seen {
                        centre: o.position_m,
                        half: o.half_size_m(),
                        sphere: o.shape == ObstacleShape::Sphere,
                        distance: o.distance_to_point_m([ee.x, ee.y, ee.z]),
                    })
                    .collect();
                let obs = p.observation(&q, [ee.x, ee.y, ee.z], t, &seen, env.observation());
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
