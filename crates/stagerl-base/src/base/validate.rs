//! Checks of configuration values, shared by every section. Each error names the field, the value
//! and what is allowed ([`Error::config`]).

use crate::{Error, Result};

/// `v` is a finite number.
pub fn finite(field: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::config(field, v, "a finite number"))
    }
}

/// `v` is a finite number > 0.
pub fn positive(field: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::config(field, v, "a finite number > 0"))
    }
}

/// `v` is a finite number >= 0.
pub fn non_negative(field: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Error::config(field, v, "a finite number >= 0"))
    }
}

/// `v` is an integer >= 1.
pub fn at_least_one(field: &str, v: u64) -> Result<()> {
    if v >= 1 {
        Ok(())
    } else {
        Err(Error::config(field, v, "an integer >= 1"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_field_value_and_allowed() {
        assert!(
            finite("a.x", -3.0).is_ok() && positive("a.x", 1e-9).is_ok() && non_negative("a.x", 0.0).is_ok()
        );
        let cases = [
            (finite("a.x", f64::NAN), "`a.x` = NaN", "a finite number"),
            (positive("a.y", 0.0), "`a.y` = 0", "> 0"),
            (positive("a.y", f64::INFINITY), "`a.y` = inf", "> 0"),
            (non_negative("a.z", -1.0), "`a.z` = -1", ">= 0"),
            (at_least_one("a.n", 0), "`a.n` = 0", "an integer >= 1"),
        ];
        for (result, named, allowed) in cases {
            let e = result.unwrap_err().to_string();
            assert!(e.contains(named) && e.contains(allowed), "{e}");
        }
    }
}
