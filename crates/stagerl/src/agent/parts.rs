//! An agent's learned state as one list of named parts (networks, optimisers, tensors, random
//! and noise states). Each agent writes that list once, with [`learned_parts!`]; saving, loading
//! and the non-finite guard of [`super::Agent`] all walk it, so they cannot disagree.

use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::io::checkpoint::Checkpoint;
use crate::nn::{first_non_finite, Adam, BrnMlp, Mlp, RunningStats, TensorInfo};
use crate::{Error, Result};

/// The list of an agent's learned parts, each under its checkpoint name, walked in order.
/// Implemented by [`learned_parts!`] from one body, so both methods hand on the same list.
pub trait Learned {
    /// Hand every part, shared, to `f` (saving, the non-finite guard).
    fn parts(&self, f: &mut dyn FnMut(&str, Part<'_>));
    /// Hand every part, mutably, to `f` (loading).
    fn parts_mut(&mut self, f: &mut dyn FnMut(&str, PartMut<'_>));
}

/// One learned part, shared. Checkpoint names: a network's tensors are
/// `{name}.layer{i}.weight|bias`, an optimiser's `{name}.m|v|step`, a tensor is `{name}`, a
/// state `{name}` (JSON); a batch-renormalised network's tensors are its layers' and
/// `{name}.bn{k}.scale|bias`, its running statistics `{name}.bn_stats` (JSON).
pub enum Part<'a> {
    Net(&'a Mlp<f32>),
    BnNet(&'a BrnMlp<f32>),
    Adam(&'a Adam<f32>),
    Tensor(&'a [f32]),
    State(&'a dyn State),
}

/// One learned part, mutable (see [`Part`]).
pub enum PartMut<'a> {
    Net(&'a mut Mlp<f32>),
    BnNet(&'a mut BrnMlp<f32>),
    Adam(&'a mut Adam<f32>),
    Tensor(&'a mut [f32]),
    State(&'a mut dyn State),
}

/// Serialisable state kept in a checkpoint as JSON (random generators, noise processes, counters).
pub trait State {
    fn save_json(&self, ck: &mut Checkpoint, name: &str);
    fn load_json(&mut self, ck: &Checkpoint, name: &str) -> Result<()>;
}

impl<T: Serialize + DeserializeOwned> State for T {
    fn save_json(&self, ck: &mut Checkpoint, name: &str) {
        ck.put_json(name, self);
    }
    fn load_json(&mut self, ck: &Checkpoint, name: &str) -> Result<()> {
        *self = ck.json(name)?;
        Ok(())
    }
}

impl Part<'_> {
    /// Write this part to `ck` under `name`.
    pub fn save(&self, ck: &mut Checkpoint, name: &str) {
        match self {
            Part::Net(net) => save_tensors(ck, name, &net.tensors(), net.params()),
            Part::BnNet(net) => {
                save_tensors(ck, name, &net.tensors(), net.params());
                ck.put_json(&format!("{name}.bn_stats"), &net.running_stats());
            }
            Part::Adam(opt) => {
                ck.put_tensor(&format!("{name}.m"), &[opt.m.len()], &opt.m);
                ck.put_tensor(&format!("{name}.v"), &[opt.v.len()], &opt.v);
                ck.put_json(&format!("{name}.step"), &opt.step);
            }
            Part::Tensor(values) => ck.put_tensor(name, &[values.len()], values),
            Part::State(state) => state.save_json(ck, name),
        }
    }

    /// Describe the first non-finite parameter or gradient of a network, or value of a tensor.
    pub fn first_non_finite(&self, name: &str) -> Option<String> {
        match self {
            Part::Net(net) => non_finite_in(name, &net.tensors(), [net.params(), net.grads()]),
            Part::BnNet(net) => {
                non_finite_in(name, &net.tensors(), [net.params(), net.grads()]).or_else(|| {
                    let stats = net.norms.iter().enumerate();
                    stats.flat_map(|(k, n)| [(k, "mean", &n.stats.mean), (k, "var", &n.stats.var)]).find_map(
                        |(k, what, v)| {
                            let i = v.iter().position(|x| !x.is_finite())?;
                            Some(format!("{name} running {what} bn{k}[{i}] = {}", v[i]))
                        },
                    )
                })
            }
            Part::Tensor(values) => first_non_finite(values).map(|i| format!("{name}[{i}] = {}", values[i])),
            Part::Adam(_) | Part::State(_) => None,
        }
    }
}

impl PartMut<'_> {
    /// Read this part from `ck`. A network's tensors must have this network's shapes and finite
    /// values (a damaged network would only show later, as a NaN action).
    pub fn load(self, ck: &Checkpoint, name: &str) -> Result<()> {
        match self {
            PartMut::Net(net) => load_tensors(ck, name, &net.tensors(), net.params_mut()),
            PartMut::BnNet(net) => {
                load_tensors(ck, name, &net.tensors(), net.params_mut())?;
                let key = format!("{name}.bn_stats");
                let stats: Vec<RunningStats> = ck.json(&key)?;
                net.set_running_stats(&stats).map_err(|e| {
                    Error::InvalidInput(format!("{}: `{key}`: {e} (a different network size?)", ck.name()))
                })
            }
            PartMut::Adam(opt) => {
                ck.read_tensor_into(&format!("{name}.m"), &mut opt.m)?;
                ck.read_tensor_into(&format!("{name}.v"), &mut opt.v)?;
                opt.step = ck.json(&format!("{name}.step"))?;
                Ok(())
            }
            PartMut::Tensor(values) => ck.read_tensor_into(name, values),
            PartMut::State(state) => state.load_json(ck, name),
        }
    }
}

fn save_tensors(ck: &mut Checkpoint, name: &str, tensors: &[TensorInfo], params: &[f32]) {
    for t in tensors {
        ck.put_tensor(&format!("{name}.{}", t.name), &t.shape, &params[t.range()]);
    }
}

/// The first non-finite parameter or gradient of a network, described.
fn non_finite_in(name: &str, tensors: &[TensorInfo], [params, grads]: [&[f32]; 2]) -> Option<String> {
    for (what, values) in [("parameter", params), ("gradient", grads)] {
        if let Some(i) = first_non_finite(values) {
            let tensor = tensors.iter().find(|t| t.range().contains(&i));
            let tname = tensor.map(|t| t.name.as_str()).unwrap_or_default();
            return Some(format!("{name} {what} {tname}[{i}] = {}", values[i]));
        }
    }
    None
}

fn load_tensors(ck: &Checkpoint, prefix: &str, tensors: &[TensorInfo], params: &mut [f32]) -> Result<()> {
    for t in tensors {
        let name = format!("{prefix}.{}", t.name);
        let (shape, data) = ck.tensor(&name)?;
        if shape != t.shape.as_slice() {
            return Err(Error::InvalidInput(format!(
                "{}: tensor `{name}` has shape {shape:?}, this agent's has {:?} \
                 (a different network size or observation?)",
                ck.name(),
                t.shape
            )));
        }
        if let Some(i) = first_non_finite(data) {
            return Err(Error::InvalidInput(format!(
                "{}: tensor `{name}`[{i}] = {} is not finite: the network is damaged",
                ck.name(),
                data[i]
            )));
        }
        params[t.range()].copy_from_slice(data);
    }
    Ok(())
}

/// Implement [`Learned`] for an agent type from one body that lists its parts:
///
/// ```ignore
/// learned_parts!(Sac, |s, f| {
///     f("actor", P::Net(r!(s.actor)));
///     f("agent_rng", P::State(r!(s.rng)));
/// });
/// ```
///
/// The body is expanded twice, once per method: `s` is the agent, `f(name, part)` hands one part
/// on, `P` is [`Part`] or [`PartMut`], `r!(place)` borrows a place (`&` or `&mut`) and
/// `each!(vec)` iterates a `Vec` (`iter` or `iter_mut`).
macro_rules! learned_parts {
    ($ty:ty, |$s:ident, $f:ident| $body:block) => {
        impl $crate::agent::parts::Learned for $ty {
            fn parts(&self, $f: &mut dyn FnMut(&str, $crate::agent::parts::Part<'_>)) {
                use $crate::agent::parts::Part as P;
                macro_rules! r {
                    ($p:expr) => {
                        &$p
                    };
                }
                #[allow(unused_macros)]
                macro_rules! each {
                    ($v:expr) => {
                        $v.iter()
                    };
                }
                let $s = self;
                $body
            }
            fn parts_mut(&mut self, $f: &mut dyn FnMut(&str, $crate::agent::parts::PartMut<'_>)) {
                use $crate::agent::parts::PartMut as P;
                macro_rules! r {
                    ($p:expr) => {
                        &mut $p
                    };
                }
                #[allow(unused_macros)]
                macro_rules! each {
                    ($v:expr) => {
                        $v.iter_mut()
                    };
                }
                let $s = self;
                $body
            }
        }
    };
}
pub(crate) use learned_parts;
