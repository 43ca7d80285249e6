//! `stagerl robot`: what stagerl sees in a URDF, and a task that fits the arm.

use anyhow::{Context, Result};
use stagerl::base::rng::Rng;
use stagerl::robot::{Chain, JointKind, Shape};
use stagerl::sim::collision::{ArmCollider, Checks};
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl robot arm.urdf --package-path ~/ws/src --config-out arm.toml")]
pub struct Args {
    /// The URDF file to look at (the same as `--robot FILE`; `ur5` or `panda` for a bundled arm).
    #[arg(value_name = "URDF", conflicts_with = "robot")]
    urdf: Option<String>,
    #[command(flatten)]
    robot: super::RobotArgs,
    /// Write a config that trains on this arm as it is (robot and task sections; the rest the
    /// defaults) to this file.
    #[arg(long, value_name = "FILE")]
    config_out: Option<PathBuf>,
}

/// The lowest a target may be (the task's default `target_min_z_m`), metres.
const TARGET_MIN_Z_M: f64 = 0.05;
/// Poses drawn to judge a home pose and a target range.
const DRAWS: usize = 400;

pub fn run(mut args: Args) -> Result<()> {
    if let Some(urdf) = args.urdf.take() {
        args.robot.robot = urdf;
    }
    let chain = args.robot.load()?;
    let mut collider = ArmCollider::new(&chain, Checks { floor: true, self_collision: true });
    print_chain(&chain, &collider)?;
    let home = suggest_home(&chain, &mut collider);
    let (range, clear) = suggest_range(&chain, &mut collider, &home);
    outln!("suggested task:")?;
    outln!("  home_pose_rad = {}", toml_list(&home))?;
    outln!("  target_joint_range_rad = {}", toml_list(&range))?;
    if collider.is_empty() {
        outln!("  (no collision shape: targets judged by height only)")?;
    }
    outln!(
        "  ({:.0} % of {DRAWS} targets drawn from it are clear of contacts and above z = {TARGET_MIN_Z_M} m)",
        100.0 * clear
    )?;
    if let Some(out) = &args.config_out {
        let urdf = std::path::Path::new(&args.robot.robot);
        let urdf = match args.robot.robot.as_str() {
            "ur5" | "panda" => args.robot.robot.clone(),
            _ => urdf.canonicalize().unwrap_or_else(|_| urdf.to_path_buf()).display().to_string(),
        };
        let mut text =
            format!("# Written by `stagerl robot` for {urdf}.\n[robot]\nurdf = {}\n", toml_str(&urdf));
        text.push_str(&format!("tip = {}\n", toml_str(chain.tip_link())));
        if !args.robot.package_paths.is_empty() {
            let abs = |p: &PathBuf| p.canonicalize().unwrap_or_else(|_| p.clone()).display().to_string();
            let paths: Vec<String> = args.robot.package_paths.iter().map(|p| toml_str(&abs(p))).collect();
            text.push_str(&format!("package_paths = [{}]\n", paths.join(", ")));
        }
        text.push_str(&format!(
            "\n[task]\nhome_pose_rad = {}\ntarget_joint_range_rad = {}\n",
            toml_list(&home),
            toml_list(&range)
        ));
        std::fs::write(out, text).with_context(|| format!("writing {}", out.display()))?;
        outln!("wrote {}", out.display())?;
    }
    Ok(())
}

fn print_chain(chain: &Chain, collider: &ArmCollider) -> Result<()> {
    outln!("chain: `{}` -> `{}`, {} actuated joints", chain.base_link(), chain.tip_link(), chain.dof())?;
    for j in chain.joints() {
        let (unit, speed) = match j.kind {
            JointKind::Revolute => ("rad", "rad/s"),
            JointKind::Prismatic => ("m", "m/s"),
        };
        let kind = if j.lower.is_infinite() {
            "continuous".to_string()
        } else {
            format!("{:?}", j.kind).to_lowercase()
        };
        outln!(
            "  joint `{}` {kind}: [{}, {}] {unit}, speed {} {speed}, effort {}",
            j.name,
            j.lower,
            j.upper,
            j.velocity,
            j.effort
        )?;
    }
    outln!("collision shapes: {}", chain.collision_shapes().len())?;
    let mut links: Vec<&str> = chain.collision_shapes().iter().map(|s| s.link.as_str()).collect();
    links.dedup();
    for link in links {
        let shapes: Vec<&Shape> =
            chain.collision_shapes().iter().filter(|s| s.link == link).map(|s| &s.shape).collect();
        let mut kinds: Vec<String> = Vec::new();
        for s in &shapes {
            let k = match s {
                Shape::Convex(p) => {
                    format!("convex ({} hull vertices) from `{}`", p.points_m.len(), p.source)
                }
                other => other.kind().to_string(),
            };
            kinds.push(k);
        }
        kinds.dedup();
        outln!("  link `{link}`: {} shape(s): {}", shapes.len(), kinds.join(", "))?;
    }
    for u in chain.unloaded_collision() {
        outln!("  link `{}`: mesh `{}` NOT loaded: {}", u.link, u.file, u.reason)?;
    }
    let mut pairs: Vec<(String, String)> = collider
        .self_pairs()
        .map(|(a, b)| (chain.collision_shapes()[a].link.clone(), chain.collision_shapes()[b].link.clone()))
        .collect();
    let mut unique: Vec<(String, String)> = Vec::new();
    for p in pairs.drain(..) {
        if !unique.contains(&p) {
            unique.push(p);
        }
    }
    let pairs = unique;
    outln!(
        "self-collision pairs (links two or more joints apart): {}",
        if pairs.is_empty() {
            "none".to_string()
        } else {
            pairs.iter().map(|(a, b)| format!("{a}-{b}")).collect::<Vec<_>>().join(", ")
        }
    )?;
    Ok(())
}

/// Whether the arm at `q` is clear of contacts.
fn clear(chain: &Chain, c: &mut ArmCollider, q: &[f64]) -> bool {
    c.check(chain, q).is_none()
}

/// The middle of each joint's range (0 for a continuous joint) if it is clear of contacts and
/// the tip is above the lowest target height, else, of poses drawn within the limits that are,
/// the one farthest from contact (the largest clearance; the tip's height on an arm without
/// collision shapes).
fn suggest_home(chain: &Chain, c: &mut ArmCollider) -> Vec<f64> {
    let (lo, hi) = (chain.lower_limits(), chain.upper_limits());
    let mid: Vec<f64> =
        (0..chain.dof()).map(|i| if lo[i].is_finite() { 0.5 * (lo[i] + hi[i]) } else { 0.0 }).collect();
    let ok = |c: &mut ArmCollider, q: &[f64]| clear(chain, c, q) && chain.fk(q).position.z > TARGET_MIN_Z_M;
    if ok(c, &mid) {
        return mid;
    }
    let mut rng = Rng::new(1);
    let mut best: Option<(f64, Vec<f64>)> = None;
    let mut scratch = Vec::new();
    for _ in 0..DRAWS {
        let q: Vec<f64> = (0..chain.dof())
            .map(|i| {
                if lo[i].is_finite() {
                    rng.uniform_range(lo[i], hi[i])
                } else {
                    rng.uniform_range(-3.0, 3.0)
                }
            })
            .collect();
        if ok(c, &q) {
            let room = c.contacts(chain, &q, &mut scratch).unwrap_or(chain.fk(&q).position.z);
            if best.as_ref().is_none_or(|(b, _)| room > *b) {
                best = Some((room, q));
            }
        }
    }
    best.map_or(mid, |(_, q)| q.iter().map(|x| (x * 1e4).round() / 1e4).collect())
}

/// A target range about `home`: half of each joint's room to its nearer limit (1 rad for a
/// continuous joint), shrunk until at least 90 % of the targets it gives are clear of contacts
/// and above the lowest target height; the range and that fraction.
fn suggest_range(chain: &Chain, c: &mut ArmCollider, home: &[f64]) -> (Vec<f64>, f64) {
    let (lo, hi) = (chain.lower_limits(), chain.upper_limits());
    let room: Vec<f64> = (0..chain.dof())
        .map(|i| if lo[i].is_finite() { (home[i] - lo[i]).min(hi[i] - home[i]) } else { 2.0 })
        .collect();
    let mut scale = 0.5;
    loop {
        let range: Vec<f64> = room.iter().map(|r| (r * scale * 1e4).round() / 1e4).collect();
        let mut rng = Rng::new(2);
        let mut ok = 0;
        for _ in 0..DRAWS {
            let q: Vec<f64> =
                (0..chain.dof()).map(|i| home[i] + rng.uniform_range(-1.0, 1.0) * range[i]).collect();
            if clear(chain, c, &q) && chain.fk(&q).position.z > TARGET_MIN_Z_M {
                ok += 1;
            }
        }
        let frac = ok as f64 / DRAWS as f64;
        if frac >= 0.9 || scale < 0.05 {
            return (range, frac);
        }
        scale *= 0.7;
    }
}

fn toml_list(v: &[f64]) -> String {
    format!("[{}]", v.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(", "))
}

fn toml_str(s: &str) -> String {
    // A TOML basic string is a JSON string.
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
}
