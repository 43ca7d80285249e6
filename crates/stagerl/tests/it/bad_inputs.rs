//! Bad inputs to the library: configs, URDFs and checkpoints. Every case must be refused with an
//! error (never a panic) whose message contains the case's substring, which names the field,
//! joint, link or file at fault. Checkpoint cases also check that nothing on disk changed.
//!
//! The cases are data: adding one is adding one line to a table.

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use stagerl::agent::Algo;
use stagerl::config::Config;
use stagerl::env::ReachEnv;
use stagerl::io::checkpoint::Checkpoint;
use stagerl::robot::Chain;
use stagerl::run::dir::RunDir;
use stagerl::train::{load_agent, train};

/// A scratch directory, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(tag: &str) -> Scratch {
        let p = std::env::temp_dir().join(format!("stagerl-bad-{tag}-{}", std::process::id()));
        std::fs::remove_dir_all(&p).ok();
        std::fs::create_dir_all(&p).unwrap();
        Scratch(p)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// Run `f`, expecting an error containing `needle`; a panic, a success or another message is a
/// failure, described in the returned string.
fn expect_err<T>(case: &str, needle: &str, f: impl FnOnce() -> stagerl::Result<T>) -> Option<String> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            Some(format!("{case}: panicked: {msg}"))
        }
        Ok(Ok(_)) => Some(format!("{case}: accepted, expected an error containing {needle:?}")),
        Ok(Err(e)) => {
            let e = e.to_string();
            if std::env::var_os("STAGERL_SHOW_ERRORS").is_some() {
                eprintln!("{case}\n    -> {e}");
            }
            (!e.contains(needle)).then(|| format!("{case}: error {e:?} does not contain {needle:?}"))
        }
    }
}

fn report(failures: Vec<String>, total: usize) {
    assert!(failures.is_empty(), "{} of {total} cases failed:\n{}", failures.len(), failures.join("\n"));
}

// ---------------------------------------------------------------------------------------------
// Configs: parsed, validated, then resolved against the arm (`ReachEnv::from_config`).
// `$DIR` is replaced by a directory holding `two.urdf` (a two-joint arm) and `bad.urdf` (branches).

struct Cfg {
    toml: &'static str,
    expect: &'static str,
}

#[rustfmt::skip]
const CONFIGS: &[Cfg] = &[
    // Wrong types.
    Cfg { toml: "[task]\ndt_s = \"fast\"\n", expect: "dt_s" },
    Cfg { toml: "[agent]\nhidden = 64\n", expect: "hidden" },
    Cfg { toml: "[reward]\ndirection_fold = \"yes\"\n", expect: "direction_fold" },
    Cfg { toml: "[train]\nseed = 1.5\n", expect: "seed" },
    Cfg { toml: "[task]\nmax_steps = 5000000000\n", expect: "max_steps" },
    Cfg { toml: "[train]\nepisodes = -5\n", expect: "episodes" },
    Cfg { toml: "[agent]\nalgo = \"a2c\"\n", expect: "a2c" },
    // PPO and hindsight relabelling.
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.ppo]\nnum_envs = 0\n", expect: "agent.ppo.num_envs" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.ppo]\nnum_minibatches = 100000\n", expect: "agent.ppo.num_minibatches" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.ppo]\ngae_lambda = 1.5\n", expect: "agent.ppo.gae_lambda" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.ppo]\nclip_coef = 0\n", expect: "agent.ppo.clip_coef" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\nnum_envs = 4\n", expect: "[agent.ppo]" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.ppo]\nnorm_obs = { clip = -1.0 }\n", expect: "agent.ppo.norm_obs.clip" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.ppo]\nnorm_obs = { clip = nan }\n", expect: "agent.ppo.norm_obs.clip" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.ppo]\nnorm_obs = { scale = 2.0 }\n", expect: "scale" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\n[agent.her]\nk = 4\n", expect: "agent.her" },
    Cfg { toml: "[agent]\nalgo = \"ppo\"\nnorm_obs = { clip = 10.0 }\n", expect: "agent.ppo.norm_obs" },
    Cfg { toml: "[agent]\nnorm_obs = { clip = -1.0 }\n", expect: "agent.norm_obs.clip" },
    Cfg { toml: "[agent]\nalgo = \"td3\"\nnorm_obs = { clip = 2e6 }\n", expect: "agent.norm_obs.clip" },
    Cfg { toml: "[agent.her]\nk = 0\n", expect: "agent.her.k" },
    // Obstacles.
    Cfg { toml: "[[task.obstacles]]\nshape = \"sphere\"\nradius_m = -1\nposition_m = [0.5, 0, 0.2]\n", expect: "task.obstacles[0].radius_m" },
    Cfg { toml: "[[task.obstacles]]\nshape = \"cuboid\"\nradius_m = 0.1\nposition_m = [0.5, 0, 0.2]\n", expect: "task.obstacles[0].radius_m" },
    Cfg { toml: "[[task.obstacles]]\nshape = \"cuboid\"\nposition_m = [0.5, 0, 0.2]\n", expect: "task.obstacles[0].half_extents_m" },
    Cfg { toml: "[[task.obstacles]]\nshape = \"cone\"\nradius_m = 0.1\nposition_m = [0.5, 0, 0.2]\n", expect: "cone" },
    Cfg { toml: "[[task.obstacles]]\nshape = \"sphere\"\nradius_m = 0.1\nposition_m = [0.5, 0, 0.2]\ncolour = 1\n", expect: "colour" },
    Cfg { toml: "[[task.obstacles]]\nshape = \"sphere\"\nradius_m = 0.1\nposition_m = [0.5, 0, 0.2]\nrotation_xyzw = [0, 0, 0, 2]\n", expect: "task.obstacles[0].rotation_xyzw" },
    Cfg { toml: "[[task.obstacles]]\nshape = \"sphere\"\nradius_m = 0.1\nposition_m = [0.5, 0, 1e300]\n", expect: "task.obstacles[0].position_m" },
    Cfg { toml: "[task.collision]\nfloor = 1\n", expect: "floor" },
    Cfg { toml: "[agent.her]\nstrategy = \"sometimes\"\n", expect: "strategy" },
    Cfg { toml: "[agent.her]\nratio = 0.8\n", expect: "ratio" },
    Cfg { toml: "[reward]\nfunction = \"SAR\"\n", expect: "SAR" },
    Cfg { toml: "[agent.ddpg]\nnoise = \"pink\"\n", expect: "pink" },
    Cfg { toml: "[task]\nobservation = \"pixels\"\n", expect: "pixels" },
    Cfg { toml: "reward = 3\n", expect: "reward" },
    // Malformed TOML: the message names the file and the line.
    Cfg { toml: "[task\ndt_s = 0.05\n", expect: "line 1" },
    Cfg { toml: "[task]\ndt_s = 0.05\ndt_s = 0.1\n", expect: "dt_s" },
    // Unknown fields and sections.
    Cfg { toml: "[task]\nmax_step = 10\n", expect: "unknown field `max_step`" },
    Cfg { toml: "[optimizer]\nlr = 1e-3\n", expect: "unknown field `optimizer`" },
    Cfg { toml: "[agent.sac]\nalpha = 0.2\n", expect: "unknown field `alpha`" },
    // Out-of-range values.
    Cfg { toml: "[task]\ndt_s = -0.05\n", expect: "task.dt_s" },
    Cfg { toml: "[task]\nmax_steps = 0\n", expect: "task.max_steps" },
    Cfg { toml: "[task]\nobs_delta_scale = 1e40\n", expect: "task.obs_delta_scale" },
    Cfg { toml: "[reward]\nbeta_m = 0\n", expect: "reward.beta_m" },
    Cfg { toml: "[reward]\nhar_boundary_m = -0.5\n", expect: "reward.har_boundary_m" },
    Cfg { toml: "[reward]\nsar_scale_m = 0\n", expect: "reward.sar_scale_m" },
    Cfg { toml: "[robot]\nurdf = \"  \"\n", expect: "robot.urdf" },
    // NaN and infinities.
    Cfg { toml: "[reward]\nsar_sigma2 = nan\n", expect: "reward.sar_sigma2" },
    Cfg { toml: "[reward]\nsuccess_bonus = -inf\n", expect: "reward.success_bonus" },
    Cfg { toml: "[task]\ndt_s = inf\n", expect: "task.dt_s" },
    Cfg { toml: "[task]\ntarget_min_z_m = nan\n", expect: "task.target_min_z_m" },
    Cfg { toml: "[agent]\nmax_grad_norm = nan\n", expect: "agent.max_grad_norm" },
    Cfg { toml: "[agent]\ncritic_lr = inf\n", expect: "agent.critic_lr" },
    Cfg { toml: "[task]\nhome_pose_rad = [nan, 0, 0, 0, 0, 0]\n", expect: "task.home_pose_rad[0]" },
    // Per-joint vectors: wrong lengths, outside the joint limits, negative ranges.
    Cfg { toml: "[task]\nhome_pose_rad = [0, 0, 0]\n", expect: "task.home_pose_rad" },
    Cfg { toml: "[task]\ntarget_joint_range_rad = [1, 1, 1, 1, 1, 1, 1]\n", expect: "6 joints" },
    Cfg { toml: "[task]\nhome_pose_rad = []\n", expect: "task.home_pose_rad" },
    Cfg { toml: "[task]\nhome_pose_rad = [0, 0, 4, 0, 0, 0]\n", expect: "elbow_joint" },
    Cfg { toml: "[task]\ntarget_joint_range_rad = [1, -0.1, 0, 0, 0, 0]\n", expect: "task.target_joint_range_rad[1]" },
    // Unreachable targets.
    Cfg { toml: "[task]\ntarget_min_z_m = 5.0\n", expect: "task.target_min_z_m" },
    Cfg { toml: "[task]\ntarget_joint_range_rad = [0, 0, 0, 0, 0, 0]\ntarget_min_z_m = 0.5\n", expect: "0 of 2000" },
    // Missing sections: a non-UR5 arm needs its [task] vectors.
    Cfg { toml: "[robot]\nurdf = \"$DIR/two.urdf\"\n", expect: "task.home_pose_rad" },
    Cfg { toml: "[robot]\nurdf = \"$DIR/two.urdf\"\n[task]\nhome_pose_rad = [0, 0]\n", expect: "task.target_joint_range_rad" },
    // The arm itself.
    Cfg { toml: "[robot]\nurdf = \"$DIR/missing.urdf\"\n", expect: "missing.urdf" },
    Cfg { toml: "[robot]\nurdf = \"$DIR/bad.urdf\"\n", expect: "several leaf links" },
    Cfg { toml: "[robot]\ntip = \"flange\"\n", expect: "unknown tip link `flange`" },
    // Agent and training values.
    Cfg { toml: "[agent]\nhidden = []\n", expect: "agent.hidden" },
    Cfg { toml: "[agent]\nhidden = [64, 0]\n", expect: "agent.hidden" },
    Cfg { toml: "[agent]\nhidden = [100000]\n", expect: "agent.hidden" },
    Cfg { toml: "[agent]\nactor_lr = -1e-3\n", expect: "agent.actor_lr" },
    Cfg { toml: "[agent]\ngamma = 1.5\n", expect: "agent.gamma" },
    Cfg { toml: "[agent]\ntau = 0\n", expect: "agent.tau" },
    Cfg { toml: "[agent]\nbatch_size = 0\n", expect: "agent.batch_size" },
    Cfg { toml: "[agent]\nbatch_size = 100000000000\n", expect: "agent.batch_size" },
    Cfg { toml: "[agent]\nbuffer_size = 100000000000000\n", expect: "agent.buffer_size" },
    // Within each field's range, but too much memory together (estimated before allocating).
    Cfg { toml: "[agent]\nhidden = [16384, 16384, 16384, 16384]\n", expect: "`agent.hidden` = [16384, 16384, 16384, 16384] is invalid: the run would need about 60.8 GiB (networks 60.0" },
    Cfg { toml: "[agent]\nhidden = [4096, 4096]\nbuffer_size = 100000000\n", expect: "`agent.buffer_size` = 100000000 is invalid: the run would need about 16." },
    Cfg { toml: "[agent]\nupdates_per_step = 0\n", expect: "agent.updates_per_step" },
    Cfg { toml: "[agent]\nalgo = \"td3\"\n[agent.td3]\npolicy_delay = 0\n", expect: "agent.td3.policy_delay" },
    Cfg { toml: "[agent]\nalgo = \"ddpg\"\n[agent.ddpg]\nnoise_sigma = -0.1\n", expect: "agent.ddpg.noise_sigma" },
    Cfg { toml: "[agent.td3]\nou_theta = nan\n", expect: "agent.td3.ou_theta" },
    Cfg { toml: "[agent.sac]\ninit_alpha = 0\n", expect: "agent.sac.init_alpha" },
    // Algorithm settings belong in their algorithm's section.
    Cfg { toml: "[agent]\npolicy_delay = 2\n", expect: "`policy_delay` in [agent] (= 2): it is an algorithm's own setting and belongs in [agent.td3]" },
    Cfg { toml: "[agent]\nalgo = \"ddpg\"\nnoise = \"ou\"\n", expect: "belongs in [agent.ddpg] or [agent.td3]" },
    Cfg { toml: "[agent]\ninit_alpha = 0.5\n", expect: "belongs in [agent.sac]" },
    Cfg { toml: "[agent.ddpg]\npolicy_delay = 2\n", expect: "unknown field `policy_delay`" },
    Cfg { toml: "[agent.sac]\npolicy_delay = 0\n", expect: "`agent.sac.policy_delay` = 0 is invalid: an integer >= 1" },
    Cfg { toml: "[agent.sac]\npolicy_delay = -1\n", expect: "policy_delay" },
    Cfg { toml: "[agent.sac]\nactor_log_std = \"softplus\"\n", expect: "unknown variant `softplus`, expected `tanh` or `clip`" },
    Cfg { toml: "[agent.sac]\nactor_log_std = 2\n", expect: "actor_log_std" },
    Cfg { toml: "[train]\nepisodes = 0\n", expect: "train.episodes" },
    Cfg { toml: "[train]\neval_trials = 0\n", expect: "train.eval_trials" },
    Cfg { toml: "[train]\nobstacles_in_path = 0.5\n", expect: "train.obstacles_in_path" },
    Cfg { toml: "[train]\nobstacles_in_path = 2\n[task.random_obstacles]\n", expect: "train.obstacles_in_path" },
    Cfg { toml: "[train]\nobstacles_in_path = nan\n[task.random_obstacles]\n", expect: "train.obstacles_in_path" },
    // Settings that make a check or a mechanism a no-op (or fire at once).
    Cfg { toml: "[task]\non_collision = \"terminate\"\n[task.collision]\nfloor = false\nself_collision = false\n", expect: "no contact can ever end an episode" },
    Cfg { toml: "[task]\non_collision = \"terminate\"\n[[task.obstacles]]\nshape = \"sphere\"\nradius_m = 0.3\nposition_m = [0, 0, 0.6]\n", expect: "touches (link `" },
    Cfg { toml: "[task.random_obstacles]\ntarget_clearance_m = 1e9\n", expect: "`task.random_obstacles` = { target_clearance_m = 1000000000" },
    Cfg { toml: "[task.random_obstacles]\nregion_min_m = [-0.1, -0.1, 0.0]\nregion_max_m = [0.1, 0.1, 0.3]\nsize_m = [0.5, 0.6]\n", expect: "none of up to" },
    // Its meshes cannot be found: an error naming the link and the file; told to go on without
    // them, the checks that would then never see a contact are refused.
    Cfg { toml: "[robot]\nurdf = \"$DIR/mesh.urdf\"\n[task]\nhome_pose_rad = [0, 0]\ntarget_joint_range_rad = [1, 1]\n", expect: "link `l1`: collision mesh `package://x/m.stl` cannot be used" },
    Cfg { toml: "[robot]\nurdf = \"$DIR/mesh.urdf\"\nmissing_collision = \"ignore\"\n[task]\nhome_pose_rad = [0, 0]\ntarget_joint_range_rad = [1, 1]\n", expect: "the collision meshes of links `l1`, `tip` were not loaded" },
    // PPO's minibatch (num_envs x num_steps / num_minibatches rows) counts in the estimate.
    Cfg { toml: "[agent]\nalgo = \"ppo\"\nhidden = [4096, 4096]\n[agent.ppo]\nnum_envs = 4096\nnum_steps = 1024\nnum_minibatches = 1\n", expect: "`agent.ppo.num_minibatches` = 1 (minibatches of 4194304 transitions) is invalid" },
];

const TWO_JOINT_URDF: &str = r#"<robot name="two">
  <link name="base"/><link name="l1"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
    <origin xyz="0.5 0 0.2"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"#;

#[test]
fn bad_configs_are_refused_naming_the_field() {
    let dir = Scratch::new("cfg");
    std::fs::write(dir.0.join("two.urdf"), TWO_JOINT_URDF).unwrap();
    // The two-joint arm with mesh collision geometry only.
    let mesh = "<collision><geometry><mesh filename=\"package://x/m.stl\"/></geometry></collision>";
    std::fs::write(
        dir.0.join("mesh.urdf"),
        TWO_JOINT_URDF
            .replace("<link name=\"l1\"/>", &format!("<link name=\"l1\">{mesh}</link>"))
            .replace("<link name=\"tip\"/>", &format!("<link name=\"tip\">{mesh}</link>")),
    )
    .unwrap();
    std::fs::write(
        dir.0.join("bad.urdf"),
        TWO_JOINT_URDF.replace("<link name=\"tip\"/>", "<link name=\"tip\"/><link name=\"side\"/>").replace(
            "</robot>",
            "<joint name=\"j3\" type=\"fixed\"><parent link=\"base\"/><child link=\"side\"/></joint></robot>",
        ),
    )
    .unwrap();
    let failures: Vec<String> = CONFIGS
        .iter()
        .enumerate()
        .filter_map(|(i, c)| {
            let text = c.toml.replace("$DIR", &dir.0.to_string_lossy());
            let path = dir.0.join(format!("case{i}.toml"));
            std::fs::write(&path, &text).unwrap();
            expect_err(&format!("config case {i} {:?}", c.toml), c.expect, || {
                let cfg = Config::load(&path)?;
                ReachEnv::from_config(&cfg, 0)
            })
        })
        .collect();
    report(failures, CONFIGS.len());
}

#[test]
fn config_parse_errors_name_the_file() {
    // The file name is part of every parse error, and of a read error.
    let e =
        Config::from_toml_str("[task]\nmax_step = 1\n", Path::new("my-run.toml")).unwrap_err().to_string();
    assert!(e.contains("my-run.toml") && e.contains("max_step"), "{e}");
    let e = Config::load(Path::new("/nonexistent/dir/run.toml")).unwrap_err().to_string();
    assert!(e.contains("/nonexistent/dir/run.toml"), "{e}");
    // Not UTF-8.
    let dir = Scratch::new("cfg-utf8");
    let p = dir.0.join("latin1.toml");
    std::fs::write(&p, b"[task]\n# caf\xe9\n").unwrap();
    let e = Config::load(&p).unwrap_err().to_string();
    assert!(e.contains("latin1.toml"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// URDFs. A compact notation: `links` are space-separated names; `joints` are `;`-separated
// `name type parent child [| extra XML]`. An actuated joint gets `<axis xyz="0 0 1"/>` and a
// `<limit>` unless its extra XML has its own, or says `nolimit`. `raw` replaces the whole document.

struct Urdf {
    links: &'static str,
    joints: &'static str,
    raw: Option<&'static str>,
    tip: Option<&'static str>,
    expect: &'static str,
}

const LIMIT: &str = r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#;

#[rustfmt::skip]
const URDFS: &[Urdf] = &[
    // Malformed documents.
    Urdf { links: "", joints: "", raw: Some(""), tip: None, expect: "cannot parse" },
    Urdf { links: "", joints: "", raw: Some("hello, robot"), tip: None, expect: "cannot parse" },
    Urdf { links: "", joints: "", raw: Some(r#"<robot name="r"><link name="a">"#), tip: None, expect: "cannot parse" },
    Urdf { links: "", joints: "", raw: Some(r#"<robot name="r"><link name="a"/><joint name="j" type="hinge"><parent link="a"/><child link="a"/></joint></robot>"#), tip: None, expect: "cannot parse" },
    Urdf { links: "", joints: "", raw: Some(r#"<robot name="r"></robot>"#), tip: None, expect: "has no links" },
    Urdf { links: "a b", joints: "j revolute a b | <origin xyz=\"0 zero 0\"/>", raw: None, tip: None, expect: "cannot parse" },
    // Not a serial chain.
    Urdf { links: "base a b", joints: "ja revolute base a; jb revolute base b", raw: None, tip: None, expect: "several leaf links (`a`, `b`)" },
    Urdf { links: "r1 r2 a", joints: "j1 revolute r1 a", raw: None, tip: None, expect: "more than one root link" },
    Urdf { links: "base a", joints: "j1 revolute base a; j2 revolute base a", raw: None, tip: None, expect: "child of two joints, `j1` and `j2`" },
    Urdf { links: "a b", joints: "j1 revolute a b; j2 revolute b a", raw: None, tip: Some("a"), expect: "no root link" },
    Urdf { links: "base a b c", joints: "j0 revolute base a; j1 revolute b c; j2 revolute c b", raw: None, tip: Some("c"), expect: "form a cycle" },
    Urdf { links: "base a", joints: "j1 revolute base ghost", raw: None, tip: None, expect: "child link `ghost`, which does not exist" },
    Urdf { links: "base a", joints: "j1 revolute phantom a", raw: None, tip: None, expect: "parent link `phantom`, which does not exist" },
    Urdf { links: "base a a", joints: "j1 revolute base a", raw: None, tip: None, expect: "link `a` is defined twice" },
    Urdf { links: "base a b", joints: "j1 revolute base a; j1 revolute a b", raw: None, tip: None, expect: "joint `j1` is defined twice" },
    Urdf { links: "base a", joints: "j1 revolute base a", raw: None, tip: Some("tool0"), expect: "unknown tip link `tool0`" },
    Urdf { links: "base a", joints: "j1 fixed base a", raw: None, tip: None, expect: "no actuated joint" },
    // Unsupported joints on the chain.
    Urdf { links: "base a", joints: "j1 floating base a", raw: None, tip: None, expect: "joint `j1` on the chain from `base` to `a` has unsupported type" },
    Urdf { links: "base a", joints: "j1 planar base a", raw: None, tip: None, expect: "joint `j1` on the chain from `base` to `a` has unsupported type Planar" },
    Urdf { links: "base a b", joints: "j1 revolute base a; j2 revolute a b | <mimic joint=\"j1\"/>", raw: None, tip: None, expect: "mimics joint `j1`" },
    // Missing or unusable limits.
    Urdf { links: "base a", joints: "j1 revolute base a | nolimit", raw: None, tip: None, expect: "joint `j1` (Revolute) has no usable <limit>" },
    Urdf { links: "base a", joints: "j1 prismatic base a | <limit lower=\"1\" upper=\"-1\" effort=\"1\" velocity=\"1\"/>", raw: None, tip: None, expect: "joint `j1` (Prismatic) has no usable <limit>" },
    Urdf { links: "base a", joints: "j1 revolute base a | <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"0\"/>", raw: None, tip: None, expect: "velocity = 0" },
    Urdf { links: "base a", joints: "j1 revolute base a | <limit lower=\"-inf\" upper=\"1\" effort=\"1\" velocity=\"1\"/>", raw: None, tip: None, expect: "lower = -inf" },
    Urdf { links: "base a", joints: "j1 continuous base a | nolimit", raw: None, tip: None, expect: "continuous joint `j1` has no usable velocity limit" },
    // Non-finite or degenerate geometry.
    Urdf { links: "base a", joints: "j1 revolute base a | <origin xyz=\"0 nan 0\"/>", raw: None, tip: None, expect: "joint `j1` has a non-finite origin" },
    Urdf { links: "base a", joints: "j1 revolute base a | <origin xyz=\"0 0 0\" rpy=\"inf 0 0\"/>", raw: None, tip: None, expect: "joint `j1` has a non-finite origin" },
    Urdf { links: "base a b", joints: "j0 fixed base a | <origin xyz=\"nan 0 0\"/>; j1 revolute a b", raw: None, tip: None, expect: "joint `j0` has a non-finite origin" },
    Urdf { links: "base a", joints: "j1 revolute base a | <axis xyz=\"0 nan 1\"/>", raw: None, tip: None, expect: "joint `j1` has a non-finite axis" },
    Urdf { links: "base a", joints: "j1 prismatic base a | <axis xyz=\"0 0 0\"/>", raw: None, tip: None, expect: "joint `j1` has a zero axis" },
    // Finite geometry too large to compute with: an origin of 1e308 m overflows forward kinematics.
    Urdf { links: "base a", joints: "j1 revolute base a | <origin xyz=\"1e308 0 0\"/>", raw: None, tip: None, expect: "joint `j1` has origin xyz = [1e308, 0.0, 0.0] m" },
    Urdf { links: "base a b", joints: "j0 fixed base a | <origin xyz=\"0 0 -2e6\"/>; j1 revolute a b", raw: None, tip: None, expect: "joint `j0` has origin xyz = [0.0, 0.0, -2000000.0] m" },
    Urdf { links: "base a", joints: "j1 prismatic base a | <limit lower=\"-1e300\" upper=\"1\" effort=\"1\" velocity=\"1\"/>", raw: None, tip: None, expect: "prismatic joint `j1` has limits [-1e300, 1.0] m" },
    // A cycle beside the chain (not on the base-tip path), and a chain hanging below a cycle.
    Urdf { links: "base a b c", joints: "j0 revolute base a; j1 revolute b c; j2 revolute c b", raw: None, tip: Some("a"), expect: "joints `j2`, `j1` form a cycle through links `b`, `c`" },
    Urdf { links: "base a b c d", joints: "j0 revolute base a; j1 revolute b c; j2 revolute c b; j3 fixed c d", raw: None, tip: Some("a"), expect: "form a cycle" },
];

#[test]
fn deeply_nested_urdfs_are_refused_without_overflowing_the_stack() {
    // 40 000 nested elements used to overflow the recursive parser's stack (SIGSEGV).
    let deep = format!("<robot name=\"r\">{}{}</robot>", "<a>".repeat(40_000), "</a>".repeat(40_000));
    let e = Chain::from_urdf_str(&deep, None).unwrap_err().to_string();
    assert!(e.contains("nested more than 64 deep"), "{e}");
    // Tags inside comments, CDATA and attribute values do not count; self-closing ones do not nest.
    let fine = format!(
        "<?xml version=\"1.0\"?><!-- {} --><robot name=\"r>\"><link name=\"base\"/><link name=\"a\"/>\
         <joint name=\"j\" type=\"revolute\"><parent link=\"base\"/><child link=\"a\"/><axis xyz=\"0 0 1\"/>\
         <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint></robot>",
        "<a>".repeat(1000)
    );
    Chain::from_urdf_str(&fine, None).unwrap();
}

fn urdf_document(u: &Urdf) -> String {
    if let Some(raw) = u.raw {
        return raw.to_string();
    }
    let mut s = String::from("<robot name=\"case\">\n");
    for l in u.links.split_whitespace() {
        s += &format!("  <link name=\"{l}\"/>\n");
    }
    for spec in u.joints.split(';').map(str::trim).filter(|j| !j.is_empty()) {
        let (head, extra) = spec.split_once('|').map(|(h, e)| (h, e.trim())).unwrap_or((spec, ""));
        let [name, kind, parent, child] = head.split_whitespace().collect::<Vec<_>>()[..] else {
            panic!("bad joint spec {spec:?}")
        };
        let mut body = extra.replace("nolimit", "");
        if kind != "fixed" {
            if !extra.contains("<axis") {
                body += "<axis xyz=\"0 0 1\"/>";
            }
            if !extra.contains("<limit") && !extra.contains("nolimit") {
                body += LIMIT;
            }
        }
        s += &format!(
            "  <joint name=\"{name}\" type=\"{kind}\"><parent link=\"{parent}\"/><child link=\"{child}\"/>{body}</joint>\n"
        );
    }
    s + "</robot>\n"
}

#[test]
fn bad_urdfs_are_refused_naming_the_joint_or_link() {
    let dir = Scratch::new("urdf");
    let mut failures = Vec::new();
    for (i, u) in URDFS.iter().enumerate() {
        let xml = urdf_document(u);
        let case = format!("URDF case {i} (expects {:?}):\n{xml}", u.expect);
        failures.extend(expect_err(&case, u.expect, || Chain::from_urdf_str(&xml, u.tip)));
        // From a file, the message also names the file.
        let path = dir.0.join(format!("case{i}.urdf"));
        std::fs::write(&path, &xml).unwrap();
        failures.extend(expect_err(&format!("file {case}"), &format!("case{i}.urdf: "), || {
            Chain::from_urdf_file(&path, u.tip)
        }));
    }
    // A sanity check of the notation: the same document without its fault compiles.
    let ok = Urdf {
        links: "base a b",
        joints: "j1 revolute base a; j2 prismatic a b",
        raw: None,
        tip: None,
        expect: "",
    };
    assert_eq!(Chain::from_urdf_str(&urdf_document(&ok), None).unwrap().dof(), 2);
    report(failures, URDFS.len());
}

// ---------------------------------------------------------------------------------------------
// Checkpoints, loaded for the config of a small SAC run (`load_agent`: file, algorithm, shapes,
// values). Every case's file, and the run's own checkpoints, must be byte-identical afterwards.

/// The bytes a case puts on disk, made from the fixture's good checkpoints.
type MakeBytes = fn(&Fixture) -> Option<Vec<u8>>;

struct Ck {
    name: &'static str,
    bytes: MakeBytes,
    expect: &'static str,
}

struct Fixture {
    /// The SAC run's final checkpoint (hidden [8]).
    sac: Vec<u8>,
    /// A TD3 run's (hidden [8]).
    td3: Vec<u8>,
    /// A SAC run's with hidden [16].
    wide: Vec<u8>,
}

/// A safetensors file from a JSON header and a data section.
fn safetensors(header: &str, data: &[u8]) -> Vec<u8> {
    let mut b = (header.len() as u64).to_le_bytes().to_vec();
    b.extend_from_slice(header.as_bytes());
    b.extend_from_slice(data);
    b
}

/// The SAC checkpoint with one byte of its data section (tensor values) flipped.
fn flip_tensor_byte(f: &Fixture) -> Option<Vec<u8>> {
    let mut b = f.sac.clone();
    let n = b.len();
    b[n - 7] ^= 0x01;
    Some(b)
}

/// The SAC checkpoint's header as JSON, the header's length and the data section's offset.
fn header(f: &Fixture) -> (serde_json::Value, usize) {
    let len = u64::from_le_bytes(f.sac[..8].try_into().unwrap()) as usize;
    (serde_json::from_slice(&f.sac[8..8 + len]).unwrap(), 8 + len)
}

/// The SAC checkpoint with its metadata entry `key` changed by `edit` (None removes it).
fn edit_meta(f: &Fixture, key: &str, edit: impl FnOnce(&str) -> Option<String>) -> Option<Vec<u8>> {
    let (mut h, data) = header(f);
    let meta = h["__metadata__"].as_object_mut().unwrap();
    match edit(meta[key].as_str().unwrap()) {
        Some(v) => meta.insert(key.to_string(), v.into()),
        None => meta.remove(key),
    };
    Some(safetensors(&h.to_string(), &f.sac[data..]))
}

/// `s` with one character changed in place (an ASCII byte with its lowest bit flipped).
fn flip_char(s: &str, at: usize) -> String {
    let mut b = s.as_bytes().to_vec();
    b[at] ^= 0x01;
    String::from_utf8(b).unwrap()
}

/// The SAC checkpoint with one edit applied.
fn edited(f: &Fixture, edit: impl FnOnce(&mut Checkpoint) -> Checkpoint) -> Option<Vec<u8>> {
    let mut ck = Checkpoint::from_bytes(&f.sac, Path::new("sac")).unwrap();
    Some(edit(&mut ck).to_bytes().unwrap())
}

/// Rebuild `ck` without tensor `skip`, with tensor `replace` given new data, and without
/// metadata key `drop_meta` (or with `set_meta` = value).
fn rebuild(
    ck: &Checkpoint,
    skip: &str,
    replace: Option<(&str, &[usize], &[f32])>,
    meta: &[(&str, Option<&str>)],
) -> Checkpoint {
    let mut out = Checkpoint::new();
    for name in ck.tensor_names() {
        if name == skip {
            continue;
        }
        match replace {
            Some((r, shape, data)) if r == name => out.put_tensor(name, shape, data),
            _ => {
                let (shape, data) = ck.tensor(name).unwrap();
                out.put_tensor(name, shape, data);
            }
        }
    }
    let mut keys: BTreeMap<String, String> = BTreeMap::new();
    for k in ["algorithm", "agent_rng", "actor_opt.step", "q1_opt.step", "q2_opt.step", "alpha_opt.step"] {
        if let Ok(v) = ck.meta(k) {
            keys.insert(k.to_string(), v.to_string());
        }
    }
    for (k, v) in meta {
        match v {
            Some(v) => keys.insert(k.to_string(), v.to_string()),
            None => keys.remove(*k),
        };
    }
    for (k, v) in keys {
        out.put_meta(&k, v);
    }
    out
}

#[rustfmt::skip]
const CHECKPOINTS: &[Ck] = &[
    // Malformed bytes and truncated files.
    Ck { name: "text", bytes: |_| Some(b"definitely not a checkpoint".to_vec()), expect: "not a valid checkpoint" },
    Ck { name: "empty", bytes: |_| Some(Vec::new()), expect: "not a valid checkpoint" },
    Ck { name: "cut-4", bytes: |f| Some(f.sac[..4].to_vec()), expect: "not a valid checkpoint" },
    Ck { name: "cut-header", bytes: |f| Some(f.sac[..40].to_vec()), expect: "not a valid checkpoint" },
    Ck { name: "cut-data", bytes: |f| Some(f.sac[..f.sac.len() - 100].to_vec()), expect: "not a valid checkpoint" },
    Ck { name: "cut-1", bytes: |f| Some(f.sac[..f.sac.len() - 1].to_vec()), expect: "not a valid checkpoint" },
    Ck { name: "huge-header-len", bytes: |_| Some(u64::MAX.to_le_bytes().to_vec()), expect: "not a valid checkpoint" },
    Ck { name: "header-not-json", bytes: |_| Some(safetensors("{not json}", &[])), expect: "not a valid checkpoint" },
    Ck { name: "offsets-past-end", bytes: |_| Some(safetensors(r#"{"t":{"dtype":"F32","shape":[4],"data_offsets":[0,16]}}"#, &[0; 8])), expect: "not a valid checkpoint" },
    Ck { name: "shape-overflow", bytes: |_| Some(safetensors(r#"{"t":{"dtype":"F32","shape":[4294967296,4294967296,4294967296],"data_offsets":[0,0]}}"#, &[])), expect: "not a valid checkpoint" },
    Ck { name: "f64-tensor", bytes: |_| Some(safetensors(r#"{"actor.layer0.weight":{"dtype":"F64","shape":[1],"data_offsets":[0,8]}}"#, &[0; 8])), expect: "tensor `actor.layer0.weight` is F64, expected F32" },
    // Silent corruption: one flipped bit in a tensor or in the metadata, no or a bad checksum.
    Ck { name: "flipped-tensor-byte", bytes: flip_tensor_byte, expect: "checksum mismatch" },
    Ck { name: "flipped-meta-rng", bytes: |f| edit_meta(f, "agent_rng", |v| Some(flip_char(v, v.len() / 2))), expect: "checksum mismatch" },
    Ck { name: "flipped-meta-algorithm", bytes: |f| edit_meta(f, "algorithm", |v| Some(flip_char(v, 1))), expect: "checksum mismatch" },
    Ck { name: "flipped-checksum", bytes: |f| edit_meta(f, "sha256", |v| Some(flip_char(v, 10))), expect: "checksum mismatch" },
    Ck { name: "huge-checksum", bytes: |f| edit_meta(f, "sha256", |_| Some("0".repeat(100_000))), expect: "0000000000... (100000 bytes)" },
    Ck { name: "no-checksum", bytes: |f| edit_meta(f, "sha256", |_| None), expect: "no `sha256` checksum" },
    // Another algorithm, another network shape.
    Ck { name: "td3-for-sac", bytes: |f| Some(f.td3.clone()), expect: "checkpoint of algorithm `td3`, the config says `sac`" },
    Ck { name: "hidden-16-for-8", bytes: |f| Some(f.wide.clone()), expect: "has shape [16, 16], this agent's has [8, 16]" },
    // Missing or damaged pieces.
    Ck { name: "no-algorithm", bytes: |f| edited(f, |c| rebuild(c, "", None, &[("algorithm", None)])), expect: "no metadata `algorithm`" },
    Ck { name: "no-actor-weight", bytes: |f| edited(f, |c| rebuild(c, "actor.layer0.weight", None, &[])), expect: "no tensor `actor.layer0.weight`" },
    Ck { name: "short-adam", bytes: |f| edited(f, |c| rebuild(c, "", Some(("q1_opt.m", &[3], &[0.0; 3])), &[])), expect: "tensor `q1_opt.m` has shape [3]" },
    Ck { name: "bad-json-meta", bytes: |f| edited(f, |c| rebuild(c, "", None, &[("agent_rng", Some("{oops"))])), expect: "metadata `agent_rng`" },
    Ck { name: "nan-weight", bytes: |f| edited(f, |c| rebuild(c, "", Some(("q2.layer2.bias", &[1], &[f32::NAN])), &[])), expect: "tensor `q2.layer2.bias`[0] = NaN is not finite" },
    Ck { name: "inf-weight", bytes: |f| edited(f, |c| { let (s, d) = c.tensor("actor.layer0.weight").unwrap(); let mut d = d.to_vec(); d[5] = f32::INFINITY; rebuild(c, "", Some(("actor.layer0.weight", s, &d)), &[]) }), expect: "`actor.layer0.weight`[5] = inf" },
    // Not a file.
    Ck { name: "missing-file", bytes: |_| None, expect: "missing-file.safetensors" },
];

fn small_run(dir: &Path, algo: Algo, hidden: usize) -> Config {
    let mut cfg = Config::default();
    cfg.agent.algo = algo;
    cfg.agent.hidden = vec![hidden, hidden];
    cfg.agent.batch_size = 8;
    cfg.agent.buffer_size = 1000;
    cfg.agent.learning_starts = 30;
    cfg.train.episodes = 2;
    cfg.train.eval_every_episodes = 0;
    cfg.train.checkpoint_every_episodes = 1;
    train(&cfg, dir, |_| {}).unwrap();
    cfg
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

#[test]
fn bad_checkpoints_are_refused_and_nothing_on_disk_changes() {
    let dir = Scratch::new("ck");
    let runs = dir.0.join("runs");
    let cfg = small_run(&runs.join("sac"), Algo::Sac, 8);
    small_run(&runs.join("td3"), Algo::Td3, 8);
    small_run(&runs.join("wide"), Algo::Sac, 16);
    let read = |run: &str| std::fs::read(RunDir::new(&runs.join(run)).final_checkpoint()).unwrap();
    let fx = Fixture { sac: read("sac"), td3: read("td3"), wide: read("wide") };
    let env = ReachEnv::from_config(&cfg, 0).unwrap();
    // The good checkpoint loads: the failures below are the cases', not the fixture's.
    load_agent(&cfg, &env, &RunDir::new(&runs.join("sac")).final_checkpoint()).unwrap();
    let runs_before = snapshot(&runs);

    let cases = dir.0.join("cases");
    std::fs::create_dir_all(&cases).unwrap();
    let mut failures = Vec::new();
    for c in CHECKPOINTS {
        let path = cases.join(format!("{}.safetensors", c.name));
        let written = (c.bytes)(&fx);
        if let Some(b) = &written {
            std::fs::write(&path, b).unwrap();
        }
        let before = snapshot(&cases);
        failures.extend(expect_err(&format!("checkpoint case `{}`", c.name), c.expect, || {
            load_agent(&cfg, &env, &path)
        }));
        if snapshot(&cases) != before {
            failures.push(format!("checkpoint case `{}`: the files on disk changed", c.name));
        }
        // The error also names the file (the last case is about exactly that).
        if let Err(e) = load_agent(&cfg, &env, &path) {
            let e = e.to_string();
            if !e.contains(&format!("{}.safetensors", c.name)) {
                failures.push(format!("checkpoint case `{}`: {e:?} does not name the file", c.name));
            }
        }
    }
    // A directory where a file is expected.
    failures.extend(expect_err("checkpoint case `directory`", "cases", || load_agent(&cfg, &env, &cases)));
    assert_eq!(snapshot(&runs), runs_before, "the runs' files changed");
    report(failures, CHECKPOINTS.len() + 1);
}

#[test]
fn train_refuses_a_section_of_another_algorithm() {
    // A SAC run whose config sets TD3's section: parsing allows it (a `--algo td3` may follow),
    // training refuses it, naming the section and the run's algorithm, before writing anything.
    let dir = Scratch::new("other-section");
    let path = dir.0.join("sac-with-td3.toml");
    std::fs::write(&path, "[agent]\nalgo = \"sac\"\n[agent.td3]\npolicy_delay = 3\n").unwrap();
    let cfg = Config::load(&path).unwrap();
    let out = dir.0.join("run");
    let e = train(&cfg, &out, |_| {}).unwrap_err().to_string();
    assert!(e.contains("`agent.td3`") && e.contains("agent.algo = \"sac\""), "{e}");
    assert!(!out.join("config.toml").exists(), "nothing written for a refused config");
    // The same file picks TD3 once the run's algorithm is TD3.
    let mut td3 = cfg.clone();
    td3.agent.algo = Algo::Td3;
    td3.validate().unwrap();
    assert_eq!(td3.agent.td3().policy_delay, 3);
}

#[test]
fn library_errors_quote_long_input_as_excerpts() {
    let big = "x".repeat(1_000_000);
    let errors = [
        Config::from_toml_str(&format!("[task]\nmax_steps = {big}\n"), Path::new("big.toml")).unwrap_err(),
        Config::from_toml_str(&format!("[reward]\nfunction = \"{big}\"\n"), Path::new("big.toml")).unwrap_err(),
        Chain::from_urdf_str(&format!("<robot name=\"r\"><link name=\"a\"/><joint name=\"j\" type=\"fixed\"><parent link=\"{big}\"/><child link=\"a\"/></joint></robot>"), None).unwrap_err(),
    ];
    for e in errors {
        let m = e.to_string();
        assert!(m.len() < 2000 && m.contains("bytes)"), "{} bytes: {}", m.len(), &m[..m.len().min(3000)]);
    }
}
