//! Relighting a file's near-field rows (chunk NEAR, written by `ltm
//! compress` from a bake with a `[light_plane]`) under textured area
//! lights in that plane, each row at its stored surface point (chunk
//! SURF). The rows are held as per-texel integrals over the face; a row
//! shades either exactly ([`NearFieldMethod::Exact`], see [`super::exact`])
//! or by the truncated affine propagation of §5.3,
//! `B_p = Σ_k L_k(p)·T_{p,k}` (eq. 30) over its Haar coefficients
//! ([`NearFieldMethod::Wavelet`]).

use super::acc_table::AccTable;
use super::exact::{FaceMasses, LightTable};
use super::light::{LightTexture, Placement, SourceCoefficients};
use super::propagate::{affine, PlaneFace, Propagator, Receiver, Targets};
use super::shading_rows::ShadingRows;
use crate::error::{RelightError, Result};
use ltm_codec::{Charge, Limits, LtmFile, PlaneBasis, PlaneRows};
use rayon::prelude::*;
use std::sync::Arc;

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

/// How each row's light is computed.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum NearFieldMethod {
    /// The light's texture integrated exactly over every face texel it
    /// covers ([`super::exact`]): nothing truncated, the texture at its own
    /// resolution (up to [`super::MAX_TABLE_SIDE`] per side); the cost
    /// grows with the texels the light covers.
    Exact,
    /// The affine wavelet propagation of §5.3 with these terms: the texture
    /// at the face's order, its largest coefficients, each row's selected
    /// targets.
    Wavelet(NearFieldTerms),
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
    face: PlaneFace,
    /// Each row's point in the plane's frame (`None`: no surface).
    receivers: Vec<Option<Receiver>>,
    /// Each row's slot in `texels`; `u32::MAX` for rows without a surface
    /// or without near-field light.
    slots: Vec<u32>,
    /// Per slot, `C` channels of `order²` per-texel integrals (`y` major),
    /// for the exact method.
    texels: Vec<f32>,
    /// The face's plane and resolution, and the rows' channels (1 or 3).
    basis: PlaneBasis,
    channels: usize,
    /// The rows' Haar coefficients, for the wavelet method.
    shading: ShadingRows,
    /// Per-row RGB albedo of a grey file.
    albedo: Option<Vec<f32>>,
    /// The wavelet method's couplings, looked up here when set.
    table: Option<Arc<AccTable>>,
    _charge: Charge,
}

/// No slot: the row gets no near-field light.
const NO_SLOT: u32 = u32::MAX;

impl NearField {
    /// Takes the near-field rows out of `file` ([`LtmFile::take_near_field`];
    /// its matrix, surface and albedo stay, for a relighter of the map): an
    /// error naming what to run when the file has none. Besides the stored
    /// coefficients (the wavelet method's), the rows of points with a
    /// surface are held as per-texel integrals (the exact method's),
    /// `4·order²·C` bytes each, charged to `limits`.
    pub fn take(file: &mut LtmFile, limits: &Limits) -> Result<NearField> {
        let basis = *file.near_field().ok_or_else(|| {
            RelightError::Invalid(
                "the file holds no near-field rows: bake a scene with a [light_plane] section (docs/SCENE.md), then compress it in a wavelet mode".into(),
            )
        })?.basis();
        let surface = file
            .surface()
            .ok_or_else(|| RelightError::Invalid("near-field rows without surface data".into()))?;
        let receivers: Vec<Option<Receiver>> = surface
            .points()
            .iter()
            .map(|s| {
                s.valid.then(|| {
                    let (depth, position) = basis.locate(s.position.map(f64::from));
                    Receiver { depth, position }
                })
            })
            .collect();
        let albedo = file.albedo().map(<[f32]>::to_vec);
        let rows = file.take_near_field().ok_or_else(|| {
            RelightError::Invalid("near-field rows taken out of the file already".into())
        })?;
        NearField::new(rows, receivers, albedo, limits)
    }

    /// Near-field rows with each row's receiving point (`None`: no
    /// surface, no light) and, for grey rows, an RGB albedo per row.
    pub fn new(
        rows: PlaneRows,
        receivers: Vec<Option<Receiver>>,
        albedo: Option<Vec<f32>>,
        limits: &Limits,
    ) -> Result<NearField> {
        let basis = *rows.basis();
        let face = PlaneFace {
            order: basis.order as usize,
            side: basis.side,
        };
        face.check()?;
        let bad = receivers.iter().enumerate().find(|(_, r)| {
            r.is_some_and(|r| !(r.depth.is_finite() && r.position.iter().all(|v| v.is_finite())))
        });
        if let Some((p, r)) = bad {
            return Err(RelightError::Invalid(format!(
                "row {p}'s receiving point {r:?} is not finite"
            )));
        }
        if let Some(a) = &albedo {
            if a.len() != 3 * receivers.len() {
                return Err(RelightError::Invalid(format!(
                    "{} albedo values for {} rows",
                    a.len(),
                    receivers.len()
                )));
            }
        }
        let (slots, texels, charge) = texel_rows(&rows, &receivers, limits)?;
        let shading = ShadingRows::new(&rows, limits)?;
        Ok(NearField {
            face,
            receivers,
            slots,
            texels,
            basis,
            channels: rows.channels(),
            shading,
            albedo,
            table: None,
            _charge: charge,
        })
    }

    /// The face's plane and its resolution.
    pub fn basis(&self) -> &PlaneBasis {
        &self.basis
    }

    /// Makes the wavelet method look its couplings up in `table` (§5.3.2's
    /// memory-based approach: nearest node, see [`AccTable`]), or evaluate
    /// them in closed form (`None`, the default). Refuses a table of
    /// another order than the face's.
    pub fn set_coupling_table(&mut self, table: Option<Arc<AccTable>>) -> Result<()> {
        if let Some(t) = &table {
            if t.order() != self.face.order {
                let valid = format!("{}, the face's order", self.face.order);
                return Err(RelightError::range(
                    "coupling table order",
                    t.order(),
                    valid,
                ));
            }
        }
        self.table = table;
        Ok(())
    }

    /// The face the rows are stored over.
    pub fn face(&self) -> PlaneFace {
        self.face
    }

    /// Row `p`'s per-texel integrals (`order²·C`, channel after channel),
    /// or `None` when it gets no near-field light.
    pub fn row_texels(&self, p: usize) -> Option<&[f32]> {
        let slot = *self.slots.get(p)?;
        let len = self.face.order * self.face.order * self.channels;
        (slot != NO_SLOT).then(|| &self.texels[slot as usize * len..][..len])
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
    pub fn render(&self, lights: &[AreaLight], method: NearFieldMethod) -> Result<Vec<[f32; 3]>> {
        let sums = match method {
            NearFieldMethod::Exact => self.render_exact(lights)?,
            NearFieldMethod::Wavelet(terms) => self.render_wavelet(lights, terms)?,
        };
        let albedo = self.albedo.as_deref();
        Ok(sums
            .into_iter()
            .enumerate()
            .map(|(p, sum)| {
                let a = albedo.map_or([1.0; 3], |a| [a[3 * p], a[3 * p + 1], a[3 * p + 2]]);
                // NaN-free and within f32 (a NaN sum becomes 0).
                let most = f64::from(f32::MAX);
                [0, 1, 2].map(|k| (sum[k] * f64::from(a[k])).max(0.0).min(most) as f32)
            })
            .collect())
    }

    fn render_exact(&self, lights: &[AreaLight]) -> Result<Vec<[f64; 3]>> {
        let tables = lights
            .iter()
            .map(|l| {
                l.placement.check()?;
                Ok((
                    LightTable::new(&l.texture, l.placement.intensity)?,
                    l.placement,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        let (face, channels) = (self.face, self.channels);
        let order = face.order;
        Ok((0..self.receivers.len())
            .into_par_iter()
            .map_init(FaceMasses::default, |masses, p| {
                let (Some(receiver), Some(texels)) = (self.receivers[p], self.row_texels(p)) else {
                    return [0.0; 3];
                };
                let mut sum = [0.0f64; 3];
                for (table, placement) in &tables {
                    if receiver.depth <= 0.0 {
                        continue;
                    }
                    let axes = affine(&face, placement, &receiver);
                    if !masses.compute(table, axes, order) {
                        continue;
                    }
                    let (w, h) = table.size();
                    // Mean radiance = mass / texel area in texel units:
                    // order² / (s_x·s_y·w·h) per unit of mass.
                    let k = (order * order) as f64 / (axes[0].0 * axes[1].0 * (w * h) as f64);
                    let b = dot_masses(masses, texels, order, channels);
                    (0..3).for_each(|c| sum[c] += k * b[c]);
                }
                sum
            })
            .collect())
    }

    fn render_wavelet(&self, lights: &[AreaLight], terms: NearFieldTerms) -> Result<Vec<[f64; 3]>> {
        terms.check()?;
        let sources = lights
            .iter()
            .map(|l| Ok((self.source(l, terms.source)?, l.placement)))
            .collect::<Result<Vec<_>>>()?;
        let face = self.face;
        self.receivers
            .par_iter()
            .enumerate()
            .map_init(
                || match &self.table {
                    Some(table) => Propagator::with_table(face, table.clone()),
                    None => Propagator::new(face),
                },
                |propagator, (p, receiver)| {
                    let propagator = propagator.as_mut().map_err(|e| {
                        RelightError::Invalid(format!("near-field propagator: {e}"))
                    })?;
                    let Some(receiver) = receiver else {
                        return Ok([0.0; 3]);
                    };
                    let mut sum = [0.0f64; 3];
                    for (source, placement) in &sources {
                        if !propagator.prepare(source, placement, receiver, terms.targets)? {
                            continue;
                        }
                        let b = self.shading.shade(propagator, p);
                        (0..3).for_each(|k| sum[k] += b[k]);
                    }
                    Ok(sum)
                },
            )
            .collect()
    }
}

/// `Σ t·mass` over the covered face texels: grey rows give RGB from the
/// masses' three channels, RGB rows one channel each.
fn dot_masses(masses: &FaceMasses, texels: &[f32], order: usize, channels: usize) -> [f64; 3] {
    let (a0, a1) = masses.columns;
    let (b0, b1) = masses.rows;
    let width = a1 - a0;
    let n = order * order;
    let mut sum = [0.0f64; 3];
    for (b, line) in (b0..b1).zip(masses.masses.chunks_exact(width)) {
        if channels == 1 {
            let t = &texels[b * order + a0..][..width];
            for (m, &t) in line.iter().zip(t) {
                let t = f64::from(t);
                sum[0] += t * m[0];
                sum[1] += t * m[1];
                sum[2] += t * m[2];
            }
            continue;
        }
        for (c, total) in sum.iter_mut().enumerate().take(channels) {
            let t = &texels[c * n + b * order + a0..][..width];
            *total += line
                .iter()
                .zip(t)
                .map(|(m, &t)| f64::from(t) * m[c])
                .sum::<f64>();
        }
    }
    sum
}

/// The rows of points with a surface and some near-field transport as
/// per-texel integrals ([`PlaneRows::texels`]), with each row's slot,
/// charged to `limits`.
fn texel_rows(
    rows: &PlaneRows,
    receivers: &[Option<Receiver>],
    limits: &Limits,
) -> Result<(Vec<u32>, Vec<f32>, Charge)> {
    let channels = rows.channels();
    if receivers.len() != rows.rows() {
        return Err(RelightError::Invalid(format!(
            "{} near-field rows for {} surface points",
            rows.rows(),
            receivers.len()
        )));
    }
    let mut slots = vec![NO_SLOT; receivers.len()];
    let mut count = 0u32;
    for (p, slot) in slots.iter_mut().enumerate() {
        let lit = (0..channels).any(|c| !rows.row(p, c).0.is_empty());
        if receivers[p].is_some() && lit {
            *slot = count;
            count += 1;
        }
    }
    let n = rows.basis().texels();
    let len = n * channels;
    let charge = limits.check_alloc("near-field rows", count as u64 * len as u64, 4)?;
    let mut texels = vec![0.0f32; count as usize * len];
    let filled: Vec<usize> = (0..slots.len()).filter(|&p| slots[p] != NO_SLOT).collect();
    texels
        .par_chunks_mut(len.max(1))
        .zip(&filled)
        .try_for_each(|(out, &p)| {
            for (c, plane) in out.chunks_exact_mut(n).enumerate() {
                rows.texels(p, c, plane)?;
            }
            Ok::<(), RelightError>(())
        })?;
    Ok((slots, texels, charge))
}
