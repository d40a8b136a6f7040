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

/// `--point X,Y,Z`: three finite world coordinates.
pub fn point(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}' is not a position X,Y,Z (three numbers)"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        [_, _, _] => Err(format!(
            "point light position '{s}' is not finite (valid: finite X,Y,Z world coordinates)"
        )),
        _ => Err(format!("'{s}' has {} coordinates (valid: X,Y,Z)", v.len())),
    }
}

/// `--intensity I` or `R,G,B`: radiant intensity, finite and ≥ 0 per
/// channel (one value for all three).
pub fn intensity(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|t| t.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}' is not an intensity I or R,G,B"))?;
    let rgb = match v[..] {
        [i] => [i; 3],
        [r, g, b] => [r, g, b],
        _ => return Err(format!("'{s}' has {} values (valid: I or R,G,B)", v.len())),
    };
    if rgb.iter().all(|c| c.is_finite() && *c >= 0.0) {
        Ok(rgb)
    } else {
        Err(format!(
            "point light intensity '{s}' is out of range (valid: finite and >= 0, W/sr)"
        ))
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
        assert_eq!(point("1,-2.5, 3e2"), Ok([1.0, -2.5, 300.0]));
        for bad in [
            "1,2", "1,2,3,4", "nan,0,0", "0,inf,0", "0,0,-inf", "a,b,c", "",
        ] {
            assert!(point(bad).is_err(), "{bad}");
        }
        assert_eq!(intensity("2"), Ok([2.0; 3]));
        assert_eq!(intensity("0,1,2"), Ok([0.0, 1.0, 2.0]));
        for bad in ["-1", "nan", "inf", "1,2", "1,-2,3", "x", "1e39"] {
            assert!(intensity(bad).is_err(), "{bad}");
        }
    }
}
