//! Measured isotropic BRDFs in the binary layout of the MERL BRDF database
//! (Matusik et al. 2003), for [`super::Brdf::Measured`].
//!
//! The layout, little-endian:
//!
//! ```text
//! sample counts i32 × 3: θ_h, θ_d, φ_d = 90, 90, 180  (N = 1,458,000)
//! values f64 × 3·N: every red value, then every green, then every blue,
//!   bin (i_h, i_d, i_φ) at i_φ + 180·(i_d + 90·i_h)
//! ```
//!
//! A stored value times the channel's scale (1/1500, 1.15/1500, 1.66/1500)
//! is the BRDF; a negative value marks a bin with no measurement (read as
//! 0). Directions map to bins through the half and difference angles
//! (Rusinkiewicz 1998): `θ_h` bins are `floor(90·sqrt(θ_h/(π/2)))`, finer
//! near the specular peak; `θ_d` bins are `floor(90·θ_d/(π/2))`; `φ_d`
//! bins are `floor(180·φ_d/π)` after `φ_d += π` when negative
//! (reciprocity); each clamped to its range.

use crate::error::{RelightError, Result};
use glam::DVec3;
use ltm_codec::{Charge, Limits};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Read;
use std::path::Path;

/// Bins of `θ_h`, `θ_d` and `φ_d`.
pub const MERL_DIMS: [usize; 3] = [90, 90, 180];
/// Bins in all.
const BINS: usize = MERL_DIMS[0] * MERL_DIMS[1] * MERL_DIMS[2];
/// Bytes of a file: the header and three channels of f64.
pub const MERL_FILE_BYTES: usize = 12 + 3 * 8 * BINS;
/// Per channel, stored value × scale = BRDF.
const SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];

/// A measured BRDF table: one RGB value per bin, scaled, unmeasured bins 0.
pub struct MeasuredBrdf {
    name: String,
    values: Vec<[f32; 3]>,
    _charge: Charge,
}

impl std::fmt::Debug for MeasuredBrdf {
    /// The name and size, not the 1.46 million values.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "MeasuredBrdf({:?}, {} bins)",
            self.name,
            self.values.len()
        )
    }
}

impl PartialEq for MeasuredBrdf {
    fn eq(&self, other: &MeasuredBrdf) -> bool {
        self.name == other.name && self.values == other.values
    }
}

fn bad(detail: String) -> RelightError {
    RelightError::Invalid(format!("MERL BRDF: {detail}"))
}

/// `v` rotated by `angle` about unit `axis` (Rodrigues).
fn rotate(v: DVec3, axis: DVec3, angle: f64) -> DVec3 {
    let (s, c) = angle.sin_cos();
    v * c + axis.cross(v) * s + axis * axis.dot(v) * (1.0 - c)
}

/// `(θ_h, θ_d, φ_d)` of a pair of directions above the surface.
fn half_diff(wi: DVec3, wo: DVec3) -> (f64, f64, f64) {
    let h = (wi + wo).normalize();
    let theta_h = h.z.clamp(-1.0, 1.0).acos();
    let phi_h = h.y.atan2(h.x);
    let d = rotate(rotate(wi, DVec3::Z, -phi_h), DVec3::Y, -theta_h);
    (theta_h, d.z.clamp(-1.0, 1.0).acos(), d.y.atan2(d.x))
}

/// The bin of half and difference angles (the database's own mapping).
fn bin(theta_h: f64, theta_d: f64, phi_d: f64) -> usize {
    let clamp = |x: f64, n: usize| (x.max(0.0) as usize).min(n - 1);
    let [nh, nd, np] = MERL_DIMS;
    let ih = clamp((theta_h / FRAC_PI_2).max(0.0).sqrt() * nh as f64, nh);
    let id = clamp(theta_d / FRAC_PI_2 * nd as f64, nd);
    let phi = if phi_d < 0.0 { phi_d + PI } else { phi_d };
    let ip = clamp(phi / PI * np as f64, np);
    ip + np * (id + nd * ih)
}

/// The directions `(ω_i, ω_o)` at the centre of bin `k` (`φ_h = 0`).
fn bin_directions(k: usize) -> (DVec3, DVec3) {
    let [nh, nd, np] = MERL_DIMS;
    let (ih, id, ip) = (k / (nd * np), (k / np) % nd, k % np);
    let theta_h = ((ih as f64 + 0.5) / nh as f64).powi(2) * FRAC_PI_2;
    let theta_d = (id as f64 + 0.5) / nd as f64 * FRAC_PI_2;
    let phi_d = (ip as f64 + 0.5) / np as f64 * PI;
    let d = DVec3::new(
        theta_d.sin() * phi_d.cos(),
        theta_d.sin() * phi_d.sin(),
        theta_d.cos(),
    );
    let h = DVec3::new(theta_h.sin(), 0.0, theta_h.cos());
    let wi = rotate(d, DVec3::Y, theta_h);
    (wi, 2.0 * wi.dot(h) * h - wi)
}

impl MeasuredBrdf {
    /// Parses a file's bytes (see the module documentation); `name` (the
    /// path, for messages and specs) is kept. The table is charged to
    /// `limits` before it is made; a value that is NaN or infinite is an
    /// error.
    pub fn from_bytes(name: &str, bytes: &[u8], limits: &Limits) -> Result<MeasuredBrdf> {
        if bytes.len() < 12 {
            return Err(bad(format!(
                "{} bytes is shorter than the header",
                bytes.len()
            )));
        }
        let dims: Vec<i64> = (0..3)
            .map(|k| {
                i64::from(i32::from_le_bytes(
                    bytes[4 * k..4 * k + 4].try_into().unwrap_or_default(),
                ))
            })
            .collect();
        if dims != MERL_DIMS.map(|d| d as i64) {
            return Err(RelightError::range(
                "MERL BRDF sample counts (θ_h, θ_d, φ_d)",
                format!("{dims:?}"),
                "[90, 90, 180]",
            ));
        }
        if bytes.len() != MERL_FILE_BYTES {
            return Err(RelightError::range(
                "MERL BRDF file size in bytes",
                bytes.len(),
                MERL_FILE_BYTES,
            ));
        }
        let (mut values, charge) = limits.vec("MERL BRDF table", BINS, [0.0f32; 3])?;
        let body = &bytes[12..];
        for (c, scale) in SCALE.iter().enumerate() {
            for (k, v) in values.iter_mut().enumerate() {
                let at = 8 * (c * BINS + k);
                let raw = f64::from_le_bytes(body[at..at + 8].try_into().unwrap_or_default());
                if !raw.is_finite() {
                    return Err(bad(format!(
                        "value {raw} (channel {c}, bin {k}) is not finite"
                    )));
                }
                v[c] = (raw.max(0.0) * scale) as f32;
            }
        }
        Ok(MeasuredBrdf {
            name: name.to_string(),
            values,
            _charge: charge,
        })
    }

    /// Reads a file, its bytes charged to `limits` before they are read
    /// (a file of any other size than [`MERL_FILE_BYTES`] is refused
    /// before reading).
    pub fn read(path: &Path, limits: &Limits) -> Result<MeasuredBrdf> {
        let io = |error| RelightError::Io {
            path: path.to_path_buf(),
            error,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        if len != MERL_FILE_BYTES as u64 {
            return Err(RelightError::range(
                "MERL BRDF file size in bytes",
                len,
                MERL_FILE_BYTES,
            ));
        }
        let _charge = limits.check_alloc("MERL BRDF file", len, 1)?;
        let mut bytes = Vec::with_capacity(MERL_FILE_BYTES);
        file.take(len).read_to_end(&mut bytes).map_err(io)?;
        MeasuredBrdf::from_bytes(&path.display().to_string(), &bytes, limits)
    }

    /// The table of an analytic BRDF `f(ω_i, ω_o)`, sampled at each bin's
    /// centre (pairs below the horizon stored as unmeasured): files in the
    /// database's layout made from known reflectances.
    pub fn tabulate(
        name: &str,
        f: impl Fn(DVec3, DVec3) -> [f64; 3] + Sync,
        limits: &Limits,
    ) -> Result<MeasuredBrdf> {
        let (mut values, charge) = limits.vec("MERL BRDF table", BINS, [0.0f32; 3])?;
        values.par_iter_mut().enumerate().for_each(|(k, v)| {
            let (wi, wo) = bin_directions(k);
            if wi.z > 0.0 && wo.z > 0.0 {
                *v = f(wi, wo).map(|x| x as f32);
            }
        });
        Ok(MeasuredBrdf {
            name: name.to_string(),
            values,
            _charge: charge,
        })
    }

    /// The file bytes of the table (unmeasured bins as stored −1).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(MERL_FILE_BYTES);
        for d in MERL_DIMS {
            out.extend_from_slice(&(d as i32).to_le_bytes());
        }
        let measured: Vec<bool> = (0..BINS)
            .into_par_iter()
            .map(|k| {
                let (wi, wo) = bin_directions(k);
                wi.z > 0.0 && wo.z > 0.0
            })
            .collect();
        for (c, scale) in SCALE.iter().enumerate() {
            for (v, &m) in self.values.iter().zip(&measured) {
                let stored = if m { f64::from(v[c]) / scale } else { -1.0 };
                out.extend_from_slice(&stored.to_le_bytes());
            }
        }
        out
    }

    /// The name it was read or made under.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// `f_r(ω_i, ω_o)` per channel: the value of the pair's bin; zero where
    /// either direction is at or below the horizon.
    pub fn eval(&self, wi: DVec3, wo: DVec3) -> [f64; 3] {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return [0.0; 3];
        }
        let (th, td, pd) = half_diff(wi, wo);
        self.values[bin(th, td, pd)].map(f64::from)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bin_centres_map_back_to_their_bins() {
        for k in (0..BINS).step_by(7919) {
            let (wi, wo) = bin_directions(k);
            let (th, td, pd) = half_diff(wi, wo);
            assert_eq!(bin(th, td, pd), k, "{wi} {wo}");
            // Reciprocity: swapping the directions stays in the bin.
            let (th, td, pd) = half_diff(wo, wi);
            assert_eq!(bin(th, td, pd), k);
        }
    }
}
