//! The transport rows against closed-form values.

use crate::common;

use common::*;
use glam::DVec3;
use ltm_bake::Scene;
use ltm_codec::cubemap::{face_point_direction, texel_index, texel_solid_angle};
use std::f64::consts::PI;

const PLANE: &str =
    "[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [400.0, 400.0]\nmaterial = \"grey\"\n";

fn plane_scene(extra: &str, lighting: &str) -> Scene {
    let toml = scene_toml(CAMERA, lighting, &format!("{PLANE}{extra}"))
        .replace("albedo = [0.5, 0.5, 0.5]", "albedo = [0.5, 0.25, 0.8]");
    let (_d, r) = build(&toml, &[]);
    r.expect("plane scene")
}

fn row(scene: &Scene, p: usize) -> (Vec<f32>, [f32; 3]) {
    let mut row = vec![0.0; scene.dims().row_len()];
    let mut albedo = [0.0; 3];
    scene.transport_row(p, &mut row, &mut albedo);
    (row, albedo)
}

/// (a) An unoccluded Lambertian plane facing +Y reflects its albedo under
/// L = 1: Σ_j T[p][j] = (1/π)∫cos dω = 1 (grey), B = albedo.
#[test]
fn unoccluded_plane_row_sums_to_one() {
    let scene = plane_scene("", "face_res = 8\ntexel_samples = 4");
    assert_eq!(scene.channels(), 1);
    for p in 0..scene.dims().pixels() {
        let (row, albedo) = row(&scene, p);
        let sum: f64 = row.iter().map(|&v| v as f64).sum();
        assert!((sum - 1.0).abs() < 0.01, "pixel {p}: row sum {sum}");
        assert_eq!(albedo, [0.5, 0.25, 0.8]);
        assert!(row.iter().all(|&v| v >= 0.0));
    }
    // Texels below the horizon are exactly zero.
    let (row, _) = row(&scene, 40);
    let n = 8;
    for r in 0..n {
        for c in 0..n {
            assert_eq!(row[texel_index(n, 3, r, c)], 0.0, "-Y face");
        }
    }
}

/// The same with 3 channels (a glossy material elsewhere in the scene):
/// the albedo is folded into T, B = albedo per channel.
#[test]
fn unoccluded_plane_three_channels() {
    let hidden = "[materials.shiny]\ntype = \"glossy\"\nalbedo = [0.5, 0.5, 0.5]\nspecular = [0.04, 0.04, 0.04]\nroughness = 0.3\n\
[[quads]]\ncenter = [0.0, -50.0, 0.0]\nsize = [0.1, 0.1]\nmaterial = \"shiny\"\n";
    let scene = plane_scene(hidden, "face_res = 8\ntexel_samples = 4");
    assert_eq!(scene.channels(), 3);
    let (row, albedo) = row(&scene, 40);
    assert_eq!(albedo, [0.0; 3]);
    for (c, want) in [0.5, 0.25, 0.8].into_iter().enumerate() {
        let sum: f64 = row.iter().skip(c).step_by(3).map(|&v| v as f64).sum();
        assert!(
            (sum - want).abs() < 0.01 * want,
            "channel {c}: {sum} vs {want}"
        );
    }
}

/// (b) A single-texel light: T[p][j] ≈ cos θ_j · Ω_j / π (grey) for texels
/// near the normal.
#[test]
fn single_texel_matches_cosine_times_solid_angle() {
    let n = 16;
    let scene = plane_scene("", "face_res = 16\ntexel_samples = 16");
    let (row, _) = row(&scene, 40); // the centre pixel of the 9×9 image
    for (r, c) in [(8, 8), (7, 8), (5, 10), (2, 13), (0, 0)] {
        let j = texel_index(n, 2, r, c);
        let d = face_point_direction(2, (c as f64 + 0.5) / n as f64, (r as f64 + 0.5) / n as f64);
        let want = d.y * texel_solid_angle(n, j) / PI;
        let got = row[j] as f64;
        assert!(
            (got - want).abs() < 0.01 * want,
            "texel ({r}, {c}): {got} vs {want}"
        );
    }
}

/// (c) A small occluder above the plane zeroes exactly the texels it covers
/// and leaves the far ones untouched.
#[test]
fn occluder_zeroes_the_covered_texels() {
    let n = 8;
    let occluder = "[[quads]]\ncenter = [0.0, 1.0, 0.0]\nsize = [0.6, 0.6]\nmaterial = \"grey\"\n";
    let lighting = "face_res = 8\ntexel_samples = 4";
    let open = plane_scene("", lighting);
    let shadowed = plane_scene(occluder, lighting);
    // The 9×9 image's centre pixel looks exactly at the target, the origin.
    let c = shadowed.camera().expect("a camera bake");
    let hit = shadowed
        .intersect(c.eye, c.direction(4.5, 4.5))
        .expect("hit");
    assert!(hit.point.length() < 1e-5, "{:?}", hit.point);
    let (free, _) = row(&open, 40);
    let (shade, _) = row(&shadowed, 40);
    let mut partly = 0;
    // From the origin the occluder covers +Y face coordinates s, t in
    // [0.35, 0.65]: texels (3..=4, 3..=4) wholly, columns/rows 2 and 5 partly.
    for r in 0..n {
        for col in 0..n {
            let j = texel_index(n, 2, r, col);
            let inside = (3..=4).contains(&r) && (3..=4).contains(&col);
            let touching = (2..=5).contains(&r) && (2..=5).contains(&col);
            if inside {
                assert_eq!(shade[j], 0.0, "covered texel ({r}, {col})");
                assert!(free[j] > 0.0);
            } else if !touching {
                assert_eq!(shade[j], free[j], "uncovered texel ({r}, {col})");
            } else {
                assert!(shade[j] <= free[j], "partly covered texel ({r}, {col})");
                partly += u32::from(shade[j] < free[j]);
            }
        }
    }
    assert!(
        partly >= 4,
        "only {partly} partly covered texels lost light"
    );
    // Side faces are untouched.
    for j in (0..6 * n * n).filter(|j| j / (n * n) != 2) {
        assert_eq!(shade[j], free[j]);
    }
}

/// A sub-sampled pixel on the edge between plane and background averages:
/// grey transport stays the plane's, the albedo image carries the coverage.
#[test]
fn coverage_goes_to_the_albedo_image() {
    let toml = scene_toml(
        "eye = [0.0, 1.0, 0.0]\ntarget = [0.0, 0.0, -10.0]\nfov = 40.0\nwidth = 9\nheight = 9\nspp = 64",
        "face_res = 8\ntexel_samples = 4",
        PLANE,
    );
    let (_d, r) = build(&toml, &[]);
    let scene = r.unwrap();
    let mut seen_partial = false;
    for p in 0..81 {
        let (row, albedo) = row(&scene, p);
        let sum: f64 = row.iter().map(|&v| v as f64).sum();
        if albedo[0] == 0.0 {
            assert_eq!(sum, 0.0, "background pixel {p}");
        } else {
            assert!((sum - 1.0).abs() < 0.01, "pixel {p}: {sum}");
            assert!(albedo[0] <= 0.5 + 1e-6);
            seen_partial |= albedo[0] < 0.49 && albedo[0] > 0.01;
        }
    }
    assert!(seen_partial, "the horizon should cut some pixels");
}

/// Mesh transforms: scale, then rotation X, Y, Z, then translation.
#[test]
fn mesh_transform_order() {
    // A triangle around the origin in the XY plane.
    let obj = "v -0.1 -0.1 0\nv 0.1 -0.1 0\nv 0 0.1 0\nf 1 2 3\n";
    let body = "[[meshes]]\npath = \"t.obj\"\nmaterial = \"grey\"\nscale = [1.0, 1.0, 1.0]\nrotation = [0.0, 90.0, 0.0]\ntranslation = [5.0, 0.0, 0.0]\n";
    let (_d, r) = build(
        &scene_toml(CAMERA, LIGHTING, body),
        &[("t.obj", obj.as_bytes())],
    );
    let scene = r.unwrap();
    // Rotated 90° about Y the triangle lies in the YZ plane at x = 5.
    let hit = scene
        .intersect(DVec3::new(0.0, 0.0, 0.0), DVec3::X)
        .expect("the triangle faces the origin along X");
    assert!((hit.point - DVec3::new(5.0, 0.0, 0.0)).length() < 1e-5);
    assert!((hit.ng.abs() - DVec3::X).length() < 1e-5);
    assert!(scene
        .intersect(DVec3::new(0.0, 0.0, 5.0), -DVec3::Z)
        .is_none());
}

/// Directions with negative-zero components trace like any other (obvhs
/// 0.4 alone would miss everything along them).
#[test]
fn negative_zero_directions_hit() {
    let (_d, r) = build(&scene_toml(CAMERA, LIGHTING, PLANE), &[]);
    let scene = r.unwrap();
    let o = DVec3::new(0.0, 1.0, 0.0);
    for d in [DVec3::new(-0.0, -1.0, -0.0), DVec3::new(0.0, -1.0, -0.0)] {
        assert!(scene.intersect(o, d).is_some(), "{d:?}");
        assert!(scene.occluded(o, d), "{d:?}");
    }
}

/// One texel per face: the solid-angle density varies 5× across a texel,
/// so the sample weighting must follow it. The +Y face seen from a surface
/// facing +Y collects (1/π)∫_{face} cos θ dω, computed here on a fine grid
/// over the face plane y = 1 (dω = da db / (1 + a² + b²)^{3/2}, cos θ =
/// 1/√(1 + a² + b²)).
#[test]
fn whole_face_texel_follows_the_solid_angle_density() {
    let scene = plane_scene("", "face_res = 1\ntexel_samples = 4096");
    let (row, _) = row(&scene, 40);
    let g = 2000;
    let mut want = 0.0;
    for i in 0..g {
        for k in 0..g {
            let a = -1.0 + 2.0 * (i as f64 + 0.5) / g as f64;
            let b = -1.0 + 2.0 * (k as f64 + 0.5) / g as f64;
            want += 1.0 / (1.0 + a * a + b * b).powi(2);
        }
    }
    want *= 4.0 / (g * g) as f64 / PI;
    let got = row[texel_index(1, 2, 0, 0)] as f64;
    assert!((got - want).abs() < 0.003 * want, "{got} vs {want}");
    let sum: f64 = row.iter().map(|&v| v as f64).sum();
    assert!((sum - 1.0).abs() < 0.01, "row sum {sum}");
}

/// `Scene::shadow_rays` yields exactly the rays the row traces (their count
/// is the row's shadow-ray count), unit directions from finite origins, and
/// the tracer's own answers; some are occluded (the box on the plane).
#[test]
fn shadow_rays_are_the_rows_rays() {
    let bx = "[[quads]]\ncenter = [0.0, 0.3, 0.0]\nsize = [0.5, 0.5]\nmaterial = \"grey\"\n";
    let scene = plane_scene(bx, "face_res = 4\ntexel_samples = 2");
    let (mut occluded, mut total) = (0, 0);
    for p in (0..scene.dims().pixels()).step_by(7) {
        let mut row = vec![0.0; scene.dims().row_len()];
        let stats = scene.transport_row(p, &mut row, &mut [0.0; 3]);
        let mut count = 0u64;
        scene.shadow_rays(p, &mut |o, dirs, hits| {
            assert_eq!(dirs.len(), hits.len());
            for (&d, &hit) in dirs.iter().zip(hits) {
                assert!(o.is_finite() && (d.length() - 1.0).abs() < 1e-9, "{o} {d}");
                assert_eq!(hit, scene.occluded(o, d));
                occluded += hit as u64;
                count += 1;
            }
        });
        assert_eq!(count, stats.shadow_rays, "pixel {p}");
        total += count;
    }
    assert!(occluded > 0 && occluded < total, "{occluded} of {total}");
}

/// Rows over a light plane's face: on an unoccluded floor facing the
/// plane, `Σ_j t[j] = (1/π) ∫∫ (1 + |v|²)⁻² dv` over the face `[−2, 2]²`
/// (cos·dω in tangent coordinates), here by a fine midpoint rule; the
/// texels' share of it follows the cosine; bad calls are errors.
#[test]
fn plane_rows_integrate_the_face_and_bad_calls_error() {
    use ltm_bake::LightPlane;
    let scene = plane_scene("", "face_res = 8\ntexel_samples = 4");
    let plane = LightPlane::new(DVec3::new(0.0, 2.0, 0.0), DVec3::X, DVec3::Z).unwrap();
    let order = 16;
    let m = 2000;
    let h = 4.0 / m as f64;
    let mut expected = 0.0;
    for i in 0..m {
        for j in 0..m {
            let (x, y) = (-2.0 + (i as f64 + 0.5) * h, -2.0 + (j as f64 + 0.5) * h);
            expected += h * h / (1.0 + x * x + y * y).powi(2);
        }
    }
    expected /= PI;
    let mut row = vec![0.0f32; order * order];
    let mut albedo = [0.0f32; 3];
    let info = scene
        .plane_row(40, &plane, order, 4.0, &mut row, &mut albedo)
        .unwrap();
    let point = info.point.expect("the floor");
    assert!(
        point.y.abs() < 1e-3 && info.stats.shadow_rays > 0,
        "{point} {:?}",
        info.stats
    );
    let sum: f64 = row.iter().map(|&v| f64::from(v)).sum();
    assert!(
        (sum - expected).abs() < 0.01 * expected,
        "{sum} against {expected}"
    );
    // The centre texels see the most, the corners the least.
    let centre = row[(order / 2) * order + order / 2];
    assert!(centre > 5.0 * row[0] && row.iter().all(|&v| v >= 0.0));
    assert_eq!(albedo, [0.5, 0.25, 0.8]);

    for (order, side, len) in [
        (0, 4.0, 0),
        (2048, 4.0, 4),
        (16, 0.0, 256),
        (16, f64::NAN, 256),
        (16, 4.0, 255),
    ] {
        let mut row = vec![0.0f32; len];
        let err = scene
            .plane_row(40, &plane, order, side, &mut row, &mut albedo)
            .unwrap_err();
        assert!(err.to_string().contains("valid"), "{err}");
    }
    // A plane facing away from the floor: the face is below its horizon.
    let away = LightPlane::new(DVec3::new(0.0, 2.0, 0.0), DVec3::Z, DVec3::X).unwrap();
    scene
        .plane_row(40, &away, 16, 4.0, &mut row, &mut albedo)
        .unwrap();
    assert!(row.iter().all(|&v| v == 0.0));
}
