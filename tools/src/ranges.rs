//! Range-checked command-line values: every number that sizes work or
//! memory is checked when the command line is parsed, before anything runs.

/// Most frames `--frames` may time.
pub const MAX_FRAMES: usize = 100_000;

/// `--frames`: 1 to [`MAX_FRAMES`].
pub fn frames(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=MAX_FRAMES).contains(&n) => Ok(n),
        _ => Err(format!("'{s}' is out of range (valid: 1..={MAX_FRAMES})")),
    }
}

/// An exposure in stops: finite, −64 to 64.
pub fn exposure(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && (-64.0..=64.0).contains(&v) => Ok(v),
        _ => Err(format!(
            "'{s}' is out of range (valid: a number of stops in -64..=64)"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_values_are_refused() {
        assert_eq!(frames("7"), Ok(7));
        for bad in ["0", "-1", "4000000000", "100001", "x", ""] {
            assert!(frames(bad).is_err(), "{bad}");
        }
        assert_eq!(exposure("-2.5"), Ok(-2.5));
        for bad in ["nan", "inf", "-inf", "65", "1e30", "x"] {
            assert!(exposure(bad).is_err(), "{bad}");
        }
    }
}
