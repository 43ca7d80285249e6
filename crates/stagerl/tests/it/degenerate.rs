//! Physics and requests that would be degenerate: link masses and inertias outside physical
//! ranges are refused when the dynamic arm is built, naming the link and the value; a vector env
//! larger than it may be is refused before anything is allocated for it.

use stagerl::config::Config;
use stagerl::env::{ReachEnv, VecEnv, MAX_VEC_ENVS};

/// A two-joint arm with `<inertial>` elements; `MASS` and `IXX` are the second link's.
const ARM: &str = r#"<robot name="two">
  <link name="base"/>
  <link name="l1"><inertial><mass value="2"/><inertia ixx="0.02" iyy="0.02" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tip"><inertial><mass value="MASS"/><inertia ixx="IXX" iyy="0.01" izz="0.005" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="50" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
    <origin xyz="0.5 0 0.2"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="50" velocity="1"/></joint>
</robot>"#;

fn dynamic_env(mass: &str, ixx: &str) -> stagerl::Result<ReachEnv> {
    let dir = std::env::temp_dir().join(format!("stagerl-degenerate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let urdf = dir.join(format!("arm-{mass}-{ixx}.urdf"));
    std::fs::write(&urdf, ARM.replace("MASS", mass).replace("IXX", ixx)).unwrap();
    let text = format!(
        "[robot]\nurdf = \"{}\"\n[task]\nsim = \"dynamic\"\nhome_pose_rad = [0, 0.3]\ntarget_joint_range_rad = [1, 1]\ntarget_min_z_m = 0.0\n",
        urdf.display()
    );
    let cfg = Config::from_toml_str(&text, std::path::Path::new("arm.toml"))?;
    let env = ReachEnv::from_config(&cfg, 0);
    std::fs::remove_file(&urdf).ok();
    env
}

#[test]
fn link_masses_and_inertias_outside_physical_ranges_are_refused_naming_the_link() {
    // The same arm with a plausible link loads.
    dynamic_env("1", "0.01").unwrap();
    for (mass, ixx, expect) in [
        ("1e30", "0.01", "link `tip` has <mass value=\"1000000000000000000000000000000\">"),
        ("1e-12", "0.01", "link `tip` has <mass value=\"0.000000000001\">"),
        ("1", "1e30", "link `tip` has <inertia ixx=\"1000000000000000000000000000000\">"),
        ("1", "-5", "ixx, iyy, izz >= 0"),
    ] {
        let e = match dynamic_env(mass, ixx) {
            Ok(_) => panic!("mass {mass}, ixx {ixx}: accepted"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(expect), "mass {mass}, ixx {ixx}: {e}");
    }
}

#[test]
fn a_vector_env_beyond_its_limit_is_refused_before_allocating() {
    let cfg = Config::default();
    for n in [0, MAX_VEC_ENVS + 1, 10_000_000] {
        let e = VecEnv::from_config(n, &cfg, 0).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("`num_envs`") && e.contains(&n.to_string()) && e.contains("65536"), "{e}");
    }
    assert_eq!(VecEnv::from_config(3, &cfg, 0).unwrap().len(), 3);
}
