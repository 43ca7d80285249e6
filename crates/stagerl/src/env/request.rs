//! The obstacles of one request (a line of `stagerl plan --targets`, `--scene`, the Python
//! `plan(obstacles=)` and `reset(options={"obstacles": ...})`): checked before an episode starts
//! among them, with messages that name the obstacle's field (`obstacles[2].radius_m`), the value
//! and what is allowed.
//!
//! Refused: a value that is not finite, a size that is not positive (or over 100 m), a rotation
//! that is not a unit quaternion (x, y, z, w), more than [`MAX_OBSTACLES`] obstacles, an obstacle
//! that encloses the target (the target is inside it or on its surface), an obstacle the arm at
//! its start pose touches (it encloses part of the start pose), and a start pose in any other
//! contact the task checks (the floor, the arm itself).

use nalgebra::Vector3;

use crate::robot::Chain;
use crate::sim::collision::ArmCollider;
use crate::sim::scene::{Obstacle, MAX_OBSTACLES};
use crate::{Error, Result};

/// An error of a request's obstacle: `InvalidInput` with the field, the value, what is allowed.
fn invalid(e: Error) -> Error {
    match e {
        Error::Config { field, value, allowed } => {
            Error::InvalidInput(format!("`{field}` = {value} is invalid: {allowed}"))
        }
        other => other,
    }
}

/// Check a request's obstacles' values; `field` names the list (`obstacles`: `obstacles[i]` in
/// the messages).
pub fn check_obstacle_values(obstacles: &[Obstacle], field: &str) -> Result<()> {
    if obstacles.len() > MAX_OBSTACLES {
        return Err(Error::InvalidInput(format!(
            "`{field}` holds {} obstacles, at most {MAX_OBSTACLES} are allowed",
            obstacles.len()
        )));
    }
    for (i, o) in obstacles.iter().enumerate() {
        o.validate(&format!("{field}[{i}]")).map_err(invalid)?;
    }
    Ok(())
}

/// Check a scene against a request: no obstacle encloses `target` (when given) or touches the
/// arm at `start`,
/// and `start` is in no other contact of the checker `c`'s checks (whose obstacles it leaves
/// cleared). `named` gives each obstacle's field name.
pub fn check_scene_for_request(
    chain: &Chain,
    c: &mut ArmCollider,
    obstacles: &[Obstacle],
    named: impl Fn(usize) -> String,
    start: &[f64],
    target: Option<Vector3<f64>>,
) -> Result<()> {
    for (i, o) in obstacles.iter().enumerate() {
        let Some(target) = target else { break };
        let t: [f64; 3] = target.into();
        let d = o.distance_to_point_m(t);
        if d <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "`{}` = {} is invalid: it encloses the target [{}, {}, {}] ({} m inside); an \
                 obstacle must leave the target outside it",
                named(i),
                describe(o),
                t[0],
                t[1],
                t[2],
                -d
            )));
        }
    }
    if chain.collision_shapes().is_empty() {
        return Ok(());
    }
    for (i, o) in obstacles.iter().enumerate() {
        if c.touches(chain, start, o) {
            return Err(Error::InvalidInput(format!(
                "`{}` = {} is invalid: the arm at its start pose {start:?} touches it (the obstacle \
                 encloses part of the start pose); an obstacle must leave the start pose clear",
                named(i),
                describe(o)
            )));
        }
    }
    c.set_obstacles(&[]);
    if let Some(contact) = c.check(chain, start) {
        return Err(Error::InvalidInput(format!(
            "the start pose {start:?} is already in contact ({}); plan from a pose clear of the \
             floor and of itself",
            contact.describe(chain)
        )));
    }
    Ok(())
}

/// An obstacle in its request's JSON form.
pub fn describe(o: &Obstacle) -> String {
    serde_json::to_string(o).unwrap_or_else(|_| format!("{o:?}"))
}

/// A scene file (`stagerl plan --scene FILE.toml`): `[[obstacles]]` tables in the schema of
/// `[[task.obstacles]]`, nothing else.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    #[serde(default)]
    obstacles: Vec<Obstacle>,
}

/// Parse a scene file's text; `origin` names it in messages. The values are checked with
/// [`check_obstacle_values`] (field `obstacles`).
pub fn parse_scene(text: &str, origin: &str) -> Result<Vec<Obstacle>> {
    let scene: SceneFile = toml::from_str(text).map_err(|e| {
        Error::InvalidInput(format!(
            "scene file {origin}: {} (expected [[obstacles]] tables such as shape = \"sphere\", \
             radius_m = 0.05, position_m = [0.4, 0.0, 0.3])",
            e.message()
        ))
    })?;
    check_obstacle_values(&scene.obstacles, &format!("{origin}: obstacles"))?;
    Ok(scene.obstacles)
}
