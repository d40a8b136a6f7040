//! The glossy path's public pieces as `ltm render --brdf` uses them: BRDF
//! specs, the lighting projected from a transport cubemap, every surface
//! point shaded from its own eye direction, and the rotation cache that
//! is read, replaced or refused.

use glam::{DVec3, Vec3};
use ltm_codec::cubemap::{texel_count, texel_direction, texel_solid_angle};
use ltm_codec::{Limits, SurfacePoint};
use ltm_relight::rotation::maps::{oct_decode, texel_center};
use ltm_relight::rotation::{
    Brdf, BrdfSlices, CacheUse, MeasuredBrdf, OctMap, RotationConfig, RotationSet, Shader,
    SliceConfig, MERL_FILE_BYTES,
};
use std::sync::Arc;

#[test]
fn brdf_specs_parse_print_and_refuse() {
    let gold: Brdf = "ggx:0.2,f0=0.95/0.64/0.54".parse().unwrap();
    assert_eq!(
        gold,
        Brdf::Ggx {
            alpha: 0.2,
            f0: [0.95, 0.64, 0.54]
        }
    );
    assert_eq!(
        "GGX:0.3,F0=0.5".parse::<Brdf>().unwrap(),
        Brdf::Ggx {
            alpha: 0.3,
            f0: [0.5; 3]
        }
    );
    assert_eq!(
        "lambert".parse::<Brdf>().unwrap(),
        Brdf::Lambert { albedo: [0.8; 3] }
    );
    for spec in [
        "ggx:0.2,f0=0.95/0.64/0.54",
        "lambert:0.7/0.6/0.5",
        "phong:50,specular=0.4",
        "plastic:0.1,albedo=0.2/0.4/0.8,ior=1.45",
    ] {
        let b: Brdf = spec.parse().unwrap();
        assert_eq!(b.to_string().parse::<Brdf>().unwrap(), b, "{spec}");
    }
    let refused = [
        ("ggx", "needs its roughness"),
        ("ggx:0.001", "0.01..=1"),
        ("ggx:0.2,ior=1.5", "no parameter 'ior'"),
        ("ggx:0.2,f0", "not key=value"),
        ("velvet:1", "unknown BRDF 'velvet'"),
        ("lambert:1/2", "not a number or r/g/b"),
        ("lambert:nan", "0..=1"),
        ("lambert:1.5", "0..=1"),
        ("phong:0.5", "1..=100000"),
        ("plastic:0.2,ior=1", "(1, 3]"),
        ("plastic:x", "not a number"),
    ];
    for (spec, says) in refused {
        let err = spec.parse::<Brdf>().unwrap_err().to_string();
        assert!(err.contains(says), "{spec}: {err}");
    }
}

#[test]
fn lighting_from_a_cubemap_keeps_its_levels_and_its_power() {
    let f = 8;
    // A constant cubemap gives a constant map.
    let constant = vec![[2.0, 1.0, 0.5]; texel_count(f)];
    let map = OctMap::from_cubemap(32, 4, f, &constant).unwrap();
    assert!(map.texels().iter().all(|t| *t == [2.0, 1.0, 0.5]));
    // One lit cube texel: the map holds its power (Σ L·Δω) within the
    // sub-sampling's error, at the texel's direction.
    let lit = 137;
    let mut delta = vec![[0.0f32; 3]; texel_count(f)];
    delta[lit] = [1.0; 3];
    let n = 64;
    let map = OctMap::from_cubemap(n, 4, f, &delta).unwrap();
    let texel_omega = |t: usize| {
        // Octahedral texels: Jacobian at the centre times the texel area.
        let (u, v) = texel_center(n, t);
        oct_decode(u, v).1 / (n * n) as f64
    };
    let power: f64 = (0..n * n)
        .map(|t| f64::from(map.texels()[t][0]) * texel_omega(t))
        .sum();
    let expected = texel_solid_angle(f, lit);
    assert!(
        (power / expected - 1.0).abs() < 0.05,
        "power {power} against {expected}"
    );
    let d: Vec3 = texel_direction(f, lit);
    assert_eq!(map.lookup(d.as_dvec3()), [1.0; 3]);
    assert_eq!(map.lookup(-d.as_dvec3()), [0.0; 3]);
    // A cubemap of the wrong length is an error naming both sizes.
    let err = OctMap::from_cubemap(32, 4, f, &constant[1..])
        .unwrap_err()
        .to_string();
    assert!(err.contains("383") && err.contains("384"), "{err}");
    assert!(OctMap::from_cubemap(32, 4, 0, &[]).is_err());
}

fn small_shader(brdf: Brdf) -> Shader {
    let limits = Limits::default();
    let cfg = RotationConfig {
        n: 16,
        normals: 8,
        supersample: 2,
        threshold: 1,
    };
    let set = Arc::new(RotationSet::build(cfg, &limits).unwrap());
    let slices = SliceConfig {
        m: 8,
        views: 16,
        supersample: 4,
        keep: 1.0,
        residuals: true,
    };
    let slices = Arc::new(BrdfSlices::build(brdf, slices, &limits).unwrap());
    Shader::new(set, slices, &limits).unwrap()
}

#[test]
fn every_point_is_shaded_from_its_own_eye_direction() {
    let albedo = [0.8, 0.5, 0.2];
    let mut shader = small_shader(Brdf::Lambert { albedo });
    let map = OctMap::from_cubemap(16, 2, 4, &vec![[1.5; 3]; texel_count(4)]).unwrap();
    shader.light(&map, None).unwrap();
    let eye = DVec3::new(0.0, 0.0, 5.0);
    let on = |p: [f32; 3], n: [f32; 3]| SurfacePoint::new(p, n);
    let mut off = on([0.0; 3], [0.0, 0.0, 1.0]);
    off.valid = false;
    let points = [
        on([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        on([1.0, 0.5, 0.0], [0.6, 0.0, 0.8]),
        // Facing away: seen from its horizon, Lambert is still ρ·L.
        on([0.0, 0.0, 0.0], [0.0, 0.0, -1.0]),
        on([0.0, 0.0, 0.0], [0.0; 3]), // no normal
        off,                           // not on the surface
    ];
    let mut out = vec![[9.0f32; 3]; points.len()];
    shader.shade_points(&points, eye, &mut out).unwrap();
    // Lambert under constant radiance L reflects ρ·L whatever the view.
    for o in &out[..3] {
        for c in 0..3 {
            let want = albedo[c] * 1.5;
            assert!((o[c] / want - 1.0).abs() < 0.03, "{o:?} against {want}");
        }
    }
    assert!(out[3..].iter().all(|o| *o == [0.0; 3]), "{out:?}");
    // The view is the point's own: a GGX highlight of a light straight
    // above is brightest where the eye sees the mirror direction.
    let mut shader = small_shader(Brdf::Ggx {
        alpha: 0.2,
        f0: [1.0; 3],
    });
    let f = 8;
    let sun = (0..texel_count(f))
        .map(|j| {
            if texel_direction(f, j).y > 0.97 {
                [5.0; 3]
            } else {
                [0.0; 3]
            }
        })
        .collect::<Vec<_>>();
    shader
        .light(&OctMap::from_cubemap(16, 4, f, &sun).unwrap(), None)
        .unwrap();
    let eye = DVec3::new(0.0, 2.0, 0.0);
    let row: Vec<SurfacePoint> = (0..9)
        .map(|i| on([i as f32 * 0.5 - 2.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
        .collect();
    let mut out = vec![[0.0f32; 3]; row.len()];
    shader.shade_points(&row, eye, &mut out).unwrap();
    // (With one shared view every point, of one normal, would shade alike.)
    // At this coarse n = 16 the peak spans the middle three points.
    for i in 0..4 {
        let (a, b) = (out[i][0], out[8 - i][0]);
        assert!((a - b).abs() <= 1e-4 * a.max(b), "not symmetric: {out:?}");
    }
    assert!(out[0][0] < out[2][0] && out[2][0] < out[3][0], "{out:?}");
    assert!(out[4][0] > 2.0 * out[0][0], "{out:?}");
    // Bad calls are errors.
    let err = shader
        .shade_points(&row, eye, &mut out[1..])
        .unwrap_err()
        .to_string();
    assert!(err.contains("one per surface point"), "{err}");
    let nan = DVec3::new(f64::NAN, 0.0, 0.0);
    assert!(shader.shade_points(&row, nan, &mut out).is_err());
}

#[test]
fn the_rotation_cache_is_read_replaced_or_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rot.bin");
    let limits = Limits::default();
    let cfg = RotationConfig {
        n: 8,
        normals: 4,
        supersample: 2,
        threshold: 1,
    };
    let (built, used) = RotationSet::cached(cfg, &path, &limits).unwrap();
    assert_eq!(used, CacheUse::Built);
    let (read, used) = RotationSet::cached(cfg, &path, &limits).unwrap();
    assert_eq!(used, CacheUse::Read);
    assert_eq!(read.to_bytes(), built.to_bytes());
    // Other settings replace the cache.
    let other = RotationConfig { normals: 2, ..cfg };
    let (_, used) = RotationSet::cached(other, &path, &limits).unwrap();
    assert_eq!(used, CacheUse::Replaced);
    assert_eq!(RotationSet::read(&path, &limits).unwrap().config(), &other);
    // A damaged cache is replaced too.
    let mut bytes = std::fs::read(&path).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    std::fs::write(&path, &bytes).unwrap();
    let (_, used) = RotationSet::cached(other, &path, &limits).unwrap();
    assert_eq!(used, CacheUse::Replaced);
    // A file that is not a cache is never replaced.
    let mine = dir.path().join("scene.ltm");
    std::fs::write(&mine, b"LTM\0 someone's file").unwrap();
    let err = RotationSet::cached(cfg, &mine, &limits)
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a rotation cache"), "{err}");
    assert_eq!(std::fs::read(&mine).unwrap(), b"LTM\0 someone's file");
    // A budget too small for the cache's file is an error, not a rebuild.
    let small = Limits::with_max_alloc(100);
    assert!(RotationSet::cached(other, &path, &small).is_err());
}

#[test]
fn every_view_slice_reflects_a_constant_lighting_in_full() {
    // A narrow lobe on a small target map keeps 8 terms of 256: its detail
    // coefficients outweigh its mean, which must be kept all the same, or
    // a constant lighting reflects nothing at some views (dark seams
    // across a glossy sphere).
    let limits = Limits::default();
    let m = 16;
    let mut plane = vec![1.0f32; m * m];
    ltm_relight::rotation::haar::forward(&mut plane, m).unwrap();
    let constant: Vec<[f32; 3]> = plane.iter().map(|&c| [c; 3]).collect();
    for brdf in ["ggx:0.05", "ggx:0.1,f0=1", "phong:2000"] {
        let brdf: Brdf = brdf.parse().unwrap();
        let cfg = SliceConfig {
            m,
            views: 32,
            supersample: 4,
            keep: 0.03,
            residuals: true,
        };
        let cut = BrdfSlices::build(brdf.clone(), cfg, &limits).unwrap();
        let full =
            BrdfSlices::build(brdf.clone(), SliceConfig { keep: 1.0, ..cfg }, &limits).unwrap();
        assert!(cut.slice(0).count() <= 8);
        for v in 0..32 * 32 {
            let (a, b) = (cut.dot(v, &constant)[0], full.dot(v, &constant)[0]);
            assert!(
                b > 0.0 && (a - b).abs() <= 1e-5 * b,
                "{brdf}, view {v}: {a} against {b}"
            );
        }
    }
}

fn lambert_over_pi(albedo: [f64; 3]) -> impl Fn(DVec3, DVec3) -> [f64; 3] + Sync {
    move |_, _| albedo.map(|a| a / std::f64::consts::PI)
}

#[test]
fn measured_brdf_files_round_trip_evaluate_and_refuse_bad_input() {
    let limits = Limits::default();
    let albedo = [0.7, 0.5, 0.3];
    let table = MeasuredBrdf::tabulate("lambert", lambert_over_pi(albedo), &limits).unwrap();
    let bytes = table.to_bytes();
    assert_eq!(bytes.len(), MERL_FILE_BYTES);
    assert_eq!(&bytes[..12], &[90, 0, 0, 0, 90, 0, 0, 0, 180, 0, 0, 0]);
    let back = MeasuredBrdf::from_bytes("lambert", &bytes, &limits).unwrap();
    assert_eq!(back, table);
    // Pairs above the horizon read the tabulated value; below, 0.
    let mut rng = 0x2545f491u64;
    let mut dir = || {
        let mut r = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        // Away from the horizon: a grazing pair can fall in a bin whose
        // centre is below it, which the layout leaves unmeasured (0).
        DVec3::new(r(), r(), 0.5 + r().abs()).normalize()
    };
    for _ in 0..1000 {
        let (wi, wo) = (dir(), dir());
        let f = back.eval(wi, wo);
        for c in 0..3 {
            let want = albedo[c] / std::f64::consts::PI;
            assert!((f[c] / want - 1.0).abs() < 1e-6, "{f:?} at {wi} {wo}");
        }
        assert_eq!(back.eval(wi, -wo), [0.0; 3]);
    }
    // A file through the spec, printed back as its spec.
    let dir_ = tempfile::tempdir().unwrap();
    let path = dir_.path().join("lambert.binary");
    std::fs::write(&path, &bytes).unwrap();
    let spec = format!("merl:{}", path.display());
    let brdf = Brdf::from_spec(&spec, &limits).unwrap();
    assert_eq!(brdf.to_string(), spec);
    // Bad files are errors that name what is wrong.
    let mut dims = bytes.clone();
    dims[0] = 45;
    let mut nan = bytes.clone();
    nan[12 + 8 * 1000..12 + 8 * 1001].copy_from_slice(&f64::NAN.to_le_bytes());
    let cases: [(&[u8], &str); 4] = [
        (&bytes[..8], "shorter than the header"),
        (&dims, "[90, 90, 180]"),
        (&bytes[..bytes.len() - 8], "file size"),
        (&nan, "not finite"),
    ];
    for (b, says) in cases {
        let err = MeasuredBrdf::from_bytes("x", b, &limits)
            .unwrap_err()
            .to_string();
        assert!(err.contains(says), "{says}: {err}");
    }
    let small = Limits::with_max_alloc(1 << 20);
    assert!(MeasuredBrdf::from_bytes("x", &bytes, &small).is_err());
    assert!(Brdf::from_spec(&spec, &small).is_err());
    let missing = Brdf::from_spec("merl:/no/such/file.binary", &limits).unwrap_err();
    assert!(
        missing.to_string().contains("/no/such/file.binary"),
        "{missing}"
    );
}

#[test]
fn a_tabulated_ggx_reflects_like_the_analytic_one() {
    // The same GGX, analytic and through the database's bins: their slices'
    // directional albedo under a constant lighting agrees per view.
    let limits = Limits::default();
    let ggx: Brdf = "ggx:0.3,f0=0.9/0.6/0.3".parse().unwrap();
    let analytic = ggx.clone();
    let table =
        MeasuredBrdf::tabulate("ggx", move |wi, wo| analytic.eval(wi, wo), &limits).unwrap();
    let measured = Brdf::Measured(Arc::new(table));
    let cfg = SliceConfig {
        m: 16,
        views: 8,
        supersample: 4,
        keep: 1.0,
        residuals: true,
    };
    let m = 16;
    let mut plane = vec![1.0f32; m * m];
    ltm_relight::rotation::haar::forward(&mut plane, m).unwrap();
    let constant: Vec<[f32; 3]> = plane.iter().map(|&c| [c; 3]).collect();
    let a = BrdfSlices::build(ggx, cfg, &limits).unwrap();
    let b = BrdfSlices::build(measured, cfg, &limits).unwrap();
    let mut worst = 0.0f32;
    for v in 0..64 {
        let (x, y) = (a.dot(v, &constant), b.dot(v, &constant));
        for c in 0..3 {
            worst = worst.max((y[c] / x[c] - 1.0).abs());
        }
    }
    eprintln!(
        "tabulated against analytic GGX: worst directional albedo {:.2} %",
        worst * 100.0
    );
    assert!(worst < 0.01, "{worst}");
}
