//! The `atlas` layout: an automatic chart atlas of the receiving surfaces,
//! as game-engine lightmappers make them (xatlas, through `ltm-xatlas`).
//!
//! xatlas cuts the receiver into charts that are near-planar and round,
//! flattens each one, and packs them into one square texture with
//! `padding` empty texels between charts. Each part gets texels in
//! proportion to its area (a finger as much per unit area as a torso),
//! unlike a single spherical chart, which shrinks whatever lies far from
//! the sphere. Vertices are split along chart seams; triangles keep their
//! order, material and part. The texture side is the requested `size`, or,
//! with only a texel density, as large as the packed charts need.
//!
//! The laid-out mesh then maps texels to surface points exactly as a `uv`
//! layout does (the `texture` module's chart grid, dilated by `dilate`).

use crate::texture::SurfaceMesh;
use glam::{DVec2, DVec3};
use ltm_codec::MAX_TEXTURE_SIZE;
use ltm_xatlas::{AtlasError, MeshInput, PackOptions};

/// What the scene asks of the atlas.
#[derive(Clone, Copy, Debug)]
pub(crate) struct AtlasRequest {
    /// Texture side, or 0: as large as `texels_per_unit` needs.
    pub size: u32,
    /// Texels per world unit of length; `None`: the densest that fits.
    pub texels_per_unit: Option<f64>,
    /// Empty texels between charts.
    pub padding: u32,
    /// Texels charts are grown by.
    pub dilate: u32,
}

/// The figures of a laid-out atlas.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AtlasQuality {
    /// Number of charts.
    pub charts: u32,
    /// The chart of each triangle.
    pub triangle_charts: Vec<u32>,
    /// Texels per world unit of length.
    pub texels_per_unit: f64,
    /// Per receiving part (mesh path or `quads[i]`): its name and its
    /// texture area per unit of surface area (texels per unit area).
    pub part_density: Vec<(String, f64)>,
}

/// The receiver with atlas texture coordinates (`(u, v)` in `[0, 1]`, v
/// up, as a mesh file's), the texture side, and the atlas's figures.
pub(crate) fn lay_out(
    mesh: &SurfaceMesh,
    req: &AtlasRequest,
    part_names: Vec<String>,
) -> Result<(SurfaceMesh, u32, AtlasQuality), String> {
    let positions: Vec<[f32; 3]> = mesh
        .positions
        .iter()
        .map(|p| p.as_vec3().to_array())
        .collect();
    let options = PackOptions {
        resolution: req.size,
        texels_per_unit: req.texels_per_unit.unwrap_or(0.0) as f32,
        padding: req.padding,
    };
    let input = MeshInput {
        positions: &positions,
        triangles: &mesh.triangles,
    };
    let atlas = ltm_xatlas::generate(input, &options).map_err(|e| match e {
        AtlasError::DoesNotFit { .. } => format!("{e}"),
        e => e.to_string(),
    })?;
    let size = if req.size > 0 {
        req.size
    } else {
        atlas.width.max(atlas.height).max(1)
    };
    if size > MAX_TEXTURE_SIZE {
        return Err(format!(
            "at {} texels per unit the atlas is {size}×{size} texels (valid: at most {MAX_TEXTURE_SIZE}); lower texels_per_unit",
            atlas.texels_per_unit
        ));
    }
    let s = size as f64;
    let src = |v: &ltm_xatlas::AtlasVertex| v.source as usize;
    let laid = SurfaceMesh {
        positions: atlas
            .vertices
            .iter()
            .map(|v| mesh.positions[src(v)])
            .collect(),
        normals: atlas
            .vertices
            .iter()
            .map(|v| mesh.normals[src(v)])
            .collect(),
        triangles: atlas.triangles.clone(),
        uvs: Some(
            atlas
                .vertices
                .iter()
                .map(|v| DVec2::new(v.uv[0] as f64 / s, 1.0 - v.uv[1] as f64 / s))
                .collect(),
        ),
        materials: mesh.materials.clone(),
        parts: mesh.parts.clone(),
        degenerate: mesh.degenerate,
        degenerate_triangles: Vec::new(),
    };
    let quality = AtlasQuality {
        charts: atlas.charts,
        triangle_charts: atlas
            .triangles
            .iter()
            .map(|t| atlas.vertices[t[0] as usize].chart)
            .collect(),
        texels_per_unit: atlas.texels_per_unit as f64,
        part_density: part_density(&laid, size, part_names),
    };
    Ok((laid, size, quality))
}

/// Per part: texture area (texels²) over surface area.
fn part_density(mesh: &SurfaceMesh, size: u32, names: Vec<String>) -> Vec<(String, f64)> {
    let mut sums = vec![(0.0f64, 0.0f64); names.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let (uv, area3) = texture_and_surface_area(mesh, tri, size);
        if let Some(s) = sums.get_mut(mesh.parts[t] as usize) {
            s.0 += uv;
            s.1 += area3;
        }
    }
    names
        .into_iter()
        .zip(sums)
        .map(|(n, (uv, a))| (n, if a > 0.0 { uv / a } else { 0.0 }))
        .collect()
}

/// A triangle's texture area in texels² and its surface area.
fn texture_and_surface_area(mesh: &SurfaceMesh, tri: &[u32; 3], size: u32) -> (f64, f64) {
    let uvs = mesh.uvs.as_ref().expect("laid out");
    let q = tri.map(|i| uvs[i as usize] * size as f64);
    let p = tri.map(|i| mesh.positions[i as usize]);
    (
        0.5 * (q[1] - q[0]).perp_dot(q[2] - q[0]).abs(),
        0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length(),
    )
}

/// Area-weighted mean and largest L2 stretch (Sander et al. 2001) of the
/// map from texture to surface, normalized so that a map of uniform scale
/// has stretch 1, and the triangles whose texture image is mirrored
/// against the majority's orientation in their chart (`charts`: one per
/// triangle; a whole chart may be mirrored, a fold inside one may not).
pub(crate) fn stretch(mesh: &SurfaceMesh, charts: &[u32]) -> (f64, f64, usize) {
    let Some(uvs) = mesh.uvs.as_ref() else {
        return (0.0, 0.0, 0);
    };
    let signed: Vec<f64> = mesh
        .triangles
        .iter()
        .map(|t| {
            let q = t.map(|i| uvs[i as usize]);
            0.5 * (q[1] - q[0]).perp_dot(q[2] - q[0])
        })
        .collect();
    let mut votes: std::collections::HashMap<u32, (usize, usize)> = Default::default();
    for (a, c) in signed.iter().zip(charts) {
        let v = votes.entry(*c).or_default();
        if *a > 0.0 {
            v.0 += 1;
        } else if *a < 0.0 {
            v.1 += 1;
        }
    }
    let flipped = votes.values().map(|&(p, n)| p.min(n)).sum();
    let uv_total: f64 = signed.iter().map(|a| a.abs()).sum();
    let area3 = mesh.area();
    if uv_total <= 0.0 || area3 <= 0.0 {
        return (0.0, 0.0, flipped);
    }
    let k = (area3 / uv_total).sqrt();
    let (mut sum, mut max) = (0.0, 0.0f64);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let q = tri.map(|i| uvs[i as usize] * k);
        let p = tri.map(|i| mesh.positions[i as usize]);
        let a = signed[t] * k * k;
        if a == 0.0 {
            continue;
        }
        let ss: DVec3 =
            (p[0] * (q[1].y - q[2].y) + p[1] * (q[2].y - q[0].y) + p[2] * (q[0].y - q[1].y))
                / (2.0 * a);
        let st: DVec3 =
            (p[0] * (q[2].x - q[1].x) + p[1] * (q[0].x - q[2].x) + p[2] * (q[1].x - q[0].x))
                / (2.0 * a);
        let s2 = 0.5 * (ss.length_squared() + st.length_squared());
        let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        sum += s2 * area;
        max = max.max(s2.sqrt());
    }
    ((sum / area3).sqrt(), max, flipped)
}
