use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use stagerl::robot::Chain;
use stagerl::sim::collision::{ArmCollider, Checks, Contact};

#[derive(clap::Args)]
#[command(after_help = "Example:\n  echo '{\"joints\":[0,-1.57,1.57,-1.57,-1.57,0]}' | stagerl fk")]
pub struct Args {
    #[command(flatten)]
    robot: super::RobotArgs,
    /// Also check the pose for contacts with the floor (z = 0) and between links no joint
    /// connects: each line gets `"contacts"` (`{"with":"floor","link":..}`,
    /// `{"with":"self","links":[..,..]}`) and `"clearance_m"`, the smallest signed distance
    /// over the checked pairs (negative: a penetration's depth).
    #[arg(long)]
    collisions: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Input {
    joints: Vec<f64>,
}

#[derive(Serialize)]
struct Output {
    position: [f64; 3],
    quaternion: [f64; 4],
    #[serde(flatten)]
    collisions: Option<Collisions>,
}

#[derive(Serialize)]
struct Collisions {
    contacts: Vec<ContactOut>,
    /// Metres; `None` (null) when no pair was checked.
    clearance_m: Option<f64>,
}

#[derive(Serialize, PartialEq)]
#[serde(tag = "with", rename_all = "snake_case")]
enum ContactOut {
    Floor {
        link: String,
    },
    #[serde(rename = "self")]
    SelfCollision {
        links: [String; 2],
    },
}

/// The contacts of the arm at `q`, one per link (floor) or pair of links (self).
fn collisions(
    chain: &Chain,
    collider: &mut ArmCollider,
    q: &[f64],
    scratch: &mut Vec<Contact>,
) -> Collisions {
    let clearance_m = collider.contacts(chain, q, scratch);
    let link = |k: usize| chain.collision_shapes()[k].link.clone();
    let mut contacts: Vec<ContactOut> = Vec::new();
    for c in scratch.iter() {
        let out = match *c {
            Contact::Floor { shape } => ContactOut::Floor { link: link(shape) },
            Contact::SelfCollision { shape_a, shape_b } => {
                ContactOut::SelfCollision { links: [link(shape_a), link(shape_b)] }
            }
            // No obstacles here.
            Contact::Obstacle { .. } => continue,
        };
        if !contacts.contains(&out) {
            contacts.push(out);
        }
    }
    Collisions { contacts, clearance_m }
}

pub fn run(args: Args) -> Result<()> {
    let chain = args.robot.load()?;
    let mut collider = None;
    if args.collisions {
        if chain.collision_shapes().is_empty() {
            bail!(
                "robot `{}` has no collision shapes on the chain `{}` -> `{}`: --collisions has nothing to check",
                args.robot.robot,
                chain.base_link(),
                chain.tip_link()
            );
        }
        collider = Some(ArmCollider::new(&chain, Checks { floor: true, self_collision: true }));
    }
    let mut scratch = Vec::new();
    let stdin = std::io::stdin().lock();
    let stdout = crate::out::stdout()?;
    crate::jsonl::process(stdin, stdout, |input: Input| {
        let pose = chain.try_fk(&input.joints)?;
        let collisions = collider.as_mut().map(|c| collisions(&chain, c, &input.joints, &mut scratch));
        Ok(Output { position: pose.position.into(), quaternion: pose.quaternion_xyzw(), collisions })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random finite f64 bit patterns (subnormals and extremes included) written as JSON numbers
    /// in several notations come back from `fk`'s line parser with the same bits.
    #[test]
    fn joints_parse_bit_exactly() {
        let mut rng = stagerl::base::rng::Rng::new(4);
        let mut values = vec![f64::MAX, f64::MIN, f64::MIN_POSITIVE, f64::from_bits(1), -0.0, 0.1];
        while values.len() < 60_000 {
            let bits = rng.next_u64();
            if f64::from_bits(bits).is_finite() {
                values.push(f64::from_bits(bits));
            }
            values.push(f64::from_bits(bits & 0x800F_FFFF_FFFF_FFFF)); // a subnormal
        }
        let mut input = String::new();
        for chunk in values.chunks(6) {
            // Shortest round-trip decimal, exponent notation, and 17 significant digits.
            for fmt in [0, 1, 2] {
                let nums: Vec<String> = chunk
                    .iter()
                    .map(|x| match fmt {
                        0 => format!("{x:?}"),
                        1 => format!("{x:e}"),
                        _ => format!("{x:.16e}"),
                    })
                    .collect();
                input.push_str(&format!("{{\"joints\":[{}]}}\n", nums.join(",")));
            }
        }
        let mut parsed = Vec::new();
        crate::jsonl::process(input.as_bytes(), std::io::sink(), |i: Input| {
            parsed.push(i.joints);
            Ok(0)
        })
        .unwrap();
        let expected: Vec<&[f64]> = values.chunks(6).flat_map(|c| [c, c, c]).collect();
        assert_eq!(parsed.len(), expected.len());
        for (got, want) in parsed.iter().zip(expected) {
            let same = got.iter().zip(want).all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same && got.len() == want.len(), "{want:?} parsed as {got:?}");
        }
    }
}
