//! The exposure of tone-mapped PNGs: `auto` (a percentile of the image's
//! luminance) or a number of stops, shared by `ltm relight`, `ltm render`
//! and `ltm demo`.

use ltm_relight::Image;
use std::fmt;
use std::str::FromStr;

/// The luminance percentile that `auto` maps to [`AUTO_WHITE`].
pub const AUTO_PERCENTILE: usize = 99;
/// The PNG value (before sRGB encoding) the percentile is mapped to.
pub const AUTO_WHITE: f32 = 0.8;
/// The range of an exposure in stops, and of the one `auto` chooses.
pub const MAX_STOPS: f32 = 64.0;

/// `--exposure`: `auto` or a number of stops (values are multiplied by
/// 2^EV before clamping to [0, 1]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    /// [`auto_exposure`] of the image written.
    Auto,
    /// This many stops.
    Stops(f32),
}

impl Exposure {
    /// The EV to write `image` at.
    pub fn resolve(self, image: &Image) -> f32 {
        match self {
            Exposure::Auto => auto_exposure(image),
            Exposure::Stops(ev) => ev,
        }
    }

    /// How the chosen EV is described in a command's summary.
    pub fn describe(self, ev: f32) -> String {
        match self {
            Exposure::Auto => format!(
                "EV {ev:+.2} (auto: {AUTO_PERCENTILE}th-percentile luminance to {AUTO_WHITE}; --exposure EV sets it)"
            ),
            Exposure::Stops(_) => format!("EV {ev:+.2}"),
        }
    }
}

impl fmt::Display for Exposure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Exposure::Auto => f.write_str("auto"),
            Exposure::Stops(ev) => write!(f, "{ev}"),
        }
    }
}

impl FromStr for Exposure {
    type Err = String;
    fn from_str(s: &str) -> Result<Exposure, String> {
        if s.trim().eq_ignore_ascii_case("auto") {
            return Ok(Exposure::Auto);
        }
        match s.trim().parse::<f32>() {
            Ok(v) if v.is_finite() && (-MAX_STOPS..=MAX_STOPS).contains(&v) => {
                Ok(Exposure::Stops(v))
            }
            _ => Err(format!(
                "'{s}' is out of range (valid: auto, or a number of stops in -64..=64)"
            )),
        }
    }
}

/// Exposure (EV) that maps the [`AUTO_PERCENTILE`]th-percentile luminance
/// of the lit pixels of `image` to [`AUTO_WHITE`]; 0 for a black image.
pub fn auto_exposure(image: &Image) -> f32 {
    let mut lum: Vec<f32> = image
        .data
        .iter()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    if lum.is_empty() {
        return 0.0;
    }
    let k = (lum.len() * AUTO_PERCENTILE / 100).min(lum.len() - 1);
    let (_, v, _) = lum.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    (AUTO_WHITE / *v).log2().clamp(-MAX_STOPS, MAX_STOPS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(values: &[f32]) -> Image {
        let mut im = Image::new(values.len(), 1);
        for (p, v) in im.data.iter_mut().zip(values) {
            *p = [*v; 3];
        }
        im
    }

    #[test]
    fn exposures_parse_and_are_checked() {
        assert_eq!("auto".parse::<Exposure>(), Ok(Exposure::Auto));
        assert_eq!("AUTO".parse::<Exposure>(), Ok(Exposure::Auto));
        assert_eq!("-2.5".parse::<Exposure>(), Ok(Exposure::Stops(-2.5)));
        for bad in ["nan", "inf", "-inf", "65", "1e30", "x", "", "automatic"] {
            let e = bad.parse::<Exposure>().unwrap_err();
            assert!(e.contains(&format!("'{bad}'")) && e.contains("auto"), "{e}");
        }
    }

    #[test]
    fn auto_maps_the_percentile_to_the_white_point() {
        // 100 pixels 1..=100: the 99th percentile is 100 (index 99).
        let values: Vec<f32> = (1..=100).map(|v| v as f32).collect();
        let ev = Exposure::Auto.resolve(&image(&values));
        assert!((ev - (AUTO_WHITE / 100.0).log2()).abs() < 1e-5, "{ev}");
        assert_eq!(Exposure::Stops(1.5).resolve(&image(&values)), 1.5);
        // Black, and non-finite pixels, do not decide it.
        assert_eq!(auto_exposure(&image(&[0.0; 8])), 0.0);
        let ev = auto_exposure(&image(&[f32::INFINITY, 0.4]));
        assert!((ev - 1.0).abs() < 1e-5, "{ev}");
    }
}
