//! Obstacles from Python (`stagerl.plan(..., obstacles=)`, `ReachEnv.reset(options={"obstacles":
//! ...})`, `ReachVectorEnv.reset(options=...)`): a list of dicts in the schema of `[[task.obstacles]]` and of a `stagerl plan` request
//! line, `{"shape": "sphere", "radius_m": r, "position_m": [x, y, z]}` or `{"shape": "cuboid",
//! "half_extents_m": [..], "position_m": [..], "rotation_xyzw": [..]}`. The shapes of the values
//! are checked here; their values by the library ([`stagerl::env::request`]), so that a bad value
//! gets the message the command line gives.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use stagerl::sim::scene::{Obstacle, ObstacleShape};

use crate::bad_arg;

const FIELDS: &str = "shape, radius_m, half_extents_m, position_m, rotation_xyzw";

/// `n` numbers of `d[key]` (`None` when absent), named `field` in errors.
fn numbers<const N: usize>(d: &Bound<'_, PyDict>, key: &str, field: &str) -> PyResult<Option<[f64; N]>> {
    let Some(v) = d.get_item(key)? else { return Ok(None) };
    let what = format!("{N} numbers");
    let values: Vec<f64> = v
        .extract()
        .map_err(|_| bad_arg(field, v.repr().map_or_else(|_| "?".into(), |r| r.to_string()), &what))?;
    <[f64; N]>::try_from(values.as_slice())
        .map(Some)
        .map_err(|_| bad_arg(field, format!("{values:?}"), &what))
}

/// The obstacles of a Python list (or `None`: none given), checked for their values.
pub(crate) fn obstacles_of(list: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Vec<Obstacle>>> {
    let Some(list) = list.filter(|l| !l.is_none()) else { return Ok(None) };
    let list = list.cast::<PyList>().map_err(|_| {
        bad_arg("obstacles", list.repr().map_or_else(|_| "?".into(), |r| r.to_string()), "a list of dicts")
    })?;
    let mut out = Vec::with_capacity(list.len());
    for (i, item) in list.iter().enumerate() {
        let f = |k: &str| format!("obstacles[{i}].{k}");
        let d = item.cast::<PyDict>().map_err(|_| {
            bad_arg(
                &format!("obstacles[{i}]"),
                item.repr().map_or_else(|_| "?".into(), |r| r.to_string()),
                "a dict",
            )
        })?;
        for k in d.keys() {
            let k: String = k.extract().unwrap_or_default();
            if !FIELDS.split(", ").any(|x| x == k) {
                return Err(bad_arg(
                    &format!("obstacles[{i}]"),
                    format!("a field `{k}`"),
                    &format!("fields {FIELDS}"),
                ));
            }
        }
        let shape: String = match d.get_item("shape")? {
            Some(s) => s.extract().unwrap_or_default(),
            None => String::new(),
        };
        let shape = match shape.as_str() {
            "sphere" => ObstacleShape::Sphere,
            "cuboid" => ObstacleShape::Cuboid,
            other => return Err(bad_arg(&f("shape"), format!("{other:?}"), "\"sphere\" or \"cuboid\"")),
        };
        let radius_m = match d.get_item("radius_m")? {
            Some(r) => {
                Some(r.extract::<f64>().map_err(|_| bad_arg(&f("radius_m"), r, "a number of metres"))?)
            }
            None => None,
        };
        let Some(position_m) = numbers::<3>(d, "position_m", &f("position_m"))? else {
            return Err(bad_arg(&f("position_m"), "(unset)", "3 numbers, metres"));
        };
        out.push(Obstacle {
            shape,
            radius_m,
            half_extents_m: numbers::<3>(d, "half_extents_m", &f("half_extents_m"))?,
            position_m,
            rotation_xyzw: numbers::<4>(d, "rotation_xyzw", &f("rotation_xyzw"))?,
        });
    }
    stagerl::env::request::check_obstacle_values(&out, "obstacles").map_err(crate::to_py)?;
    Ok(Some(out))
}

/// Check a request's scene, `obstacles` beside `env`'s fixed ones, for an episode from `start`
/// (to `target`, when given), as `stagerl plan` checks a request's: the same messages.
pub(crate) fn check_scene(
    env: &stagerl::env::ReachEnv,
    obstacles: &[Obstacle],
    start: &[f64],
    target: Option<stagerl::nalgebra::Vector3<f64>>,
) -> PyResult<()> {
    crate::guard("reset", || {
        stagerl::env::check_joint_positions(env.chain(), start).map_err(crate::to_py)?;
        let all: Vec<_> = env.task().obstacles.iter().chain(obstacles).cloned().collect();
        let nf = env.task().obstacles.len();
        let named = |i: usize| match i {
            i if i < nf => format!("task.obstacles[{i}]"),
            i => format!("obstacles[{}]", i - nf),
        };
        let mut c = stagerl::sim::collision::ArmCollider::new(env.chain(), env.task().collision);
        stagerl::env::request::check_scene_for_request(env.chain(), &mut c, &all, named, start, target)
            .map_err(crate::to_py)
    })
}
