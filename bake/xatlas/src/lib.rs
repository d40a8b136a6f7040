//! `ltm-xatlas`: automatic chart atlases for texture-space bakes, a safe
//! binding to xatlas (vendored in `vendor/`, MIT licence in
//! `vendor/LICENSE`).
//!
//! xatlas grows charts over a triangle mesh (seeded where normals deviate,
//! grown while the charts stay near-planar and round), flattens each chart
//! (planar, orthogonal or least-squares conformal), and packs the charts
//! into one texture with a padding of texels between them: the same
//! automatic lightmap atlas that game engines bake into. This crate feeds
//! it one mesh and returns, per output vertex, its source vertex and its
//! texture coordinate in texels, and per triangle its corners.
//!
//! xatlas is compiled single-threaded (`XA_MULTITHREADED=0`): its chart
//! seeds and packing come from fixed-seed generators, so an atlas depends
//! on its inputs alone, which the bake's input identity and resume rely
//! on. The published `xatlas-rs` crate does not link on Linux (its
//! bindings name MSVC-mangled symbols), hence this binding to xatlas's C
//! interface.

mod ffi;

use thiserror::Error;

/// The vendored xatlas: the source release it was taken from, and the
/// local patch (`vendor/README.md`).
pub const XATLAS_VERSION: &str = "xatlas (PyPI xatlas 0.0.11 sources) + ltm patch 1";

/// Largest texture side packed: a density whose charts would need more
/// is refused before xatlas runs (xatlas itself crashes on atlases of
/// hundreds of thousands of texels a side).
pub const MAX_SIDE: u32 = 8192;

/// Largest vertex or triangle count given to xatlas.
pub const MAX_ELEMENTS: usize = 1 << 24;

/// Why an atlas could not be made.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum AtlasError {
    /// The mesh is empty, too large or malformed.
    #[error("cannot make an atlas of this mesh: {0}")]
    Mesh(String),
    /// The charts did not fit one texture of the requested side.
    #[error("the charts need {atlases} textures of {side}×{side} at {texels_per_unit} texels per unit (valid: one); lower the texel density or raise the size")]
    DoesNotFit {
        /// Textures xatlas needed.
        atlases: u32,
        /// The requested side.
        side: u32,
        /// The density used.
        texels_per_unit: f32,
    },
    /// xatlas returned an output this binding cannot use.
    #[error("xatlas returned an unusable atlas: {0}")]
    Output(String),
}

/// A mesh to lay out.
#[derive(Clone, Copy, Debug)]
pub struct MeshInput<'a> {
    /// Vertex positions (finite).
    pub positions: &'a [[f32; 3]],
    /// Triangles as indices into `positions` (non-degenerate ones; xatlas
    /// leaves zero-area triangles out of every chart).
    pub triangles: &'a [[u32; 3]],
}

/// How to pack.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackOptions {
    /// Side of the square texture, texels; 0: as large as
    /// `texels_per_unit` needs.
    pub resolution: u32,
    /// Texels per world unit of length; 0: the largest density at which
    /// the charts fit `resolution` (estimated by xatlas).
    pub texels_per_unit: f32,
    /// Empty texels kept between charts.
    pub padding: u32,
}

/// One vertex of the atlas: a corner of a chart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtlasVertex {
    /// Index of the input vertex it stands for.
    pub source: u32,
    /// Texture coordinate in texels (`x` right, `y` down, in
    /// `[0, width] × [0, height]`).
    pub uv: [f32; 2],
    /// Index of its chart.
    pub chart: u32,
}

/// The packed atlas of one mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Atlas {
    /// Texture width and height used by the charts, texels.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// Texels per world unit of length.
    pub texels_per_unit: f32,
    /// Number of charts.
    pub charts: u32,
    /// Fraction of the texture's texels that charts cover (xatlas's
    /// estimate).
    pub utilization: f32,
    /// Output vertices (input vertices are split along chart seams).
    pub vertices: Vec<AtlasVertex>,
    /// Triangles as indices into `vertices`, in input order.
    pub triangles: Vec<[u32; 3]>,
}

/// Lays `mesh` out in one texture: at `options.texels_per_unit` when it
/// is positive (in a `resolution`-sided texture, or one just large enough
/// when `resolution` is 0), else at the highest density found whose
/// charts fit one `resolution`-sided texture.
pub fn generate(mesh: MeshInput<'_>, options: &PackOptions) -> Result<Atlas, AtlasError> {
    check(mesh)?;
    let tpu = options.texels_per_unit;
    if !(tpu.is_finite() && tpu >= 0.0) || (tpu == 0.0 && options.resolution == 0) {
        return Err(AtlasError::Mesh(format!(
            "texels per unit {tpu} and resolution {} (valid: a finite density ≥ 0, and a resolution where it is 0)",
            options.resolution
        )));
    }
    check_density(mesh, options)?;
    let mut handle = ffi::Handle::charts(mesh)?;
    if tpu > 0.0 {
        return pack_once(&mut handle, mesh, options);
    }
    fit(&mut handle, mesh, options)
}

fn pack_once(
    handle: &mut ffi::Handle,
    mesh: MeshInput<'_>,
    options: &PackOptions,
) -> Result<Atlas, AtlasError> {
    handle.pack(options);
    let atlas = handle.read(mesh)?;
    if handle.atlas_count() > 1 {
        return Err(AtlasError::DoesNotFit {
            atlases: handle.atlas_count(),
            side: options.resolution,
            texels_per_unit: options.texels_per_unit,
        });
    }
    Ok(atlas)
}

/// Packings tried when searching for the density that fills a texture.
const FIT_TRIES: usize = 16;

/// The densest packing found that fits one `resolution`-sided texture:
/// from xatlas's estimate (scaled by how far its packing over- or
/// undershot the side), shrunk by a fifth until the charts fit, then
/// bisected between the densest fit and the sparsest miss.
fn fit(
    handle: &mut ffi::Handle,
    mesh: MeshInput<'_>,
    options: &PackOptions,
) -> Result<Atlas, AtlasError> {
    let side = options.resolution;
    handle.pack(&PackOptions {
        resolution: 0,
        ..*options
    });
    let first = handle.read(mesh)?;
    let used = first.width.max(first.height).max(1) as f32;
    let mut tpu = first.texels_per_unit * (side as f32 / used);
    let mut try_at = |tpu: f32| {
        let opts = PackOptions {
            texels_per_unit: tpu,
            ..*options
        };
        match pack_once(handle, mesh, &opts) {
            Err(AtlasError::DoesNotFit { .. }) => Ok(None),
            other => other.map(Some),
        }
    };
    let (mut best, mut miss) = (None, None);
    for _ in 0..FIT_TRIES {
        match (try_at(tpu)?, &best, miss) {
            (Some(a), _, _) => {
                best = Some((tpu, a));
                match miss {
                    None => tpu *= 1.25,
                    Some(m) => tpu = 0.5 * (tpu + m),
                }
            }
            (None, Some((b, _)), _) => {
                miss = Some(tpu);
                tpu = 0.5 * (tpu + b);
            }
            (None, None, _) => {
                miss = Some(tpu);
                tpu *= 0.8;
            }
        }
        if let (Some((b, _)), Some(m)) = (&best, miss) {
            if m - b <= 0.01 * b {
                break;
            }
        }
    }
    best.map(|(_, a)| a).ok_or(AtlasError::DoesNotFit {
        atlases: 2,
        side,
        texels_per_unit: tpu,
    })
}

/// Refuses a side above [`MAX_SIDE`], and a density at which the surface
/// alone would cover more than a [`MAX_SIDE`]² texture.
fn check_density(mesh: MeshInput<'_>, options: &PackOptions) -> Result<(), AtlasError> {
    if options.resolution > MAX_SIDE {
        return Err(AtlasError::Mesh(format!(
            "texture side {} (valid: at most {MAX_SIDE})",
            options.resolution
        )));
    }
    let area: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].map(f64::from));
            let (u, v) = (
                [0, 1, 2].map(|k| b[k] - a[k]),
                [0, 1, 2].map(|k| c[k] - a[k]),
            );
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
        })
        .sum();
    let texels = area * (options.texels_per_unit as f64).powi(2);
    let limit = (MAX_SIDE as f64).powi(2);
    if texels > limit {
        return Err(AtlasError::Mesh(format!(
            "at {} texels per unit the surface (area {area:.4e}) covers {texels:.3e} texels (valid: at most {MAX_SIDE}² = {limit:.3e}); lower the texel density",
            options.texels_per_unit
        )));
    }
    Ok(())
}

fn check(mesh: MeshInput<'_>) -> Result<(), AtlasError> {
    let (v, t) = (mesh.positions.len(), mesh.triangles.len());
    if v == 0 || t == 0 {
        return Err(AtlasError::Mesh(format!(
            "{v} vertices and {t} triangles (valid: at least one of each)"
        )));
    }
    if v > MAX_ELEMENTS || t > MAX_ELEMENTS {
        return Err(AtlasError::Mesh(format!(
            "{v} vertices and {t} triangles (valid: at most {MAX_ELEMENTS} each)"
        )));
    }
    if let Some(i) = mesh
        .positions
        .iter()
        .position(|p| p.iter().any(|c| !c.is_finite()))
    {
        return Err(AtlasError::Mesh(format!(
            "vertex {i} has a non-finite position {:?}",
            mesh.positions[i]
        )));
    }
    if let Some(i) = mesh
        .triangles
        .iter()
        .position(|tri| tri.iter().any(|&k| k as usize >= v))
    {
        return Err(AtlasError::Mesh(format!(
            "triangle {i} has vertex indices {:?} (valid: below {v})",
            mesh.triangles[i]
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
