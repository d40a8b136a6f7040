//! Relighting `pca` files: the blocked loop against the scalar reference,
//! relit images against the exact `T·L` and against the dense product of
//! the decoded matrix, `--terms` below the rank, and `open`.

use ltm_codec::compress::{compress_pca, PcaOptions};
use ltm_codec::npy::decode_matrix;
use ltm_codec::{Dims, Limits, LtmFile, RawHeader, RawStore, RawWriter};
use ltm_relight::{
    open, reference, relative_l2, PcaRelighter, Relight, Relighter, Request, Weighting,
};
use ltm_testkit::Rng;
use std::path::Path;

/// Non-negative transport with a shadow edge and a highlight, so that the
/// spectrum decays but is not exactly low rank.
fn matrix(d: Dims) -> Vec<f32> {
    let (w, p, m, c) = (
        d.width() as usize,
        d.pixels(),
        d.lights(),
        d.channels as usize,
    );
    let mut rng = Rng(17);
    let mut t = vec![0.0f32; p * m * c];
    for px in 0..p {
        let (x, y) = ((px % w) as f64, (px / w) as f64);
        for j in 0..m {
            for ch in 0..c {
                let lit = if (j as f64) < (m as f64) * (0.3 + 0.02 * x) {
                    1.0
                } else {
                    0.1
                };
                let spec = if (j + 3 * px) % 97 == 0 { 5.0 } else { 0.0 };
                t[(px * m + j) * c + ch] = ((lit + spec)
                    * (1.0 + 0.1 * y + 0.05 * ch as f64)
                    * (0.9 + 0.2 * rng.uniform())
                    * 1e-3) as f32;
            }
        }
    }
    t
}

fn light(m: usize) -> Vec<[f32; 3]> {
    let mut rng = Rng(3);
    (0..m)
        .map(|j| {
            let sun = if j == m / 3 { 500.0 } else { 0.0 };
            [
                (rng.uniform() + sun) as f32,
                (2.0 * rng.uniform()) as f32,
                (0.5 + rng.uniform() + sun) as f32,
            ]
        })
        .collect()
}

fn setup(dir: &Path, d: Dims, rank: usize, albedo: bool) -> (RawStore, std::path::PathBuf) {
    let t = matrix(d);
    let a: Vec<f32> = (0..3 * d.pixels())
        .map(|i| 0.3 + (i % 5) as f32 * 0.1)
        .collect();
    let header = RawHeader::new(d, albedo, (7 * d.row_len() * 4) as u64);
    let raw_path =
        RawWriter::write_dense(&dir.join("t.raw"), header, &t, albedo.then_some(&a[..])).unwrap();
    let raw = RawStore::open(&raw_path).unwrap();
    let out = dir.join("t.ltm");
    let opts = PcaOptions {
        rank: Some(rank),
        bits: 16,
        raise_bits: false,
        ..Default::default()
    };
    compress_pca(&raw, &out, &opts, ltm_codec::Progress::NONE).unwrap();
    (raw, out)
}

#[test]
fn relit_images_match_the_decoded_matrix_and_the_scalar_loop() {
    let dir = tempfile::tempdir().unwrap();
    for (d, albedo, rank) in [
        (Dims::image(19, 13, 2, 3), false, 21), // k not a multiple of the lanes
        (Dims::image(16, 16, 4, 1), true, 40),
    ] {
        let (raw, out) = setup(dir.path(), d, rank, albedo);
        let file = LtmFile::open(&out).unwrap();
        let relighter = PcaRelighter::new(&file, &Limits::default()).unwrap();
        let l = light(d.lights());
        let dense = decode_matrix(&file, &Limits::default()).unwrap();
        let mut frame = relighter.frame().unwrap();
        for k in [0, 1, 7, 8, 9, rank] {
            relighter
                .relight(
                    &l,
                    &Request {
                        terms: k,
                        weighting: Weighting::Unweighted,
                    },
                    &mut frame,
                )
                .unwrap();
            let scalar = relighter.relight_scalar(&l, k).unwrap();
            assert!(
                relative_l2(&frame.image, &scalar).unwrap() < 1e-5,
                "k = {k}"
            );
        }
        // With every term, the image is the decoded matrix times L.
        let (p, m, c) = (d.pixels(), d.lights(), d.channels as usize);
        let a = raw.albedo();
        let want: Vec<[f32; 3]> = (0..p)
            .map(|px| {
                let mut v = [0.0f64; 3];
                for (j, lj) in l.iter().enumerate() {
                    for (ch, vc) in v.iter_mut().enumerate() {
                        *vc += dense[(px * m + j) * c + ch.min(c - 1)] as f64 * lj[ch] as f64;
                    }
                }
                if let Some(a) = a {
                    for (ch, vc) in v.iter_mut().enumerate() {
                        *vc *= a[3 * px + ch] as f64;
                    }
                }
                v.map(|x| x as f32)
            })
            .collect();
        let scalar = relighter.relight_scalar(&l, rank).unwrap();
        let mut img = scalar.clone();
        img.data = want;
        assert!(relative_l2(&scalar, &img).unwrap() < 1e-6);
        // Against the exact T·L: close to the file's matrix error or better.
        let exact = reference(&raw, &l).unwrap();
        let e = relative_l2(&scalar, &exact).unwrap();
        assert!(
            e < 3.0 * file.meta().achieved_error as f64 + 1e-4,
            "relit {e} vs matrix {}",
            file.meta().achieved_error
        );
        // Errors shrink as terms grow (first 1, then the rank).
        let e1 = relative_l2(&relighter.relight_scalar(&l, 1).unwrap(), &exact).unwrap();
        assert!(e <= e1);
        // Too many terms, wrong lighting.
        let bad = relighter.relight(
            &l,
            &Request {
                terms: rank + 1,
                weighting: Weighting::Unweighted,
            },
            &mut frame,
        );
        assert!(bad
            .unwrap_err()
            .to_string()
            .contains(&format!("0..={rank}")));
        assert!(relighter
            .relight(
                &l[1..],
                &Request {
                    terms: 1,
                    weighting: Weighting::Unweighted
                },
                &mut frame
            )
            .is_err());
        let mut nan = l.clone();
        nan[2][1] = f32::NAN;
        assert!(relighter
            .relight(
                &nan,
                &Request {
                    terms: 1,
                    weighting: Weighting::Unweighted
                },
                &mut frame
            )
            .is_err());
    }
}

#[test]
fn open_picks_the_mode_and_relighters_refuse_the_other() {
    let dir = tempfile::tempdir().unwrap();
    let d = Dims::image(8, 8, 2, 3);
    let (_, out) = setup(dir.path(), d, 5, false);
    let r = open(&out, &Limits::default()).unwrap();
    assert_eq!(r.max_terms(), 5);
    let e = Relighter::open(&out).err().unwrap().to_string();
    assert!(e.contains("PcaRelighter"), "{e}");
}

/// A diffuse sphere (albedo ρ, no occlusion) seen as an 8×8 grid of points
/// on its upper half: `T[p][j] = ρ/π · max(0, n_p·ω_j) · Ω_j` with `ω_j`
/// the texel centre. A point light's exact image is `ρ/π · I · max(0,
/// n·ω)/d²`.
fn sphere(n: usize) -> (Dims, Vec<f32>, Vec<ltm_relight::SurfaceSample>) {
    use ltm_codec::cubemap::{texel_direction, texel_solid_angle};
    let d = Dims::image(8, 8, n as u32, 1);
    let rho = 0.8f64;
    let mut samples = Vec::new();
    let mut t = Vec::new();
    for p in 0..64 {
        let (u, v) = (
            (p % 8) as f64 / 7.0 * 2.4 - 1.2,
            (p / 8) as f64 / 7.0 * 2.4 - 1.2,
        );
        let theta = (u * u + v * v).sqrt().min(1.5);
        let phi = v.atan2(u);
        let nrm = [
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        ];
        samples.push(ltm_relight::SurfaceSample {
            position: nrm.map(|x| x as f32),
            normal: nrm.map(|x| x as f32),
            valid: p != 5,
        });
        for j in 0..d.lights() {
            let w = texel_direction(n, j);
            let cos = (nrm[0] * w.x as f64 + nrm[1] * w.y as f64 + nrm[2] * w.z as f64).max(0.0);
            t.push((rho / std::f64::consts::PI * cos * texel_solid_angle(n, j)) as f32);
        }
    }
    (d, t, samples)
}

#[test]
fn point_lights_on_an_analytic_sphere() {
    use ltm_relight::{Lookup, PointLight};
    let dir = tempfile::tempdir().unwrap();
    let n = 8;
    let (d, t, samples) = sphere(n);
    let header = RawHeader::new(d, false, (8 * d.row_len() * 4) as u64).with_surface();
    let surface = ltm_codec::Surface::new(
        samples
            .iter()
            .map(|s| match s.valid {
                true => ltm_codec::SurfacePoint::new(s.position, s.normal),
                false => ltm_codec::SurfacePoint::INVALID,
            })
            .collect(),
    )
    .unwrap();
    let raw = RawStore::open(
        &RawWriter::write_dense_with_surface(
            &dir.path().join("s.raw"),
            header,
            &t,
            None,
            Some(&surface),
        )
        .unwrap(),
    )
    .unwrap();
    let out = dir.path().join("s.ltm");
    let opts = PcaOptions {
        rank: Some(64),
        bits: 16,
        raise_bits: false,
        ..Default::default()
    };
    compress_pca(&raw, &out, &opts, ltm_codec::Progress::NONE).unwrap();
    let r = PcaRelighter::open_with_limits(&out, &Limits::default()).unwrap();
    let light = PointLight {
        position: [0.7, 6.0, -0.4],
        intensity: [10.0, 5.0, 1.0],
    };
    let exact = |p: usize, centre: bool| -> f64 {
        let s = samples[p];
        if !s.valid {
            return 0.0;
        }
        let x = glam::DVec3::from_array(light.position);
        let to = x - glam::DVec3::from_array(s.position.map(f64::from));
        let w = if centre {
            ltm_codec::cubemap::texel_direction(
                n,
                ltm_codec::cubemap::direction_texel(n, to.as_vec3()),
            )
            .as_dvec3()
        } else {
            to.normalize()
        };
        let nrm = glam::DVec3::from_array(s.normal.map(f64::from));
        0.8 / std::f64::consts::PI * nrm.dot(w).max(0.0) / to.length_squared()
    };
    // The file carries the store's surface data: its own samples give the
    // same image, and two lights give the sum of their images.
    assert_eq!(r.surface().map(<[_]>::len), Some(64));
    let near = r.relight_points(&[light], Lookup::Nearest, 64).unwrap();
    assert_eq!(
        near,
        r.relight_point(&samples, &light, Lookup::Nearest, 64)
            .unwrap()
    );
    let second = PointLight {
        position: [-3.0, 2.0, 1.0],
        intensity: [0.5, 1.0, 2.0],
    };
    let both = r
        .relight_points(&[light, second], Lookup::Nearest, 64)
        .unwrap();
    let alone = r.relight_points(&[second], Lookup::Nearest, 64).unwrap();
    for ((b, a), s) in both.data.iter().zip(&alone.data).zip(&near.data) {
        for c in 0..3 {
            assert!((b[c] - a[c] - s[c]).abs() <= 1e-6 * b[c].abs().max(1e-3));
        }
    }
    let bil = r
        .relight_point(&samples, &light, Lookup::Bilinear, 64)
        .unwrap();
    let top = (0..64).map(|p| exact(p, true) * 10.0).fold(0.0, f64::max);
    let (mut e_near, mut e_bil, mut norm) = (0.0, 0.0, 0.0);
    for (p, sample) in samples.iter().enumerate() {
        for (c, &i) in light.intensity.iter().enumerate() {
            let i = i as f64;
            // Nearest: the matrix's own value at the texel centre.
            let want = exact(p, true) * i;
            // Quantization (16 bits) leaves errors near 1e-5 of the largest values.
            assert!(
                (near.data[p][c] as f64 - want).abs() <= 1e-3 * want.abs() + 1e-4 * top,
                "pixel {p}: {} vs {want}",
                near.data[p][c]
            );
            let e = exact(p, false) * i;
            e_near += (near.data[p][c] as f64 - e).powi(2);
            e_bil += (bil.data[p][c] as f64 - e).powi(2);
            norm += e * e;
        }
        if !sample.valid {
            assert_eq!(near.data[p], [0.0; 3]);
        }
    }
    let (e_near, e_bil) = ((e_near / norm).sqrt(), (e_bil / norm).sqrt());
    println!("point light vs exact: nearest {e_near:.4}, bilinear {e_bil:.4}");
    // n = 8 texels span about 11°: nearest is off by up to half of that.
    assert!(
        e_bil < 0.5 * e_near && e_near < 0.2 && e_bil < 0.05,
        "nearest {e_near}, bilinear {e_bil}"
    );

    // Bad lights and samples.
    let bad = |l: PointLight| {
        r.relight_point(&samples, &l, Lookup::Nearest, 64)
            .unwrap_err()
            .to_string()
    };
    assert!(bad(PointLight {
        intensity: [f32::NAN, 1.0, 1.0],
        ..light
    })
    .contains("intensity"));
    assert!(bad(PointLight {
        intensity: [1.0, -1.0, 1.0],
        ..light
    })
    .contains("intensity"));
    let on = samples[9].position.map(f64::from);
    assert!(bad(PointLight {
        position: on,
        ..light
    })
    .contains("row 9"));
    assert!(bad(PointLight {
        position: [f64::NAN, 0.0, 0.0],
        ..light
    })
    .contains("not finite"));
    assert!(r
        .relight_point(&samples[1..], &light, Lookup::Nearest, 64)
        .is_err());
    // A light at an invalid row's point is not refused for that row (it
    // sees no surface), but it lies on the sphere, behind every other
    // row's tangent plane; so is a light inside the sphere.
    for position in [samples[5].position.map(f64::from), [0.0, 0.2, 0.1]] {
        let e = bad(PointLight { position, ..light });
        assert!(
            e.contains("behind the surface of every row") && !e.contains("row 5"),
            "{e}"
        );
    }
    // Beside the sphere, in front of some rows: accepted.
    assert!(r
        .relight_point(
            &samples,
            &PointLight {
                position: [3.0, 0.1, 0.0],
                ..light
            },
            Lookup::Nearest,
            64
        )
        .is_ok());
    let e = r
        .relight_points(
            &[
                light,
                PointLight {
                    intensity: [-1.0; 3],
                    ..light
                },
            ],
            Lookup::Nearest,
            64,
        )
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("point light 2") && e.contains("intensity"),
        "{e}"
    );
    // A file without surface data refuses point lights.
    let (_, plain) = setup(dir.path(), Dims::image(6, 5, 2, 1), 5, false);
    let e = PcaRelighter::open_with_limits(&plain, &Limits::default())
        .unwrap()
        .relight_points(&[light], Lookup::Nearest, 5)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no per-row surface data"), "{e}");
}

/// Rows the raw store flags all zero (background pixels) are stored in the
/// pca file's empty-row mask (chunk EMPT) and decode and relight to exactly
/// 0, where `μ + F·B` alone would leave small values.
#[test]
fn empty_rows_decode_and_relight_to_zero() {
    let dir = tempfile::tempdir().unwrap();
    let d = Dims::image(6, 5, 2, 3);
    let mut t = matrix(d);
    let empty = [0usize, 7, 29];
    for &p in &empty {
        t[p * d.row_len()..(p + 1) * d.row_len()].fill(0.0);
    }
    let header = RawHeader::new(d, false, (7 * d.row_len() * 4) as u64);
    let raw = RawStore::open(
        &RawWriter::write_dense(&dir.path().join("e.raw"), header, &t, None).unwrap(),
    )
    .unwrap();
    let out = dir.path().join("e.ltm");
    let opts = PcaOptions {
        rank: Some(3),
        bits: 12,
        raise_bits: false,
        ..Default::default()
    };
    compress_pca(&raw, &out, &opts, ltm_codec::Progress::NONE).unwrap();
    let file = LtmFile::open(&out).unwrap();
    let mask = file.empty_rows().expect("an EMPT chunk");
    assert_eq!(mask.count(), empty.len());
    let dense = decode_matrix(&file, &Limits::default()).unwrap();
    let r = PcaRelighter::new(&file, &Limits::default()).unwrap();
    let mut frame = r.frame().unwrap();
    let request = Request {
        terms: 3,
        weighting: Weighting::Unweighted,
    };
    r.relight(&light(d.lights()), &request, &mut frame).unwrap();
    for p in 0..d.pixels() {
        let row = &dense[p * d.row_len()..(p + 1) * d.row_len()];
        if empty.contains(&p) {
            assert!(row.iter().all(|&v| v == 0.0), "row {p}");
            assert_eq!(frame.image.data[p], [0.0; 3], "pixel {p}");
        } else {
            assert!(row.iter().any(|&v| v != 0.0), "row {p}");
            assert_ne!(frame.image.data[p], [0.0; 3], "pixel {p}");
        }
    }
}
