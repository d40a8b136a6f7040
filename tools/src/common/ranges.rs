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

/// An image size, in one grammar for every command that takes one
/// (`--size` of `bake`, `demo` and `render`): `WxH` in pixels, or `N` for
/// N×N; each side 1..=`max`.
pub fn image_size(s: &str, max: u32) -> Result<(u32, u32), String> {
    let bad = || format!("'{s}' is not an image size (valid: WxH or N, e.g. 640x480 or 256)");
    let side = |t: &str| t.trim().parse::<u32>().map_err(|_| bad());
    let (w, h) = match s.split_once(['x', 'X']) {
        Some((w, h)) => (side(w)?, side(h)?),
        None => {
            let n = side(s)?;
            (n, n)
        }
    };
    if !(1..=max).contains(&w) || !(1..=max).contains(&h) {
        return Err(format!("'{s}' is out of range (valid: sides 1..={max})"));
    }
    Ok((w, h))
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
            "position '{s}' is not finite (valid: finite X,Y,Z world coordinates)"
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

/// `--area-center X,Y`, `--area-size W,H`: two finite numbers.
pub fn pair(s: &str) -> Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}' is not two numbers X,Y"))?;
    match v[..] {
        [x, y] if x.is_finite() && y.is_finite() => Ok([x, y]),
        [_, _] => Err(format!("'{s}' is not finite (valid: two finite numbers)")),
        _ => Err(format!("'{s}' has {} numbers (valid: two, X,Y)", v.len())),
    }
}

/// `--area-source-terms`, `--area-target-terms`: a share in (0, 1].
pub fn share(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v <= 1.0 => Ok(v),
        _ => Err(format!(
            "'{s}' is out of range (valid: a share in (0, 1], e.g. 0.05)"
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
        assert_eq!(image_size("640x480", 1000), Ok((640, 480)));
        assert_eq!(image_size("256", 1000), Ok((256, 256)));
        assert_eq!(image_size("2X3", 1000), Ok((2, 3)));
        for bad in ["0x10", "10x", "x", "", "1001", "10x1001", "-1", "2x3x4"] {
            let e = image_size(bad, 1000).unwrap_err();
            assert!(e.contains(&format!("'{bad}'")), "{e}");
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

    #[test]
    fn area_light_values_are_checked() {
        assert_eq!(pair("-0.5, 2"), Ok([-0.5, 2.0]));
        for bad in ["1", "1,2,3", "nan,0", "0,inf", "a,b"] {
            assert!(pair(bad).is_err(), "{bad}");
        }
        assert_eq!(share("1"), Ok(1.0));
        for bad in ["0", "-0.1", "1.5", "nan", "x"] {
            assert!(share(bad).is_err(), "{bad}");
        }
    }
}
