//! Floats survive every text path bit for bit: the JSON in checkpoint metadata (random-generator
//! and environment states, counters) and the TOML of configs. A lost ulp there made resumed runs
//! diverge from uninterrupted ones.

use stagerl::base::rng::Rng;
use stagerl::io::checkpoint::Checkpoint;
use std::path::Path;

/// Finite f64s: random bit patterns (every exponent, both signs), random subnormals, and the
/// extremes.
fn interesting_f64s(n: usize) -> Vec<f64> {
    let mut rng = Rng::new(8);
    let mut v = vec![
        0.0,
        -0.0,
        f64::MIN_POSITIVE,
        -f64::MIN_POSITIVE,
        f64::from_bits(1),
        -f64::from_bits(1),
        f64::from_bits(0x000F_FFFF_FFFF_FFFF),
        f64::MAX,
        f64::MIN,
        f64::EPSILON,
        1.0 + f64::EPSILON,
        0.1,
        1e-300,
        1e300,
        std::f64::consts::PI,
    ];
    while v.len() < n {
        let bits = rng.next_u64();
        let x = f64::from_bits(bits);
        if x.is_finite() {
            v.push(x);
        }
        // A subnormal: exponent bits zero, random mantissa and sign.
        v.push(f64::from_bits(bits & 0x800F_FFFF_FFFF_FFFF));
    }
    v
}

fn same_bits(a: &[f64], b: &[f64]) -> Result<(), String> {
    if a.len() != b.len() {
        return Err(format!("{} values became {}", a.len(), b.len()));
    }
    let bad: Vec<String> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.to_bits() != y.to_bits())
        .take(5)
        .map(|(x, y)| format!("{x:e} ({:#018x}) came back as {y:e} ({:#018x})", x.to_bits(), y.to_bits()))
        .collect();
    if bad.is_empty() {
        Ok(())
    } else {
        Err(bad.join("\n"))
    }
}

#[test]
fn random_f64_bits_round_trip_through_checkpoint_json() {
    let values = interesting_f64s(200_000);
    let mut ck = Checkpoint::new();
    ck.put_json("values", &values);
    // One value per entry too, the shape of most state fields.
    for (i, x) in values.iter().take(2000).enumerate() {
        ck.put_json(&format!("v{i}"), x);
    }
    let back = Checkpoint::from_bytes(&ck.to_bytes().unwrap(), Path::new("mem")).unwrap();
    same_bits(&values, &back.json::<Vec<f64>>("values").unwrap()).unwrap();
    let singles: Vec<f64> = (0..2000).map(|i| back.json::<f64>(&format!("v{i}")).unwrap()).collect();
    same_bits(&values[..2000], &singles).unwrap();
}

#[test]
fn random_f64_bits_round_trip_through_config_toml() {
    #[derive(serde::Serialize, serde::Deserialize)]
    struct Section {
        values: Vec<f64>,
    }
    let values = interesting_f64s(50_000);
    let text = toml::to_string(&Section { values: values.clone() }).unwrap();
    let back: Section = toml::from_str(&text).unwrap();
    same_bits(&values, &back.values).unwrap();
}
