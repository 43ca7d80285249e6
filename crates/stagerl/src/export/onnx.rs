//! The actor as an ONNX model (opset 13, IR version 7), encoded by hand with [`crate::io::proto`].
//!
//! Input `observation` (f32, `[batch, obs_dim]`, the standard layout of [`crate::run::policy`]),
//! output `joint_velocity` (f32, `[batch, dof]`, rad/s; m/s for prismatic joints). The graph:
//! for a normalised observation (`agent.ppo.norm_obs`, `agent.norm_obs`) `Sub` the means, `Div` by the standard
//! deviations and `Clip`; per actor layer `Gemm(x, W, b, transB=1)` then `Relu` or `Tanh` (none for identity); for SAC
//! `Slice` of the first `dof` outputs (the Gaussian's mean) and `Tanh`; then `Clip` to [-1, 1]
//! (the environment's clamp) and `Mul` by the speed limits. The batch dimension is the symbolic
//! `batch`. `metadata_props` hold the observation layout in words, the action rule, the robot,
//! the joints, the control period, the config hash and the stagerl version.

use crate::agent::obs_norm::ObsNorm;
use crate::io::proto::{put_int, put_len_delimited, put_str};
use crate::nn::Mlp;
use crate::run::policy::PolicySpec;
use crate::{Error, Result};

/// The ONNX opset the model imports.
pub const OPSET: i64 = 13;
/// The ONNX IR version of opset 13.
pub const IR_VERSION: i64 = 7;
/// The graph's input name.
pub const INPUT: &str = "observation";
/// The graph's output name.
pub const OUTPUT: &str = "joint_velocity";

/// `TensorProto.DataType` values.
const FLOAT: i64 = 1;
const INT64: i64 = 7;
/// `AttributeProto.AttributeType.INT`.
const ATTR_INT: i64 = 2;

/// What the model's metadata records besides the [`PolicySpec`].
#[derive(Clone, Debug, PartialEq)]
pub struct ModelInfo {
    /// The run's config hash ([`crate::train::config_hash`]).
    pub config_hash: String,
    /// The checkpoint exported.
    pub checkpoint: String,
}

/// One node of the graph.
struct Node<'a> {
    op: &'a str,
    inputs: Vec<String>,
    output: String,
    /// Integer attributes.
    ints: Vec<(&'a str, i64)>,
}

impl Node<'_> {
    fn encode(&self, name: &str) -> Vec<u8> {
        let mut b = Vec::new();
        for i in &self.inputs {
            put_str(&mut b, 1, i);
        }
        put_str(&mut b, 2, &self.output);
        put_str(&mut b, 3, name);
        put_str(&mut b, 4, self.op);
        for (attr, v) in &self.ints {
            let mut a = Vec::new();
            put_str(&mut a, 1, attr);
            put_int(&mut a, 3, *v);
            put_int(&mut a, 20, ATTR_INT);
            put_len_delimited(&mut b, 5, &a);
        }
        b
    }
}

/// A `TensorProto` initializer of f32 values (`raw_data`, little-endian).
fn f32_tensor(name: &str, dims: &[usize], data: &[f32]) -> Vec<u8> {
    let mut b = Vec::with_capacity(data.len() * 4 + name.len() + 16);
    for &d in dims {
        put_int(&mut b, 1, d as i64);
    }
    put_int(&mut b, 2, FLOAT);
    put_str(&mut b, 8, name);
    let raw: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    put_len_delimited(&mut b, 9, &raw);
    b
}

/// A `TensorProto` initializer of int64 values.
fn i64_tensor(name: &str, data: &[i64]) -> Vec<u8> {
    let mut b = Vec::new();
    put_int(&mut b, 1, data.len() as i64);
    put_int(&mut b, 2, INT64);
    put_str(&mut b, 8, name);
    let raw: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    put_len_delimited(&mut b, 9, &raw);
    b
}

/// A `ValueInfoProto` of an f32 tensor `[batch, features]`.
fn value_info(name: &str, features: usize, doc: &str) -> Vec<u8> {
    let mut batch = Vec::new();
    put_str(&mut batch, 2, "batch"); // dim_param
    let mut feat = Vec::new();
    put_int(&mut feat, 1, features as i64); // dim_value
    let mut shape = Vec::new();
    put_len_delimited(&mut shape, 1, &batch);
    put_len_delimited(&mut shape, 1, &feat);
    let mut tensor = Vec::new();
    put_int(&mut tensor, 1, FLOAT);
    put_len_delimited(&mut tensor, 2, &shape);
    let mut ty = Vec::new();
    put_len_delimited(&mut ty, 1, &tensor);
    let mut b = Vec::new();
    put_str(&mut b, 1, name);
    put_len_delimited(&mut b, 2, &ty);
    put_str(&mut b, 3, doc);
    b
}

/// The nodes and initializers of the observation's normalisation (if any), the actor and the
/// action rule, in graph order.
fn graph_parts(
    spec: &PolicySpec,
    actor: &Mlp<f32>,
    norm: Option<&ObsNorm>,
) -> Result<(Vec<Node<'static>>, Vec<Vec<u8>>)> {
    let (mut nodes, mut inits) = (Vec::new(), Vec::new());
    let params = actor.params();
    let tensors = actor.tensors();
    let mut x = INPUT.to_string();
    match (&spec.observation.normalization, norm) {
        (None, None) => {}
        (Some(ns), Some(n)) => {
            // x' = clip((x - mean) / std, -clip, clip): the same f32 operations as training.
            let d = spec.observation.dim;
            inits.push(f32_tensor(&ns.mean, &[d], &n.mean));
            inits.push(f32_tensor(&ns.std, &[d], &n.std));
            inits.push(f32_tensor("obs_norm.min", &[], &[-n.clip]));
            inits.push(f32_tensor("obs_norm.max", &[], &[n.clip]));
            let steps = [
                ("Sub", vec![x, ns.mean.clone()], "obs_norm.centred"),
                ("Div", vec!["obs_norm.centred".into(), ns.std.clone()], "obs_norm.scaled"),
                (
                    "Clip",
                    vec!["obs_norm.scaled".into(), "obs_norm.min".into(), "obs_norm.max".into()],
                    "obs_norm.out",
                ),
            ];
            for (op, inputs, output) in steps {
                nodes.push(Node { op, inputs, output: output.into(), ints: vec![] });
            }
            x = "obs_norm.out".into();
        }
        _ => {
            return Err(Error::InvalidInput(
                "the policy's description and the agent disagree on the observation's normalisation".into(),
            ))
        }
    }
    for (i, (layer, pair)) in spec.actor.layers.iter().zip(tensors.chunks_exact(2)).enumerate() {
        let (w, b) = (&pair[0], &pair[1]);
        inits.push(f32_tensor(&layer.weight, &w.shape, &params[w.range()]));
        inits.push(f32_tensor(&layer.bias, &b.shape, &params[b.range()]));
        let z = format!("actor.layer{i}.linear");
        nodes.push(Node {
            op: "Gemm",
            inputs: vec![x, layer.weight.clone(), layer.bias.clone()],
            output: z.clone(),
            ints: vec![("transB", 1)],
        });
        x = match layer.activation.as_str() {
            "identity" => z,
            "relu" | "tanh" => {
                let op = if layer.activation == "relu" { "Relu" } else { "Tanh" };
                let y = format!("actor.layer{i}.out");
                nodes.push(Node { op, inputs: vec![z], output: y.clone(), ints: vec![] });
                y
            }
            other => {
                return Err(Error::InvalidInput(format!(
                    "actor layer {i}: activation `{other}` has no ONNX export"
                )))
            }
        };
    }
    let n = spec.action.dim;
    if spec.action.rule == "tanh_of_mean" {
        inits.push(i64_tensor("mean.starts", &[0]));
        inits.push(i64_tensor("mean.ends", &[n as i64]));
        inits.push(i64_tensor("mean.axes", &[1]));
        let inputs = vec![x, "mean.starts".into(), "mean.ends".into(), "mean.axes".into()];
        nodes.push(Node { op: "Slice", inputs, output: "mean".into(), ints: vec![] });
        nodes.push(Node {
            op: "Tanh",
            inputs: vec!["mean".into()],
            output: "action.tanh".into(),
            ints: vec![],
        });
        x = "action.tanh".into();
    } else if spec.action.rule != "actor_output" {
        return Err(Error::InvalidInput(format!("action rule `{}` has no ONNX export", spec.action.rule)));
    }
    inits.push(f32_tensor("action.min", &[], &[-1.0]));
    inits.push(f32_tensor("action.max", &[], &[1.0]));
    let clip = vec![x, "action.min".into(), "action.max".into()];
    nodes.push(Node { op: "Clip", inputs: clip, output: "action".into(), ints: vec![] });
    let limits: Vec<f32> = spec.action.speed_limits.iter().map(|&v| v as f32).collect();
    inits.push(f32_tensor("speed_limits", &[n], &limits));
    let mul = vec!["action".into(), "speed_limits".into()];
    nodes.push(Node { op: "Mul", inputs: mul, output: OUTPUT.into(), ints: vec![] });
    Ok((nodes, inits))
}

/// The `metadata_props` of the model.
fn metadata(spec: &PolicySpec, info: &ModelInfo) -> Vec<(String, String)> {
    let layout: Vec<String> = spec
        .observation
        .layout
        .iter()
        .map(|e| format!("[{}..{}) {}: {}", e.start, e.start + e.size, e.name, e.value))
        .collect();
    vec![
        ("observation_layout".into(), layout.join("; ")),
        ("observation_dim".into(), spec.observation.dim.to_string()),
        (
            "observation_normalization".into(),
            spec.observation.normalization.as_ref().map_or_else(|| "none".into(), |n| n.rule_text.clone()),
        ),
        ("action_rule".into(), format!("{}: {}", spec.action.rule, spec.action.rule_text)),
        (
            "output".into(),
            format!("{OUTPUT} = clip(a, -1, 1) * speed_limits, rad/s (m/s for prismatic joints)"),
        ),
        ("algorithm".into(), spec.algorithm.clone()),
        ("robot".into(), spec.robot.clone()),
        ("tip_link".into(), spec.tip_link.clone()),
        ("joint_names".into(), spec.joint_names.join(",")),
        ("dt_s".into(), spec.action.dt_s.to_string()),
        ("config_hash".into(), info.config_hash.clone()),
        ("checkpoint".into(), info.checkpoint.clone()),
        ("stagerl_version".into(), env!("CARGO_PKG_VERSION").into()),
        ("policy".into(), serde_json::to_string(spec).unwrap_or_default()),
    ]
}

/// The ONNX `ModelProto` of `actor` (the network `spec` describes) as bytes.
pub fn encode(
    spec: &PolicySpec,
    actor: &Mlp<f32>,
    norm: Option<&ObsNorm>,
    info: &ModelInfo,
) -> Result<Vec<u8>> {
    if spec.actor.layers.len() != actor.layers().len() {
        return Err(Error::InvalidInput(format!(
            "the policy describes {} actor layers, the actor has {}",
            spec.actor.layers.len(),
            actor.layers().len()
        )));
    }
    let (nodes, inits) = graph_parts(spec, actor, norm)?;
    let mut graph = Vec::new();
    for (i, node) in nodes.iter().enumerate() {
        put_len_delimited(&mut graph, 1, &node.encode(&format!("{}_{i}", node.op)));
    }
    put_str(&mut graph, 2, &format!("stagerl {} actor", spec.algorithm));
    for t in &inits {
        put_len_delimited(&mut graph, 5, t);
    }
    let mut obs_doc = "standard observation: q / pi, end-effector position (m), target (m), k * (target - ee), k * |target - ee|".to_string();
    if let Some(o) = &spec.observation.obstacles {
        let (n, len, encoding) = (o.slots, o.values_per_slot, &o.encoding);
        obs_doc.push_str(&format!(", then {n} obstacle slots of {len} values ({encoding} encoding)"));
    }
    put_len_delimited(&mut graph, 11, &value_info(INPUT, spec.observation.dim, &obs_doc));
    let out_doc = "joint velocity command, rad/s (m/s for prismatic joints)";
    put_len_delimited(&mut graph, 12, &value_info(OUTPUT, spec.action.dim, out_doc));
    let mut model = Vec::new();
    put_int(&mut model, 1, IR_VERSION);
    put_str(&mut model, 2, "stagerl");
    put_str(&mut model, 3, env!("CARGO_PKG_VERSION"));
    put_str(&mut model, 6, "A stagerl reaching policy: joint velocities (rad/s) from an observation");
    put_len_delimited(&mut model, 7, &graph);
    let mut opset = Vec::new();
    put_str(&mut opset, 1, "");
    put_int(&mut opset, 2, OPSET);
    put_len_delimited(&mut model, 8, &opset);
    for (k, v) in metadata(spec, info) {
        let mut e = Vec::new();
        put_str(&mut e, 1, &k);
        put_str(&mut e, 2, &v);
        put_len_delimited(&mut model, 14, &e);
    }
    Ok(model)
}
