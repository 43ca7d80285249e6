//! The portable description of a checkpoint's policy: everything needed to run the trained actor
//! without stagerl's source, written as the JSON metadata entry [`POLICY_KEY`] (`policy`) of
//! every checkpoint (latest, final, best).
//!
//! Running the policy from the safetensors file alone:
//! 1. observation (f32, `observation.dim` values, in the order of `observation.layout`):
//!    `q / pi` (one per joint, q in radians), the end-effector position (3, metres, base frame),
//!    the target (3, metres), `obs_delta_scale * (target - end effector)` (3) and
//!    `obs_delta_scale * |target - end effector|` (1), then, when the run observes obstacles,
//!    7 values per obstacle slot (`obstacle_<i>`, computed as `observation.obstacles` says:
//!    [`ObstacleSlotsSpec`]); when `observation.normalization` is
//!    present (`agent.ppo.norm_obs`, `agent.norm_obs`), each value is then normalised in f32,
//!    `x' = clip((x - mean) / std, -clip, clip)`, with the tensors it names (shape `[dim]`);
//! 2. the actor: for each entry of `actor.layers` in order, `x <- f(W x + b)` with `W` the tensor
//!    named `weight` (shape `[out, in]`), `b` the tensor named `bias` and `f` its `activation`
//!    (`relu`: max(z, 0); `tanh`; `identity`);
//! 3. the deterministic action `a` (in [-1, 1]) by `action.rule`: `actor_output` (DDPG, TD3: the
//!    actor's tanh output itself) or `tanh_of_mean` (SAC: the actor outputs `[mean | log-std
//!    parameter]`, `2 * action.dim` values; `a = tanh(mean)`);
//! 4. the joint-velocity command, rad/s (m/s for prismatic joints): `clip(a, -1, 1) *
//!    action.speed_limits`, held for `action.dt_s` seconds; joint positions are clamped to
//!    `action.lower_limits` and `action.upper_limits`.

use serde::{Deserialize, Serialize};

use crate::agent::{Agent, Algo};
use crate::config::Config;
use crate::env::{empty_slot_distance, ObsEntry, ObservationLayout, ObstacleObservation, ReachEnv};
use crate::nn::Activation;

/// The checkpoint metadata key of the [`PolicySpec`].
pub const POLICY_KEY: &str = "policy";

/// The newest version of the [`PolicySpec`] format. A spec is written with the oldest version
/// whose readers can run it: 3 when the observation holds obstacle slots (`observation.obstacles`
/// and the `obstacle_<i>` entries; specs written before version 3 left those values out of the
/// layout), 2 when it is normalised (a reader of format 1 would not know to), else 1.
pub const POLICY_FORMAT_VERSION: u32 = 3;

/// A checkpoint's policy, described for running it anywhere (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicySpec {
    /// [`POLICY_FORMAT_VERSION`].
    pub format_version: u32,
    /// `ddpg`, `td3` or `sac`.
    pub algorithm: String,
    /// The arm: `ur5` or the URDF's path, its tip link and its joints, root to tip.
    pub robot: String,
    pub tip_link: String,
    pub joint_names: Vec<String>,
    pub observation: ObservationSpec,
    pub actor: ActorSpec,
    pub action: ActionSpec,
}

/// The observation vector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObservationSpec {
    /// Number of values (f32).
    pub dim: usize,
    /// The factor `k` of the scaled entries.
    pub obs_delta_scale: f64,
    /// The entries in order; their sizes sum to `dim`.
    pub layout: Vec<ObsEntry>,
    /// The observed obstacles' slots (the `obstacle_<i>` entries), if any (format 3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<ObstacleSlotsSpec>,
    /// The running normalisation the actor's input goes through, if any (format 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normalization: Option<NormalizationSpec>,
}

/// How the `obstacle_<i>` entries are computed (each entry's `value` says it in words).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObstacleSlotsSpec {
    /// Number of slots, `values_per_slot` values each.
    pub slots: usize,
    /// Values per slot: 7 (`absolute`, `nearest`) or 4 (`per_link`). Absent in descriptions
    /// of older versions: 7.
    #[serde(default = "seven", skip_serializing_if = "is_seven")]
    pub values_per_slot: usize,
    /// `absolute`: slot `i` is obstacle `i` (fixed obstacles first, then random ones): centre (3,
    /// m, base frame), half size along its axes (3, m; a sphere's radius three times), 1 for a
    /// sphere else 0; all zeros without one. `nearest`: slot `i` is the `i+1`-th nearest obstacle
    /// to the end effector by surface distance (ties by obstacle order), within `range_m` if set:
    /// `obs_delta_scale` times (centre - end effector) (3), half size (3) and that distance (1);
    /// without one, zeros and `empty_slot_distance`. `per_link`: slot `i` is collision shape `i`
    /// of the arm and its nearest obstacle, `range_m` the influence radius R: with `d` their
    /// signed distance, the unit direction from the shape to the obstacle times
    /// `1 - max(d, 0) / R` (3) and `max(d, -R) / R` (1) when `d < R`, else `0, 0, 0, 1`.
    pub encoding: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range_m: Option<f64>,
    /// The distance value of an empty `nearest` slot (f32 as written).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub empty_slot_distance: Option<f64>,
}

fn seven() -> usize {
    crate::env::OBSTACLE_OBS_LEN
}

fn is_seven(n: &usize) -> bool {
    *n == seven()
}

/// `x' = clip((x - mean) / std, -clip, clip)` per observation value, in f32.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NormalizationSpec {
    /// Name of the f32 tensor of means, shape `[dim]`.
    pub mean: String,
    /// Name of the f32 tensor of standard deviations, `sqrt(variance + 1e-8)`, shape `[dim]`.
    pub std: String,
    pub clip: f64,
    /// The rule in words.
    pub rule_text: String,
}

/// The actor network: `x <- activation(W x + b)` per layer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActorSpec {
    pub layers: Vec<LayerSpec>,
}

/// One layer of the actor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayerSpec {
    /// Name of the weight tensor, shape `[out, in]`.
    pub weight: String,
    /// Name of the bias tensor, shape `[out]`.
    pub bias: String,
    pub inputs: usize,
    pub outputs: usize,
    /// `relu`, `tanh` or `identity`.
    pub activation: String,
}

/// From the actor's output to joint velocities.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActionSpec {
    /// Number of actions (one per joint).
    pub dim: usize,
    /// `actor_output` or `tanh_of_mean` (see the module docs).
    pub rule: String,
    /// The rule in words.
    pub rule_text: String,
    /// Joint speed limits: an action of 1 commands this velocity, rad/s (m/s for prismatic).
    pub speed_limits: Vec<f64>,
    /// How long a command is held, seconds.
    pub dt_s: f64,
    /// Joint position limits, radians (metres for prismatic joints).
    pub lower_limits: Vec<f64>,
    pub upper_limits: Vec<f64>,
}

/// Activation names as [`LayerSpec::activation`] writes them.
pub fn activation_name(a: Activation) -> &'static str {
    match a {
        Activation::Identity => "identity",
        Activation::Relu => "relu",
        Activation::Tanh => "tanh",
    }
}

impl PolicySpec {
    /// The description of `agent`'s policy on `env`, trained with `cfg`.
    pub fn new(cfg: &Config, env: &ReachEnv, agent: &dyn Agent) -> PolicySpec {
        let chain = env.chain();
        let n = env.act_dim();
        let actor = agent.actor();
        let layers = actor.sizes().len() - 1;
        let layers = (0..layers)
            .map(|i| LayerSpec {
                weight: format!("actor.layer{i}.weight"),
                bias: format!("actor.layer{i}.bias"),
                inputs: actor.sizes()[i],
                outputs: actor.sizes()[i + 1],
                activation: activation_name(if i + 1 == layers {
                    actor.output_activation()
                } else {
                    actor.hidden_activation()
                })
                .into(),
            })
            .collect();
        let (rule, rule_text) = match agent.algo() {
            // CrossQ's actor is its batch-renormalised one folded into a plain MLP (the
            // running statistics in its weights), SAC's kind of head.
            Algo::Sac | Algo::Crossq => (
                "tanh_of_mean",
                format!(
                    "a[i] = tanh(y[i]) for i < {n}: the actor's output y holds the Gaussian's mean \
                     (first {n} values) and its log-std parameter (last {n}, unused)"
                ),
            ),
            Algo::Ddpg | Algo::Td3 => ("actor_output", "a = y: the actor's output (tanh) itself".into()),
            Algo::Ppo => (
                "actor_output",
                "a = y: the actor's output, the Gaussian policy's mean (linear; clipped to [-1, 1] in step 4)".into(),
            ),
        };
        let mut observation = observation_spec(env);
        observation.normalization = agent.obs_norm().map(|n| NormalizationSpec {
            mean: crate::agent::obs_norm::MEAN_TENSOR.into(),
            std: crate::agent::obs_norm::STD_TENSOR.into(),
            clip: f64::from(n.clip),
            rule_text: format!(
                "x[i] = clip((x[i] - mean[i]) / std[i], -{0}, {0}) in f32, the statistics of the \
                 observations seen in training (running mean; std = sqrt(variance + 1e-8))",
                n.clip
            ),
        });
        PolicySpec {
            format_version: match (&observation.obstacles, &observation.normalization) {
                (Some(_), _) => 3,
                (None, Some(_)) => 2,
                (None, None) => 1,
            },
            algorithm: agent.algo().name().into(),
            robot: cfg.robot.urdf.clone(),
            tip_link: chain.tip_link().into(),
            joint_names: chain.joints().iter().map(|j| j.name.clone()).collect(),
            observation,
            actor: ActorSpec { layers },
            action: ActionSpec {
                dim: n,
                rule: rule.into(),
                rule_text,
                speed_limits: chain.velocity_limits().to_vec(),
                dt_s: env.task().dt_s,
                lower_limits: chain.lower_limits().to_vec(),
                upper_limits: chain.upper_limits().to_vec(),
            },
        }
    }
}

fn observation_spec(env: &ReachEnv) -> ObservationSpec {
    let task = env.task();
    let layout = ObservationLayout::of(task);
    let obstacles = (layout.obstacle_slots() > 0).then(|| ObstacleSlotsSpec {
        slots: layout.obstacle_slots(),
        encoding: task.obstacle_observation.name().into(),
        values_per_slot: layout.slot_len(),
        range_m: match task.obstacle_observation {
            ObstacleObservation::PerLink => Some(task.per_link_range_m()),
            _ => task.obstacle_range_m,
        },
        empty_slot_distance: (task.obstacle_observation == ObstacleObservation::Nearest)
            .then(|| f64::from(empty_slot_distance(task, env.chain()))),
    });
    ObservationSpec {
        dim: layout.dim(),
        obs_delta_scale: task.obs_delta_scale,
        layout: layout.entries(task, env.chain()),
        obstacles,
        normalization: None,
    }
}

/// The leaves of two JSON values that differ, by path (`observation.obs_delta_scale`); numbers
/// equal to 1e-12 relative count as equal (a JSON round trip of an f64 may move its last bit).
///
/// With `a_keys_only`, only the fields `a` has are compared (`a` is a spec written by an older
/// version, which did not have the newer fields), and an array of `a` with the first as many
/// values of `b`'s.
fn json_differences(
    a: &serde_json::Value,
    b: &serde_json::Value,
    path: &str,
    a_keys_only: bool,
    out: &mut Vec<String>,
) {
    use serde_json::Value;
    let join = |k: &str| if path.is_empty() { k.to_string() } else { format!("{path}.{k}") };
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let keys: std::collections::BTreeSet<&String> = match a_keys_only {
                true => x.keys().collect(),
                false => x.keys().chain(y.keys()).collect(),
            };
            for k in keys {
                let (va, vb) = (x.get(k).unwrap_or(&Value::Null), y.get(k).unwrap_or(&Value::Null));
                json_differences(va, vb, &join(k), a_keys_only, out);
            }
        }
        // An older spec's layout lists fewer entries (format 3 added the obstacle slots' to a
        // layout whose `dim` already counted them): its entries against the first ones.
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() || (a_keys_only && x.len() < y.len()) => {
            for (i, (va, vb)) in x.iter().zip(y).enumerate() {
                json_differences(va, vb, &format!("{path}[{i}]"), a_keys_only, out);
            }
        }
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap_or(f64::NAN), y.as_f64().unwrap_or(f64::NAN));
            if !(x == y || (x - y).abs() <= 1e-12 * x.abs().max(y.abs())) {
                out.push(path.to_string());
            }
        }
        _ if a == b => {}
        _ => out.push(path.to_string()),
    }
}

/// The value at a JSON path of [`json_differences`], as text (`absent` when there is none).
fn json_at(v: &serde_json::Value, path: &str) -> String {
    let mut cur = Some(v);
    for part in path.split('.') {
        let (key, index) = match part.split_once('[') {
            Some((k, i)) => (k, i.trim_end_matches(']').parse::<usize>().ok()),
            None => (part, None),
        };
        cur = cur.and_then(|c| c.get(key));
        if let Some(i) = index {
            cur = cur.and_then(|c| c.get(i));
        }
    }
    match cur {
        None | Some(serde_json::Value::Null) => "absent".into(),
        Some(v) => crate::base::text::excerpt(&v.to_string()),
    }
}

/// The config fields (`task.obs_delta_scale`) whose values differ between two configs' TOML.
pub fn config_differences(stored_toml: &str, cfg: &Config) -> Vec<(String, String, String)> {
    let parse = |t: &str| toml::from_str::<toml::Table>(t).ok().and_then(|t| serde_json::to_value(t).ok());
    let (Some(a), Some(b)) = (parse(stored_toml), parse(&cfg.to_toml_string())) else { return Vec::new() };
    let mut paths = Vec::new();
    json_differences(&a, &b, "", false, &mut paths);
    paths
        .into_iter()
        .map(|p| {
            let (was, is) = (json_at(&a, &p), json_at(&b, &p));
            (p, was, is)
        })
        .collect()
}

/// An error if the policy a checkpoint was trained as (`stored`, its [`POLICY_KEY`] metadata)
/// differs from the one the config it is used with describes (`current`) in what goes in or
/// comes out of it: the observation (its size, layout, scale, obstacle slots, normalisation),
/// the action (its size, rule, speed limits, control period, joint limits), the joints, the
/// actor's layers or the algorithm. The error names the policy field, both values and the config
/// fields that differ (from the checkpoint's `config` metadata, `stored_config`). The robot's
/// file path is not compared (a run may be moved); its joints and tip are.
pub fn check_same_policy(
    stored: &serde_json::Value,
    current: &PolicySpec,
    stored_config: Option<&str>,
    cfg: &Config,
    origin: &std::path::Path,
) -> crate::Result<()> {
    let Ok(current_json) = serde_json::to_value(current) else { return Ok(()) };
    let mut paths = Vec::new();
    json_differences(stored, &current_json, "", true, &mut paths);
    // Not compared: the robot file's path (a run may be moved), the format's version and the
    // rules and entries in words (`rule_text`, a layout entry's `value`), which versions reword.
    paths.retain(|p| {
        p != "robot" && p != "format_version" && !p.ends_with("rule_text") && !p.ends_with(".value")
    });
    // The plainest field first: a value of the spec's own before its layout's entries.
    paths.sort_by_key(|p| (p.contains("layout"), p.clone()));
    let Some(first) = paths.first() else { return Ok(()) };
    let fields: Vec<String> = stored_config
        .map(|t| config_differences(t, cfg))
        .unwrap_or_default()
        .into_iter()
        .map(|(field, was, is)| format!("`{field}` = {was} there, {is} here"))
        .collect();
    let fields = match fields.len() {
        0 => String::new(),
        n => format!(
            " (config: {}{})",
            fields.iter().take(3).cloned().collect::<Vec<_>>().join(", "),
            if n > 3 { format!(" and {} more", n - 3) } else { String::new() }
        ),
    };
    Err(crate::Error::InvalidInput(format!(
        "{}: trained with `{first}` = {}, used with {}{fields}: the policy's inputs or outputs \
         would mean something else; refused",
        origin.display(),
        json_at(stored, first),
        json_at(&current_json, first),
    )))
}
