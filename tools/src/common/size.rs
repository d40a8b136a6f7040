//! Byte sizes on the command line, in one grammar for every flag that takes
//! one (`--max-memory`, `--mem-budget`): a number, optionally with a
//! fraction, and an optional binary suffix K, M, G, T, P or E (either
//! case): `1000000`, `512M`, `1.5G`, `2E`.

/// The smallest size a size flag accepts: 1 MiB.
pub const MIN_SIZE: u64 = 1 << 20;

/// The valid range, as messages name it.
const RANGE: &str = "1M to 16E bytes, 16E excluded";

/// Parses a size flag's value: at least [`MIN_SIZE`] and below 16E
/// (2⁶⁴ bytes). Fractions of a byte are dropped (`1.5M` is 1572864
/// bytes, `1.0000001M` 1048576).
pub fn size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (number, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                'P' => 50,
                'E' => 60,
                _ => {
                    return Err(format!(
                        "'{s}' has an unknown size suffix '{c}' (valid: K, M, G, T, P, E; sizes {RANGE})"
                    ))
                }
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    let bytes = bytes(number, shift).ok_or_else(|| {
        format!("'{s}' is not a size (valid: a number with an optional K, M, G, T, P or E suffix, e.g. 512M, 1.5G or 1000000; sizes {RANGE})")
    })?;
    match bytes {
        Some(b) if b >= MIN_SIZE => Ok(b),
        _ => Err(format!("'{s}' is out of range (valid: {RANGE})")),
    }
}

/// `number × 2^shift` in whole bytes, the fraction floored: `None` when
/// `number` is not digits with at most one decimal point, `Some(None)` when
/// the result does not fit in a u64.
fn bytes(number: &str, shift: u32) -> Option<Option<u64>> {
    let (whole, frac) = number.split_once('.').unwrap_or((number, ""));
    let digits = |d: &str| d.bytes().all(|b| b.is_ascii_digit());
    if whole.is_empty() && frac.is_empty() || !digits(whole) || !digits(frac) {
        return None;
    }
    // Exactly, in u128: the whole part below 2⁶⁴ (else out of range) times
    // 2^shift (shift ≤ 60), and at most 19 fraction digits.
    let w = match whole.trim_start_matches('0') {
        "" => 0,
        w => match w.parse::<u64>() {
            Ok(w) => w,
            Err(_) => return Some(None),
        },
    };
    let frac = &frac[..frac.len().min(19)];
    let f: u128 = if frac.is_empty() {
        0
    } else {
        frac.parse().ok()?
    };
    let scale = 10u128.pow(frac.len() as u32);
    let total = (u128::from(w) << shift) + (f << shift) / scale;
    Some(u64::try_from(total).ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_in_one_grammar() {
        assert_eq!(size("1000000000"), Ok(1_000_000_000));
        assert_eq!(size("1M"), Ok(1 << 20));
        assert_eq!(size("512m"), Ok(512 << 20));
        assert_eq!(size(" 4G "), Ok(4 << 30));
        assert_eq!(size("1.5G"), Ok(3 << 29));
        assert_eq!(size("1.5g"), Ok(3 << 29));
        assert_eq!(size("0.5T"), Ok(1 << 39));
        assert_eq!(size("2P"), Ok(2 << 50));
        assert_eq!(size("1E"), Ok(1 << 60));
        assert_eq!(size("15.5E"), Ok(31 << 59));
        assert_eq!(size(".5G"), Ok(1 << 29));
        assert_eq!(size("2048.K"), Ok(2 << 20));
        // Fractions of a byte are dropped.
        assert_eq!(size("1048576.9"), Ok(1 << 20));
        assert_eq!(size("1.0000000001M"), Ok(1 << 20));
        assert_eq!(size("18446744073709551615"), Ok(u64::MAX));
        assert_eq!(size("0015.9375E"), Ok(u64::MAX - (1 << 56) + 1));
    }

    #[test]
    fn bad_sizes_name_the_value_and_the_range() {
        for bad in [
            "0",
            "12",
            "3.",
            "1K",
            "1023K",
            "0.9M",
            "16E",
            "17E",
            "99999999999999999999",
            "1e9",
            "-1G",
            "+1G",
            "1..5G",
            "G",
            ".",
            "",
            "x",
            "1.5Q",
            "1 G",
            "nan",
            "inf",
            "1GB",
        ] {
            let e = size(bad).unwrap_err();
            assert!(e.contains(&format!("'{bad}'")), "{bad}: {e}");
            assert!(e.contains("1M to 16E"), "{bad}: {e}");
        }
        assert!(size("16E").unwrap_err().contains("out of range"));
        assert!(size("12").unwrap_err().contains("out of range"));
        assert!(size("1.5Q")
            .unwrap_err()
            .contains("unknown size suffix 'Q'"));
    }
}
