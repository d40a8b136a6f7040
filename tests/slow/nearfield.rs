//! Near-field area lights end to end: rows baked over a light plane's face
//! (`Scene::plane_row`) and lit by propagating a textured light's Haar
//! coefficients (`ltm::relight::nearfield`), against an independent
//! estimate that samples the light's rectangle by area:
//! `B = (ρ/π) ∫ F(y)·V(x, y)·cos θ_x·cos θ_y / r² dA_y`; and a scene lit
//! near and far against Mitsuba 3, with Lambertian and with glossy (GGX)
//! receivers (fixtures in tests/fixtures/).

use glam::DVec3;
use ltm::bake::{LightPlane, Scene, SceneDesc};
use ltm::relight::nearfield::{
    transport_coefficients, LightTexture, Placement, PlaneFace, Propagator, Receiver,
    SourceCoefficients, Targets,
};
use std::path::Path;

const SCENE: &str = r#"
[camera]
eye = [0.0, 2.6, 2.2]
target = [0.0, 0.0, 0.0]
fov = 50.0
width = 24
height = 18
spp = 1

[lighting]
face_res = 4
texel_samples = 16

[materials.grey]
type = "lambert"
albedo = [0.5, 0.4, 0.3]

[[quads]]
center = [0.0, 0.0, 0.0]
size = [4.0, 4.0]
material = "grey"

[[quads]]
center = [0.25, 0.6, 0.1]
size = [0.5, 0.4]
material = "grey"
"#;

/// Side of the light texture.
const SIDE: usize = 16;

/// A 16×16 light texture: a colour ramp, stripes and a dark corner.
fn texels() -> Vec<[f32; 3]> {
    (0..SIDE * SIDE)
        .map(|j| {
            let (x, y) = ((j % SIDE) as f32, (j / SIDE) as f32);
            let stripe = if (j % SIDE) % 4 < 2 { 3.0 } else { 0.3 };
            let corner = if x < 5.0 && y < 5.0 { 0.0 } else { 1.0 };
            [
                corner * (1.0 + 0.2 * x),
                corner * (0.5 + 0.1 * y),
                corner * stripe,
            ]
        })
        .collect()
}

/// Radiance of the light at in-plane position `q` (zero outside).
fn radiance(light: &[[f32; 3]], placement: &Placement, q: [f64; 2]) -> [f64; 3] {
    let u = (q[0] - placement.center[0]) / placement.size[0] + 0.5;
    let v = (q[1] - placement.center[1]) / placement.size[1] + 0.5;
    if !(0.0..1.0).contains(&u) || !(0.0..1.0).contains(&v) {
        return [0.0; 3];
    }
    let s = SIDE as f64;
    let t = light[(v * s) as usize * SIDE + (u * s) as usize];
    [0, 1, 2].map(|c| f64::from(t[c]) * placement.intensity)
}

/// The area estimate of the reflected radiance at a floor row's point
/// (normal +Y), with `m × m` midpoint samples over the light, with or
/// without the scene's shadows.
fn by_area(
    scene: &Scene,
    plane: &LightPlane,
    placement: &Placement,
    row: &FloorRow,
    m: usize,
    shadows: bool,
) -> [f64; 3] {
    let (x, albedo) = (row.point, row.albedo);
    let texels = texels();
    let normal = DVec3::Y;
    let area = placement.size[0] * placement.size[1] / (m * m) as f64;
    let mut sum = [0.0f64; 3];
    for i in 0..m {
        for j in 0..m {
            let q = [
                placement.center[0] + placement.size[0] * ((i as f64 + 0.5) / m as f64 - 0.5),
                placement.center[1] + placement.size[1] * ((j as f64 + 0.5) / m as f64 - 0.5),
            ];
            let y = plane.point(q);
            let d = y - x;
            let r2 = d.length_squared();
            let w = d / r2.sqrt();
            let (cos_x, cos_y) = (normal.dot(w), -plane.normal().dot(w));
            let start = x + 1e-6 * normal;
            if cos_x <= 0.0 || (shadows && scene.occluded_until(start, w, (y - start).length())) {
                continue;
            }
            let f = radiance(&texels, placement, q);
            for c in 0..3 {
                sum[c] += f[c] * cos_x * cos_y / r2 * area;
            }
        }
    }
    [0, 1, 2].map(|c| sum[c] * f64::from(albedo[c]) / std::f64::consts::PI)
}

/// A row's surface point, albedo and transport's Haar coefficients.
struct FloorRow {
    point: DVec3,
    albedo: [f32; 3],
    transport: Vec<(u32, f32)>,
}

fn floor_rows(scene: &Scene, plane: &LightPlane, face: &PlaneFace) -> Vec<FloorRow> {
    let order = face.order;
    let mut row = vec![0.0f32; order * order];
    let mut rows = Vec::new();
    for p in 0..scene.dims().pixels() {
        let mut albedo = [0.0f32; 3];
        let info = scene
            .plane_row(p, plane, order, face.side, &mut row, &mut albedo)
            .unwrap();
        // Only floor points: the occluder's top is not compared.
        if let Some(point) = info.point.filter(|x| x.y.abs() < 1e-3) {
            let transport = transport_coefficients(&row, order).unwrap();
            rows.push(FloorRow {
                point,
                albedo,
                transport,
            });
        }
    }
    rows
}

fn relative_l2(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).powi(2)))
        .sum();
    let den: f64 = b.iter().flat_map(|y| y.iter().map(|v| v * v)).sum();
    (num / den).sqrt()
}

#[test]
fn near_field_light_matches_an_area_integral_with_shadows() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, SCENE).unwrap();
    let scene = Scene::build(&SceneDesc::load(&path).unwrap()).unwrap();
    let (plane, placement, face) = floor_light();
    let rows = floor_rows(&scene, &plane, &face);
    assert!(rows.len() > 200, "{} floor rows", rows.len());
    let reference: Vec<[f64; 3]> = rows
        .iter()
        .map(|r| by_area(&scene, &plane, &placement, r, 96, true))
        .collect();
    let light = LightTexture::new(SIDE, SIDE, texels()).unwrap();
    let mut propagator = Propagator::new(face).unwrap();
    let mut relit = |keep: usize, targets: Targets| -> Vec<[f64; 3]> {
        let source = SourceCoefficients::new(&light, &placement, face.order, keep).unwrap();
        rows.iter()
            .map(|r| {
                let (depth, position) = plane.locate(r.point);
                let receiver = Receiver { depth, position };
                propagator
                    .prepare(&source, &placement, &receiver, targets)
                    .unwrap();
                let b = propagator.shade(&r.transport);
                [0, 1, 2].map(|c| b[c] * f64::from(r.albedo[c]))
            })
            .collect()
    };
    let full = relative_l2(&relit(usize::MAX, Targets::All), &reference);
    eprintln!(
        "{} floor rows: every term, relative L2 {full:.4}",
        rows.len()
    );
    assert!(full < 0.03, "relative L2 {full}");
    for (source, target) in [(0.01, 0.2), (0.05, 0.3), (0.25, 0.5)] {
        let keep = (source * 1024.0f64).ceil() as usize;
        let e = relative_l2(&relit(keep, Targets::Share(target)), &reference);
        eprintln!("source {source}, target {target}: relative L2 {e:.4}");
    }
    // The shadow is part of what is checked: without it the floor differs.
    let unshadowed: Vec<[f64; 3]> = rows
        .iter()
        .map(|r| by_area(&scene, &plane, &placement, r, 96, false))
        .collect();
    let shadow = relative_l2(&unshadowed, &reference);
    eprintln!("the occluder's shadow: {shadow:.3} of the floor's light");
    assert!(shadow > 0.1, "{shadow}");
}

/// The floor tests' light: its plane 1.5 above the floor, lit side down
/// (x × z = −y), its rectangle, and an order-32 face of side 4.
fn floor_light() -> (LightPlane, Placement, PlaneFace) {
    let plane = LightPlane::new(DVec3::new(0.0, 1.5, 0.0), DVec3::X, DVec3::Z).unwrap();
    let placement = Placement {
        center: [-0.1, 0.2],
        size: [1.0, 0.8],
        intensity: 1.0,
    };
    let face = PlaneFace {
        order: 32,
        side: 4.0,
    };
    (plane, placement, face)
}

/// Shadow rays towards a light in the plane end at the plane: a ceiling
/// above it casts no shadow, though every ray through the plane would hit
/// it.
#[test]
fn a_ceiling_above_the_light_plane_casts_no_shadow() {
    let dir = tempfile::tempdir().unwrap();
    let scene_of = |extra: &str, name: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, format!("{SCENE}{extra}")).unwrap();
        Scene::build(&SceneDesc::load(&path).unwrap()).unwrap()
    };
    let open = scene_of("", "open.toml");
    // Above the plane (1.5) and over the lit floor, out of the camera's view.
    let ceiling =
        "\n[[quads]]\ncenter = [0.0, 2.0, -0.5]\nsize = [3.0, 2.0]\nmaterial = \"grey\"\n";
    let covered = scene_of(ceiling, "ceiling.toml");
    let (plane, placement, face) = floor_light();
    let (rows_open, rows_covered) = (
        floor_rows(&open, &plane, &face),
        floor_rows(&covered, &plane, &face),
    );
    assert_eq!(
        rows_open.len(),
        rows_covered.len(),
        "the same floor is seen"
    );
    assert!(rows_open.len() > 200);
    // Without the limit the ceiling would block the light: every ray from
    // the floor through the light's centre (most of them) hits it.
    let centre = plane.point(placement.center);
    let blocked = rows_covered
        .iter()
        .filter(|r| {
            let w = (centre - r.point).normalize();
            covered.occluded(r.point + 1e-6 * DVec3::Y, w)
        })
        .count();
    assert!(blocked > rows_covered.len() * 3 / 4, "{blocked} blocked");
    let light = LightTexture::new(SIDE, SIDE, texels()).unwrap();
    let source = SourceCoefficients::new(&light, &placement, face.order, usize::MAX).unwrap();
    let mut propagator = Propagator::new(face).unwrap();
    let mut relit = |rows: &[FloorRow]| -> Vec<[f64; 3]> {
        rows.iter()
            .map(|r| {
                let (depth, position) = plane.locate(r.point);
                let receiver = Receiver { depth, position };
                propagator
                    .prepare(&source, &placement, &receiver, Targets::All)
                    .unwrap();
                let b = propagator.shade(&r.transport);
                [0, 1, 2].map(|c| b[c] * f64::from(r.albedo[c]))
            })
            .collect()
    };
    let (a, b) = (relit(&rows_open), relit(&rows_covered));
    let e = relative_l2(&b, &a);
    eprintln!("ceiling against none: relative L2 {e:.2e}");
    assert!(e < 1e-3, "the ceiling changed the floor's light by {e}");
    let reference: Vec<[f64; 3]> = rows_covered
        .iter()
        .map(|r| by_area(&covered, &plane, &placement, r, 64, true))
        .collect();
    let e = relative_l2(&b, &reference);
    assert!(e < 0.03, "against the area integral under the ceiling: {e}");
}

/// Reads a float32 `H × W × 3` `.npy` fixture: `(width, height, pixels)`.
fn read_npy(name: &str) -> (usize, usize, Vec<[f32; 3]>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name);
    let bytes = std::fs::read(&path).unwrap();
    let header = ltm::codec::npy::read_npy_header(&mut &bytes[..]).unwrap();
    assert_eq!(header.dtype, ltm::codec::npy::NpyDtype::F32);
    let [h, w, 3] = header.shape[..] else {
        panic!("shape {:?}", header.shape)
    };
    let values: Vec<f32> = bytes[header.data_offset..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(values.len(), h * w * 3);
    (
        w,
        h,
        values.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect(),
    )
}

/// Pixels within 1 px of a miss or of a bend of the distance to the eye by
/// more than 1 % between a pixel and its two neighbours along a row or a
/// column (as `silhouettes` in tools/validate/mitsuba_nearfield.py).
fn silhouettes(points: &[Option<DVec3>], eye: DVec3, w: usize, h: usize) -> Vec<bool> {
    let dist: Vec<Option<f64>> = points
        .iter()
        .map(|p| p.map(|p| (p - eye).length()))
        .collect();
    let d = |x: usize, y: usize| dist[y * w + x].unwrap_or(0.0);
    let mut edge: Vec<bool> = dist.iter().map(Option::is_none).collect();
    for y in 0..h {
        for x in 0..w {
            let bends = |a: f64, b: f64| (a + b - 2.0 * d(x, y)).abs() > 0.01 * d(x, y);
            let across = x > 0 && x + 1 < w && bends(d(x - 1, y), d(x + 1, y));
            let down = y > 0 && y + 1 < h && bends(d(x, y - 1), d(x, y + 1));
            edge[y * w + x] |= across || down;
        }
    }
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            edge[i]
                || (x > 0 && edge[i - 1])
                || (x + 1 < w && edge[i + 1])
                || (y > 0 && edge[i - w])
                || (y + 1 < h && edge[i + w])
        })
        .collect()
}

/// Name, plane height, centre, size, bound.
type MitsubaLight = (&'static str, f64, [f64; 2], [f64; 2], f64);

/// The near and far lights of tools/validate/mitsuba_nearfield.py (keep in
/// step): name, plane height, centre, size (intensity 4), and the bound on
/// the relative L2 against Mitsuba 3 over the compared pixels (the issue's
/// 3 % near; 2.5 % far).
const MITSUBA_LIGHTS: [MitsubaLight; 2] = [
    ("near", 1.5, [0.15, 0.25], [0.8, 0.6], 0.03),
    ("far", 4.0, [0.3, 0.5], [2.4, 1.8], 0.025),
];

/// The face of the Mitsuba checks: order 32, side 4.
const MITSUBA_FACE: PlaneFace = PlaneFace {
    order: 32,
    side: 4.0,
};

/// The Mitsuba checks' light texture (fixture `nearfield_light.npy`).
fn mitsuba_texture() -> LightTexture {
    let (tw, th, texels) = read_npy("nearfield_light.npy");
    LightTexture::new(tw, th, texels).unwrap()
}

/// The near and far lights on `tools/validate/point/scene.toml`, against
/// Mitsuba 3's `direct` integrator along the pixel centres' rays at 16384
/// samples (fixtures from tools/validate/mitsuba_nearfield.py), over pixels
/// that see the whole light inside their face (side 4, order 32) and lie
/// more than 1 px from a silhouette. Measured: near 2.07 %, far 1.46 %
/// (Mitsuba's own noise there: 0.46 % and 0.39 %; the script's 16
/// direction samples per texel give 1.73 % and 1.27 %). The light's
/// texture flipped upside down misses by far more, so the fixture sees the
/// convention.
#[test]
fn near_and_far_lights_against_mitsuba() {
    let scene_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/validate/point/scene.toml");
    let scene = Scene::build(&SceneDesc::load(&scene_path).unwrap()).unwrap();
    let eye = DVec3::new(0.3, 1.3, 3.0);
    let (tw, th, texels) = read_npy("nearfield_light.npy");
    let light = LightTexture::new(tw, th, texels.clone()).unwrap();
    let flipped: Vec<[f32; 3]> = texels.chunks_exact(tw).rev().flatten().copied().collect();
    let flipped = LightTexture::new(tw, th, flipped).unwrap();
    let face = PlaneFace {
        order: 32,
        side: 4.0,
    };
    for (name, height, center, size, bound) in MITSUBA_LIGHTS {
        let (w, h, reference) = read_npy(&format!("nearfield_mitsuba_{name}.npy"));
        let plane = LightPlane::new(DVec3::new(0.0, height, 0.0), DVec3::X, DVec3::Z).unwrap();
        let placement = Placement {
            center,
            size,
            intensity: 4.0,
        };
        let rows = image_rows(&scene, &plane, &face);
        assert_eq!(rows.len(), w * h);
        let points: Vec<Option<DVec3>> = rows.iter().map(|r| r.as_ref().map(|r| r.point)).collect();
        let edge = silhouettes(&points, eye, w, h);
        let inside: Vec<bool> = rows
            .iter()
            .zip(&edge)
            .map(|(r, &e)| {
                !e && r
                    .as_ref()
                    .is_some_and(|r| sees_whole_light(r.point, &plane, &placement, &face))
            })
            .collect();
        let error = |light: &LightTexture| {
            let source =
                SourceCoefficients::new(light, &placement, face.order, usize::MAX).unwrap();
            let mut propagator = Propagator::new(face).unwrap();
            let (mut num, mut den) = (0.0, 0.0);
            for ((row, reference), _) in rows
                .iter()
                .zip(&reference)
                .zip(&inside)
                .filter(|(_, i)| **i)
            {
                let r = row.as_ref().unwrap();
                let (depth, position) = plane.locate(r.point);
                propagator
                    .prepare(
                        &source,
                        &placement,
                        &Receiver { depth, position },
                        Targets::All,
                    )
                    .unwrap();
                let b = propagator.shade(&r.transport);
                for c in 0..3 {
                    let ours = b[c] * f64::from(r.albedo[c]);
                    num += (ours - f64::from(reference[c])).powi(2);
                    den += f64::from(reference[c]).powi(2);
                }
            }
            (num / den).sqrt()
        };
        let share = inside.iter().filter(|i| **i).count() as f64 / inside.len() as f64;
        let (right, wrong) = (error(&light), error(&flipped));
        eprintln!(
            "{name}: {:.1} % of pixels, relative L2 {right:.4}, texture flipped {wrong:.4}",
            100.0 * share
        );
        assert!(share > 0.45, "{name}: {share}");
        assert!(right < bound, "{name}: relative L2 {right} (bound {bound})");
        assert!(
            wrong > 1.5 * right,
            "{name}: flipped {wrong} against {right}"
        );
    }
}

/// Every pixel's row over the plane's face (`None` for a miss).
fn image_rows(scene: &Scene, plane: &LightPlane, face: &PlaneFace) -> Vec<Option<FloorRow>> {
    use rayon::prelude::*;
    (0..scene.dims().pixels())
        .into_par_iter()
        .map(|p| {
            let mut row = vec![0.0f32; face.order * face.order];
            let mut albedo = [0.0f32; 3];
            let info = scene
                .plane_row(p, plane, face.order, face.side, &mut row, &mut albedo)
                .unwrap();
            let transport = transport_coefficients(&row, face.order).unwrap();
            info.point.map(|point| FloorRow {
                point,
                albedo,
                transport,
            })
        })
        .collect()
}

/// Whether the whole light rectangle lies inside the face of a row at
/// `point`.
fn sees_whole_light(
    point: DVec3,
    plane: &LightPlane,
    placement: &Placement,
    face: &PlaneFace,
) -> bool {
    let (depth, position) = plane.locate(point);
    depth > 0.0
        && (0..2).all(|a| {
            let reach = 0.5 * depth * face.side;
            let half = 0.5 * placement.size[a];
            placement.center[a] - half >= position[a] - reach
                && placement.center[a] + half <= position[a] + reach
        })
}

/// The text of the point scene `tools/validate/point/{name}`.
fn point_scene(name: &str) -> String {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/validate/point");
    std::fs::read_to_string(base.join(name)).unwrap()
}

/// A point scene's TOML `scene` (paths relative to tools/validate/point/)
/// with a `[light_plane]` at `height` (lit side down), baked at face
/// resolution 4 (the distant matrix is not what is checked here) and
/// compressed twice: the `.ltm` files' paths, named after `stem`, with the
/// near-field rows stored losslessly and at the default target (1 %).
fn stored_bake(
    dir: &Path,
    stem: &str,
    scene: &str,
    height: f64,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/validate/point");
    let text = scene.to_string()
        + &format!(
            "\n[light_plane]\norigin = [0.0, {height}, 0.0]\nx_axis = [1.0, 0.0, 0.0]\ny_axis = [0.0, 0.0, 1.0]\n"
        );
    let mut desc = SceneDesc::parse(&text, &base, &base.join("scene.toml")).unwrap();
    desc.apply(&ltm::bake::Overrides {
        face_res: Some(4),
        ..Default::default()
    })
    .unwrap();
    let scene = Scene::build(&desc).unwrap();
    let stem = format!("{stem}-{height}");
    let raw = dir.join(format!("{stem}.raw"));
    let progress = ltm::codec::Progress::NONE;
    ltm::bake(&scene, &raw, &ltm::BakeOptions::default(), progress).unwrap();
    let store = ltm::RawStore::open(&raw).unwrap();
    let lossless = ltm::CompressOptions::from(ltm::codec::CodeOptions {
        near_error: Some(0.0),
        ..Default::default()
    });
    let out = dir.join(format!("{stem}.ltm"));
    ltm::compress(&store, &out, &lossless, progress).unwrap();
    let lossy = dir.join(format!("{stem}-lossy.ltm"));
    ltm::compress(&store, &lossy, &ltm::CompressOptions::default(), progress).unwrap();
    (out, lossy)
}

/// The near-field image of the file at `path` under `light` (exact method).
fn exact_image(path: &Path, light: &ltm::relight::nearfield::AreaLight) -> Vec<[f32; 3]> {
    use ltm::relight::nearfield::{NearField, NearFieldMethod};
    let mut file = ltm::LtmFile::open(path).unwrap();
    let near = NearField::take(&mut file, &ltm::Limits::default()).unwrap();
    near.render(std::slice::from_ref(light), NearFieldMethod::Exact)
        .unwrap()
}

/// The stored path end to end: `[light_plane]` in the scene, the bake's
/// near-field rows (raw store version 6), the `.ltm` file's NEAR chunk and
/// [`NearField`](ltm::relight::nearfield::NearField), each row lit at its
/// stored surface point. It must equal the library's rows
/// (`Scene::plane_row`) lit at the same points, and meet the same bounds
/// against Mitsuba 3 as `near_and_far_lights_against_mitsuba` (measured:
/// near 2.07 %, far 1.46 %).
#[test]
fn stored_near_field_rows_against_mitsuba_and_the_library() {
    use ltm::relight::nearfield::{AreaLight, NearField, NearFieldMethod, NearFieldTerms};
    let dir = tempfile::tempdir().unwrap();
    let (texture, face) = (mitsuba_texture(), MITSUBA_FACE);
    for (name, height, center, size, bound) in MITSUBA_LIGHTS {
        let (path, lossy) = stored_bake(dir.path(), "diffuse", &point_scene("scene.toml"), height);
        let mut file = ltm::LtmFile::open(&path).unwrap();
        assert!(file.near_field().is_some(), "the NEAR chunk is stored");
        let near = NearField::take(&mut file, &ltm::Limits::default()).unwrap();
        assert!(file.near_field().is_none(), "taken out of the file");
        let placement = Placement {
            center,
            size,
            intensity: 4.0,
        };
        let light = AreaLight {
            texture: texture.clone(),
            placement,
        };
        let all = NearFieldMethod::Wavelet(NearFieldTerms::ALL);
        let image = near.render(std::slice::from_ref(&light), all).unwrap();
        let exact = near
            .render(std::slice::from_ref(&light), NearFieldMethod::Exact)
            .unwrap();
        // Rows quantized to 1 % (the default): a smaller chunk, and an
        // image within that of the lossless rows' (measured: 0.1–0.5 %).
        let rounded = exact_image(&lossy, &light);
        let size = |p: &Path| std::fs::metadata(p).unwrap().len();
        assert!(
            size(&lossy) * 2 < size(&path),
            "{} {}",
            size(&lossy),
            size(&path)
        );
        let wide = |v: &[[f32; 3]]| v.iter().map(|t| t.map(f64::from)).collect::<Vec<_>>();
        let moved = relative_l2(&wide(&rounded), &wide(&exact));
        eprintln!("stored {name}: rows at 1 % move the image by {moved:.5}");
        assert!(moved < 0.01, "{name}: {moved}");
        let (w, h, reference) = read_npy(&format!("nearfield_mitsuba_{name}.npy"));
        assert_eq!(image.len(), w * h);
        let points = stored_points(&file);
        let plane = LightPlane::new(DVec3::new(0.0, height, 0.0), DVec3::X, DVec3::Z).unwrap();
        library_rows_agree(&path, &image, &points, (&plane, &placement, &texture, face));
        let inside = inside_pixels(&points, (w, h), &plane, &placement, &face);
        let count = inside.len();
        assert!(count > w * h * 45 / 100, "{name}: {count} pixels");
        let methods = [
            ("wavelet, every term", &image),
            ("exact", &exact),
            ("exact, rows at 1 %", &rounded),
        ];
        for (method, image) in methods {
            let error = error_over(image, &reference, &inside);
            eprintln!("stored {name} ({method}): {count} pixels, relative L2 {error:.4}");
            assert!(
                error < bound,
                "{name} ({method}): relative L2 {error} (bound {bound})"
            );
        }
    }
}

/// A file's stored surface points (SURF), `None` where the row missed.
fn stored_points(file: &ltm::LtmFile) -> Vec<Option<DVec3>> {
    file.surface()
        .unwrap()
        .points()
        .iter()
        .map(|s| {
            s.valid
                .then(|| DVec3::from_array(s.position.map(f64::from)))
        })
        .collect()
}

/// The pixels of the point scenes' camera (eye at (0.3, 1.3, 3)) compared
/// with Mitsuba: those that see the whole light inside their face and lie
/// more than 1 px from a silhouette.
fn inside_pixels(
    points: &[Option<DVec3>],
    (w, h): (usize, usize),
    plane: &LightPlane,
    placement: &Placement,
    face: &PlaneFace,
) -> Vec<usize> {
    let edge = silhouettes(points, DVec3::new(0.3, 1.3, 3.0), w, h);
    (0..w * h)
        .filter(|&p| {
            !edge[p]
                && points[p].is_some_and(|point| sees_whole_light(point, plane, placement, face))
        })
        .collect()
}

/// Relative L2 of `image` against `reference` over the pixels `over`.
fn error_over(image: &[[f32; 3]], reference: &[[f32; 3]], over: &[usize]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for &p in over {
        for c in 0..3 {
            num += (f64::from(image[p][c]) - f64::from(reference[p][c])).powi(2);
            den += f64::from(reference[p][c]).powi(2);
        }
    }
    (num / den).sqrt()
}

/// Glossy receivers through the stored path: `tools/validate/point/glossy.toml`
/// (the bunny and the ground GGX conductors with Fresnel 1, alpha 0.25 and
/// 0.3; the wall Lambertian), RGB rows over the plane's face, against
/// Mitsuba 3's `roughconductor` under the same near and far lights
/// (fixtures from `tools/validate/mitsuba_nearfield.py --scene glossy`),
/// over the same kind of pixels as the diffuse check (measured: near
/// 1.95 %, far 1.54 %; the script's 16 direction samples per texel give
/// 1.78 % and 1.47 %). The same scene with rougher conductors (alpha 0.5
/// and 0.6) must miss by far more, so the fixture sees the lobes.
#[test]
fn glossy_receivers_against_mitsuba() {
    use ltm::relight::nearfield::{AreaLight, NearField, NearFieldMethod};
    let dir = tempfile::tempdir().unwrap();
    let (texture, face) = (mitsuba_texture(), MITSUBA_FACE);
    for (name, height, center, size, bound) in MITSUBA_LIGHTS {
        let light = AreaLight {
            texture: texture.clone(),
            placement: Placement {
                center,
                size,
                intensity: 4.0,
            },
        };
        let (w, h, reference) = read_npy(&format!("nearfield_mitsuba_glossy_{name}.npy"));
        let mut errors = Vec::new();
        let glossy = point_scene("glossy.toml");
        let rough = glossy
            .replace("roughness = 0.3", "roughness = 0.6")
            .replace("roughness = 0.25", "roughness = 0.5");
        assert_ne!(rough, glossy);
        for (scene, text) in [("glossy", &glossy), ("rougher", &rough)] {
            let (path, _) = stored_bake(dir.path(), scene, text, height);
            let mut file = ltm::LtmFile::open(&path).unwrap();
            assert_eq!(file.near_field().map(|r| r.channels()), Some(3), "RGB rows");
            let near = NearField::take(&mut file, &ltm::Limits::default()).unwrap();
            let image = near
                .render(std::slice::from_ref(&light), NearFieldMethod::Exact)
                .unwrap();
            assert_eq!(image.len(), w * h);
            let plane = LightPlane::new(DVec3::new(0.0, height, 0.0), DVec3::X, DVec3::Z).unwrap();
            let inside = inside_pixels(
                &stored_points(&file),
                (w, h),
                &plane,
                &light.placement,
                &face,
            );
            assert!(
                inside.len() > w * h * 45 / 100,
                "{name}: {} pixels",
                inside.len()
            );
            let error = error_over(&image, &reference, &inside);
            eprintln!(
                "glossy {name} ({scene}): {} pixels, relative L2 {error:.4}",
                inside.len()
            );
            errors.push(error);
        }
        let [right, rough] = errors[..] else {
            unreachable!()
        };
        assert!(right < bound, "{name}: relative L2 {right} (bound {bound})");
        assert!(
            rough > 5.0 * right,
            "{name}: rougher {rough} against {right}"
        );
    }
}

/// The library's row of every pixel (`Scene::plane_row`, the bake's own
/// computation) lit at the stored surface point equals the stored path's
/// image within float rounding.
fn library_rows_agree(
    ltm_path: &Path,
    image: &[[f32; 3]],
    points: &[Option<DVec3>],
    (plane, placement, texture, face): (&LightPlane, &Placement, &LightTexture, PlaneFace),
) {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/validate/point");
    let height = plane.point([0.0, 0.0]).y;
    let text = std::fs::read_to_string(base.join("scene.toml")).unwrap();
    let scene =
        Scene::build(&SceneDesc::parse(&text, &base, &base.join("scene.toml")).unwrap()).unwrap();
    let albedo = ltm::LtmFile::open(ltm_path)
        .unwrap()
        .albedo()
        .unwrap()
        .to_vec();
    let source = SourceCoefficients::new(texture, placement, face.order, usize::MAX).unwrap();
    let mut propagator = Propagator::new(face).unwrap();
    let mut row = vec![0.0f32; face.order * face.order];
    let mut worst = 0.0f64;
    for (p, point) in points.iter().enumerate().step_by(7) {
        let mut a = [0.0f32; 3];
        scene
            .plane_row(p, plane, face.order, face.side, &mut row, &mut a)
            .unwrap();
        let want = match point {
            Some(x) => {
                let (depth, position) = plane.locate(*x);
                let receiver = Receiver { depth, position };
                if propagator
                    .prepare(&source, placement, &receiver, Targets::All)
                    .unwrap()
                {
                    let b = propagator.shade(&transport_coefficients(&row, face.order).unwrap());
                    [0, 1, 2].map(|c| (b[c] * f64::from(albedo[3 * p + c])).max(0.0))
                } else {
                    [0.0; 3]
                }
            }
            None => [0.0; 3],
        };
        for c in 0..3 {
            let d = (want[c] - f64::from(image[p][c])).abs();
            worst = worst.max(d / want[c].abs().max(1e-3));
        }
    }
    eprintln!(
        "plane at {height}: stored against library rows, worst relative difference {worst:.2e}"
    );
    // The stored path sums in f32 (`shade_bands`, `shade_rgb_bands`), the
    // library's in f64.
    assert!(worst < 2e-5, "{worst}");
}
