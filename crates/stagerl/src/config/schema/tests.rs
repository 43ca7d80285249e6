//! Tests of the config's self-description.

use super::*;
use std::collections::BTreeSet;

/// A config with every optional section and field set (and every field a written config leaves
/// out at its default set to another value), so that its serialisation names every field.
const FULL: &str = r#"
[robot]
urdf = "ur5"
tip = "wrist_3_link"
[task]
home_pose_rad = [0.0, -1.5, 1.5, -1.5, -1.5, 0.0]
target_joint_range_rad = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]
on_collision = "terminate"
observe_obstacles = true
obstacle_observation = "nearest"
obstacle_range_m = 0.15
sim = "dynamic"
[task.collision]
floor = true
self_collision = false
[task.shield]
# enabled = true is refused with sim = "dynamic"
enabled = false
margin_m = 0.03
self_margin_m = 0.003
influence_m = 0.2
gain = 0.5
[[task.obstacles]]
shape = "cuboid"
position_m = [0.4, 0.0, 0.3]
half_extents_m = [0.05, 0.05, 0.05]
rotation_xyzw = [0.0, 0.0, 0.0, 1.0]
[[task.obstacles]]
shape = "sphere"
position_m = [0.4, 0.2, 0.3]
radius_m = 0.05
[task.random_obstacles]
count = [1, 2]
[reward]
collision_penalty = 10.0
shield_penalty = 0.5
[reward.clearance]
weight = 2.0
margin_m = 0.05
[agent]
actor_lr = 0.001
critic_lr = 0.001
her = { strategy = "future", k = 4 }
norm_obs = { clip = 5.0 }
[agent.ddpg]
[agent.td3]
[agent.sac]
n_critics = 10
critic_subset = 2
actor_q = "min"
critic_dropout = 0.01
critic_layer_norm = true
actor_log_std = "clip"
policy_delay = 3
bc_weight = 2.0
[agent.ppo]
norm_obs = { clip = 10.0 }
[agent.crossq]
critic_hidden = [256, 256]
n_critics = 3
policy_delay = 2
adam_beta1 = 0.9
bn_momentum = 0.9
renorm_warmup_steps = 1000
alpha_lr = 0.0003
init_alpha = 0.5
target_entropy_per_dim = -0.5
fixed_alpha = true
[train]
obstacles_in_path = 0.5
env_steps = 30000
eval_every_env_steps = 1000
[train.curriculum]
window = 50
advance_at = 0.7
obstacles_in_path = [0.0, 0.5]
max_obstacles = [1, 2]
[train.demonstrations]
episodes = 50
planner = "rrt-connect"
obstacles_in_path = 1.0
max_iterations = 2000
clearance_m = 0.03
speed_fraction = 0.5
"#;

/// Every `section.field` path of a JSON value (list items as their section).
fn paths(v: &Value, prefix: &str, out: &mut BTreeSet<String>) {
    match v {
        Value::Object(m) => {
            for (k, v) in m {
                let path = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                out.insert(path.clone());
                paths(v, &path, out);
            }
        }
        Value::Array(items) => items.iter().filter(|i| i.is_object()).for_each(|i| paths(i, prefix, out)),
        _ => {}
    }
}

/// The `section.field` paths the listing shows (set or commented out), and its sections.
fn listed() -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut section = String::new();
    for line in annotated_toml().lines() {
        let code = line.strip_prefix("# ").unwrap_or(line);
        let header = code.strip_prefix("[[").and_then(|s| s.strip_suffix("]]"));
        if let Some(s) = header.or_else(|| code.strip_prefix('[').and_then(|s| s.strip_suffix(']'))) {
            section = s.to_string();
            // Every section along the way (`agent.ppo.norm_obs` lists `agent.ppo` too).
            let mut prefix = String::new();
            for part in section.split('.') {
                prefix = if prefix.is_empty() { part.to_string() } else { format!("{prefix}.{part}") };
                out.insert(prefix.clone());
            }
        } else if let Some((name, _)) = code.split_once(" = ") {
            if name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_') {
                out.insert(format!("{section}.{name}"));
            }
        }
    }
    out
}

/// Every property path of the JSON Schema, following `$ref`s.
fn schema_paths(schema: &Value, node: &Value, prefix: &str, out: &mut BTreeSet<String>) {
    let Some(props) = node.get("properties").and_then(Value::as_object) else { return };
    for (k, prop) in props {
        let path = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
        out.insert(path.clone());
        if let Some(def) = resolve(schema, prop) {
            schema_paths(schema, def, &path, out);
        }
    }
}

#[test]
fn every_field_of_the_config_types_is_listed_and_in_the_schema() {
    let full = Config::from_toml_str(FULL, std::path::Path::new("full.toml")).unwrap();
    let mut fields = BTreeSet::new();
    paths(&serde_json::to_value(&full).unwrap(), "", &mut fields);
    // Every field a written config can hold (those left out at their defaults are set above).
    assert!(fields.len() > 90, "{}: {fields:?}", fields.len());
    let listing = listed();
    let schema = json_schema();
    let mut in_schema = BTreeSet::new();
    schema_paths(&schema, &schema, "", &mut in_schema);
    let missing: Vec<&String> = fields.iter().filter(|f| !listing.contains(*f)).collect();
    assert!(missing.is_empty(), "not in `stagerl config`: {missing:?}");
    let missing: Vec<&String> = fields.iter().filter(|f| !in_schema.contains(*f)).collect();
    assert!(missing.is_empty(), "not in the JSON Schema: {missing:?}");
    // Nor does either show a field the types do not have.
    let extra: Vec<&String> = listing.iter().filter(|f| !fields.contains(*f)).collect();
    assert!(extra.is_empty(), "listed but no such field: {extra:?}");
}

#[test]
fn the_listing_is_the_default_config_and_shows_the_optional_sections_commented_out() {
    let text = annotated_toml();
    let parsed = Config::from_toml_str(&text, std::path::Path::new("listing.toml")).unwrap();
    assert_eq!(parsed, Config::default(), "what is not commented out is the default config");
    for section in [
        "# [task.collision]",
        "# [task.shield]",
        "# [[task.obstacles]]",
        "# [task.random_obstacles]",
        "# [reward.clearance]",
        "# [agent.her]",
        "# [agent.norm_obs]",
        "# [agent.ppo]",
        "# [agent.ppo.norm_obs]",
        "# [agent.sac]",
        "# [train.curriculum]",
        "# [train.demonstrations]",
    ] {
        assert!(text.lines().any(|l| l == section), "{section} in\n{text}");
    }
    // Defaults a written config leaves out are found and shown, with the choices.
    for line in [
        "sim = \"kinematic\"",
        "on_collision = \"record\"",
        "observe_obstacles = false",
        "obstacle_observation = \"absolute\"",
        "obstacles_in_path = 0.0",
        "# collision_penalty = (unset)",
        "# position_m = (required)",
        "# count = [1, 3]",
        "algo = \"sac\"",
        "dt_s = 0.05",
    ] {
        assert!(text.lines().any(|l| l == line), "{line:?} in\n{text}");
    }
    assert!(text.contains("One of \"kinematic\", \"dynamic\"."), "{text}");
    // Help is one line, its unit named, rustdoc links gone.
    assert!(
        text.contains("# Control period: each joint-velocity command is held this long, seconds"),
        "{text}"
    );
    assert!(!text.contains("[`"), "{text}");
}

#[test]
fn first_sentences_lose_their_links() {
    assert_eq!(first_sentence("At most [`MAX_X`]. More."), "At most `MAX_X`.");
    assert_eq!(first_sentence("See [`a::B`](crate::a::B)\nand on. Next."), "See `a::B` and on.");
    assert_eq!(first_sentence("No period"), "No period");
}

#[test]
fn a_file_missing_required_settings_is_refused_naming_every_one() {
    let text = "[[task.obstacles]]\nradius_m = 0.05\n[[task.obstacles]]\nshape = \"sphere\"\n\
                [task.random_obstacles]\ncount = [1, 2]\n";
    let e = Config::from_toml_str(text, std::path::Path::new("m.toml")).unwrap_err().to_string();
    for field in ["task.obstacles[0].shape", "task.obstacles[0].position_m", "task.obstacles[1].position_m"] {
        assert!(e.contains(field), "{field} in {e}");
    }
    assert!(!e.contains("obstacles[1].shape"), "{e}");
    assert!(e.contains("m.toml"), "{e}");
}
