//! Relighting a file's near-field rows (chunk NEAR, written by `ltm
//! compress` from a bake with a `[light_plane]`) under textured area
//! lights in that plane: each row's light is propagated to its stored
//! surface point (chunk SURF) and dotted with its Haar coefficients,
//! `B_p = Σ_k L_k(p)·T_{p,k}` (§5.3, eq. 30).

use super::light::{LightTexture, Placement, SourceCoefficients};
use super::propagate::{PlaneFace, Propagator, Receiver, Targets};
use crate::error::{RelightError, Result};
use ltm_codec::{LtmFile, PlaneRows};
use rayon::prelude::*;

/// An area light in the file's light plane: its radiance texture and
/// where it lies (centre, size, intensity).
#[derive(Clone, Debug)]
pub struct AreaLight {
    /// The light's radiance over its rectangle.
    pub texture: LightTexture,
    /// Its rectangle in the plane's coordinates and its intensity.
    pub placement: Placement,
}

/// How much of the light and of each row's incident lighting is computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearFieldTerms {
    /// Share (0..=1] of the light's `order²` Haar coefficients kept, the
    /// largest (source level, §5.3.1).
    pub source: f64,
    /// Which incident coefficients each row computes (target level,
    /// eq. 32).
    pub targets: Targets,
}

impl NearFieldTerms {
    /// Every term.
    pub const ALL: NearFieldTerms = NearFieldTerms {
        source: 1.0,
        targets: Targets::All,
    };

    fn check(&self) -> Result<()> {
        let share_ok = |s: f64| s.is_finite() && s > 0.0 && s <= 1.0;
        if !share_ok(self.source) {
            return Err(RelightError::range("source share", self.source, "(0, 1]"));
        }
        if let Targets::Share(s) = self.targets {
            if !share_ok(s) {
                return Err(RelightError::range("target share", s, "(0, 1]"));
            }
        }
        Ok(())
    }
}

/// The near-field rows of a file with each row's receiving point.
#[derive(Debug)]
pub struct NearField {
    rows: PlaneRows,
    face: PlaneFace,
    /// Each row's point in the plane's frame (`None`: no surface).
    receivers: Vec<Option<Receiver>>,
    /// Per-row RGB albedo of a grey file.
    albedo: Option<Vec<f32>>,
}

impl NearField {
    /// Takes the near-field rows out of `file` ([`LtmFile::take_near_field`];
    /// its matrix, surface and albedo stay, for a relighter of the map): an
    /// error naming what to run when the file has none.
    pub fn take(file: &mut LtmFile) -> Result<NearField> {
        let basis = *file.near_field().ok_or_else(|| {
            RelightError::Invalid(
                "the file holds no near-field rows: bake a scene with a [light_plane] section (docs/SCENE.md), then compress it in a wavelet mode".into(),
            )
        })?.basis();
        let surface = file
            .surface()
            .ok_or_else(|| RelightError::Invalid("near-field rows without surface data".into()))?;
        let receivers = surface
            .points()
            .iter()
            .map(|s| {
                s.valid.then(|| {
                    let (depth, position) = basis.locate(s.position.map(f64::from));
                    Receiver { depth, position }
                })
            })
            .collect();
        let face = PlaneFace {
            order: basis.order as usize,
            side: basis.side,
        };
        face.check()?;
        let albedo = file.albedo().map(<[f32]>::to_vec);
        let rows = file.take_near_field().ok_or_else(|| {
            RelightError::Invalid("near-field rows taken out of the file already".into())
        })?;
        Ok(NearField {
            rows,
            face,
            receivers,
            albedo,
        })
    }

    /// The face's plane and its resolution.
    pub fn basis(&self) -> &ltm_codec::PlaneBasis {
        self.rows.basis()
    }

    /// The face the rows are stored over.
    pub fn face(&self) -> PlaneFace {
        self.face
    }

    /// The light's source coefficients at the face's order with `share` of
    /// its terms kept.
    pub fn source(&self, light: &AreaLight, share: f64) -> Result<SourceCoefficients> {
        let all = self.face.order * self.face.order;
        let keep = ((share * all as f64).ceil() as usize).clamp(1, all);
        SourceCoefficients::new(&light.texture, &light.placement, self.face.order, keep)
    }

    /// Every row's RGB radiance under `lights` (added together), times the
    /// albedo of a grey file; 0 for rows without a surface or behind the
    /// plane. Rows are shaded in parallel.
    pub fn render(&self, lights: &[AreaLight], terms: NearFieldTerms) -> Result<Vec<[f32; 3]>> {
        terms.check()?;
        let sources = lights
            .iter()
            .map(|l| Ok((self.source(l, terms.source)?, l.placement)))
            .collect::<Result<Vec<_>>>()?;
        let channels = self.rows.channels();
        let (rows, albedo, face) = (&self.rows, self.albedo.as_deref(), self.face);
        self.receivers
            .par_iter()
            .enumerate()
            .map_init(
                || Propagator::new(face),
                |propagator, (p, receiver)| {
                    let Ok(propagator) = propagator.as_mut() else {
                        return Err(RelightError::range(
                            "near-field order",
                            face.order,
                            "a power of two in 1..=1024",
                        ));
                    };
                    let Some(receiver) = receiver else {
                        return Ok([0.0; 3]);
                    };
                    let mut sum = [0.0f64; 3];
                    for (source, placement) in &sources {
                        if !propagator.prepare(source, placement, receiver, terms.targets)? {
                            continue;
                        }
                        for c in 0..channels {
                            let (index, value) = rows.row(p, c);
                            let b = propagator.shade_indexed(index, value);
                            if channels == 1 {
                                (0..3).for_each(|k| sum[k] += b[k]);
                            } else {
                                sum[c] += b[c];
                            }
                        }
                    }
                    let a = albedo.map_or([1.0; 3], |a| [a[3 * p], a[3 * p + 1], a[3 * p + 2]]);
                    // NaN-free and within f32 (a NaN sum becomes 0).
                    let most = f64::from(f32::MAX);
                    Ok([0, 1, 2].map(|k| (sum[k] * f64::from(a[k])).max(0.0).min(most) as f32))
                },
            )
            .collect()
    }
}
