//! Non-linear approximation of the lighting (Ng et al. 2003 §3.2): keep the
//! N wavelet lights of highest priority under one of three rules.

use ltm_codec::wavelet::row_level;
use std::str::FromStr;

/// The priority rule for choosing wavelet lights.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum Weighting {
    /// |c|: the lighting coefficient's magnitude.
    #[default]
    Unweighted,
    /// |c|·‖T_j‖: weighted by the L2 norm of the light's transport column.
    Transport,
    /// |c|·area: weighted by the area of the wavelet's support on its face.
    Area,
}

impl Weighting {
    /// The rule's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Weighting::Unweighted => "unweighted",
            Weighting::Transport => "transport",
            Weighting::Area => "area",
        }
    }
}

impl FromStr for Weighting {
    type Err = String;
    fn from_str(s: &str) -> Result<Weighting, String> {
        match s {
            "unweighted" => Ok(Weighting::Unweighted),
            "transport" => Ok(Weighting::Transport),
            "area" => Ok(Weighting::Area),
            _ => Err(format!(
                "unknown weighting '{s}' (expected unweighted, transport or area)"
            )),
        }
    }
}

/// Rec. 709 luminance: colour lights are ranked by it and carry RGB.
#[inline]
pub fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// A colour coefficient's magnitude for ranking: the luminance of its
/// channels' absolute values (wavelet coefficients can be negative, and
/// channels of opposite sign must not cancel).
#[inline]
pub fn magnitude(c: [f32; 3]) -> f32 {
    luminance([c[0].abs(), c[1].abs(), c[2].abs()])
}

/// Support of light coefficient `j`'s wavelet on its face, in texels, for the
/// dyadic (Haar) structure: `n²` for a face's scaling function, `(n/2^(l−1))²`
/// at row level `l ≥ 1`. Longer Daubechies filters have wider supports; the
/// dyadic area still orders levels the same way.
pub fn support_area(n: usize, j: usize) -> f32 {
    match row_level(n, j) {
        0 => (n * n) as f32,
        l => {
            let side = (n >> (l - 1)).max(1);
            (side * side) as f32
        }
    }
}

/// Indices of the `terms` lights of highest `magnitude(light[j])·scale[j]`
/// (all nonzero lights when `terms` is at least their number), into `out`.
pub fn select(
    light: &[[f32; 3]],
    scale: &[f32],
    terms: usize,
    scratch: &mut Vec<(f32, u32)>,
    out: &mut Vec<u32>,
) {
    scratch.clear();
    scratch.extend(
        light
            .iter()
            .zip(scale)
            .enumerate()
            .map(|(j, (c, s))| (magnitude(*c) * s, j as u32))
            .filter(|(p, _)| *p > 0.0),
    );
    if scratch.len() > terms {
        scratch.select_nth_unstable_by(terms, |a, b| b.0.total_cmp(&a.0));
        scratch.truncate(terms);
    }
    out.clear();
    out.extend(scratch.iter().map(|&(_, j)| j));
}
