//! Environment maps: loading, rotation, and the exact resampling to the
//! cubemap (constant maps stay constant, power is conserved, lights land in
//! the right texel).

use glam::{DVec3, Vec3};
use ltm_codec::cubemap::{
    direction_texel, face_point_direction, latlong_uv, texel_count, texel_solid_angle,
};
#[cfg(feature = "exr")]
use ltm_relight::Image;
use ltm_relight::{EnvMap, RelightError, Rotation};
#[cfg(feature = "exr")]
use std::path::{Path, PathBuf};

#[cfg(feature = "exr")]
fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/envmaps")
        .join(name)
}

fn rotations() -> Vec<Rotation> {
    vec![
        Rotation::IDENTITY,
        Rotation::yaw(30.0),
        Rotation::yaw(90.0),
        Rotation::new(0.0, 10.0, 0.0), // the zenith on the interior of a texel edge
        Rotation::new(0.0, 90.0, 0.0), // a face centre (texel corner) at the zenith
        Rotation::new(45.0, 35.264_389_682_754_654, 0.0), // a cube corner near the zenith
        Rotation::new(17.0, 33.0, 51.0),
        Rotation::new(-120.5, 200.25, -7.0),
    ]
}

/// Σ_j L[j]·Ω_j per channel.
fn cubemap_power(cube: &[[f32; 3]], n: usize) -> [f64; 3] {
    let mut p = [0.0f64; 3];
    for (j, l) in cube.iter().enumerate() {
        let omega = texel_solid_angle(n, j);
        for c in 0..3 {
            p[c] += l[c] as f64 * omega;
        }
    }
    p
}

fn assert_power(env: &EnvMap, cube: &[[f32; 3]], n: usize, what: &str) {
    let want = env.power();
    let got = cubemap_power(cube, n);
    for c in 0..3 {
        let rel = (got[c] - want[c]).abs() / want[c].abs().max(1e-30);
        assert!(
            rel < 1e-5,
            "{what}: channel {c}: cubemap power {} vs map {} (relative error {rel:e})",
            got[c],
            want[c]
        );
    }
}

/// A direction's texel, in f64 (no f32 rounding at texel edges).
fn texel_of(n: usize, d: DVec3) -> usize {
    direction_texel(n, d.as_vec3())
}

#[test]
fn constant_map_gives_the_constant_in_every_texel() {
    let value = [0.25f32, 1.0, 3.5];
    for (w, h) in [(64, 32), (256, 128), (1024, 512)] {
        let env = EnvMap::constant(w, h, value).unwrap();
        for n in [1usize, 2, 8, 32] {
            for rot in rotations() {
                let cube = env.to_cubemap(n, &rot);
                assert_eq!(cube.len(), texel_count(n));
                let mut worst = 0.0f64;
                for (j, l) in cube.iter().enumerate() {
                    for c in 0..3 {
                        let rel = (l[c] as f64 - value[c] as f64).abs() / value[c] as f64;
                        worst = worst.max(rel);
                        assert!(
                            rel < 1e-5,
                            "{w}×{h}, n = {n}, rotation {rot}: texel {j} channel {c} is {} (want {})",
                            l[c],
                            value[c]
                        );
                    }
                }
                assert!(worst < 1e-5, "{w}×{h} n={n} {rot}: {worst:e}");
            }
        }
    }
}

#[test]
fn constant_map_survives_random_and_near_degenerate_rotations() {
    // Poles just off texel edges and corners (the (φ, z) parametrization is
    // singular there) and random rotations.
    let mut seed = 12345u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 720.0 - 360.0
    };
    let mut rots: Vec<Rotation> = (0..40)
        .map(|_| Rotation::new(rnd(), rnd(), rnd()))
        .collect();
    for e in [1e-3, 3e-5, 1e-6, 1e-8, 3e-9, 1e-10, 1e-12, 1e-15, -1e-7] {
        rots.extend([
            Rotation::new(0.0, e, 0.0),
            Rotation::new(45.0, e, 0.0),
            Rotation::new(0.0, 90.0 + e, 0.0),
            Rotation::new(0.0, 45.0, e),
            Rotation::new(45.0 + e, 35.264_389_682_754_654, 0.0),
            Rotation::new(e, 90.0, 45.0),
            Rotation::new(0.0, 7.125 + e, 0.0),
        ]);
    }
    let env = EnvMap::constant(64, 32, [1.0; 3]).unwrap();
    for n in [1usize, 2, 16] {
        for rot in &rots {
            for (j, l) in env.to_cubemap(n, rot).iter().enumerate() {
                assert!(
                    (l[0] - 1.0).abs() < 1e-5,
                    "n = {n}, rotation {rot}: texel {j} = {}",
                    l[0]
                );
            }
        }
    }
}

#[test]
fn resampling_matches_supersampled_texel_means() {
    // A map with a different value in every pixel, integrated over each
    // texel by brute force: k² sub-rectangles per texel with exact solid
    // angles, each looking up the map pixel under a jittered point (a
    // regular point would alias with meridians, which are lines of constant
    // s on the side faces).
    let (w, h) = (32, 16);
    let env = EnvMap::from_fn(w, h, |x, y| {
        let v = 1.0 + ((x * 7 + y * 13) % 11) as f32 + 0.1 * x as f32;
        [v, 2.0 * v, 1.0 + (y as f32)]
    })
    .unwrap();
    let n = 2;
    let k = 256;
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut jitter = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for rot in [Rotation::IDENTITY, Rotation::new(17.0, 33.0, 51.0)] {
        let cube = env.to_cubemap(n, &rot);
        let inv = rot.matrix().transpose();
        let mut worst = 0.0f64;
        for (j, got) in cube.iter().enumerate() {
            let (face, row, col) = ltm_codec::cubemap::texel_coords(n, j);
            let mut sum = [0.0f64; 3];
            let mut area = 0.0;
            let ds = 1.0 / (k * n) as f64;
            for a in 0..k {
                for b in 0..k {
                    let s0 = (col * k + a) as f64 * ds;
                    let t0 = (row * k + b) as f64 * ds;
                    let omega = ltm_codec::cubemap::face_rect_solid_angle(s0, s0 + ds, t0, t0 + ds);
                    let d =
                        inv * face_point_direction(face, s0 + jitter() * ds, t0 + jitter() * ds);
                    let (u, v) = latlong_uv(d);
                    let x = ((u * w as f64) as usize).min(w - 1);
                    let y = ((v * h as f64) as usize).min(h - 1);
                    let l = env.pixel(x, y).unwrap();
                    for c in 0..3 {
                        sum[c] += omega * l[c] as f64;
                    }
                    area += omega;
                }
            }
            for c in 0..3 {
                let want = sum[c] / area;
                let rel = (got[c] as f64 - want).abs() / want;
                worst = worst.max(rel);
                assert!(
                    rel < 2e-3,
                    "rotation {rot}: texel {j} channel {c}: {} vs supersampled {want} ({rel:e})",
                    got[c]
                );
            }
        }
        println!("rotation {rot}: worst relative difference {worst:e}");
    }
}

#[test]
#[cfg(feature = "exr")]
fn power_is_conserved_for_the_bundled_maps() {
    for name in ["courtyard.exr", "sunset.exr", "interior.exr"] {
        let env = EnvMap::load(&asset(name)).unwrap();
        assert_eq!((env.width(), env.height()), (1024, 512));
        assert!(env
            .data()
            .iter()
            .flatten()
            .all(|v| *v >= 0.0 && v.is_finite()));
        for n in [8usize, 32] {
            for rot in [Rotation::IDENTITY, Rotation::new(30.0, 20.0, 10.0)] {
                let cube = env.to_cubemap(n, &rot);
                assert_power(&env, &cube, n, &format!("{name}, n = {n}, rotation {rot}"));
            }
        }
    }
}

#[test]
#[cfg(feature = "exr")]
fn bundled_map_loads_with_negatives_clamped() {
    // courtyard.exr stores small negative samples (lossy DWAB compression).
    let raw = Image::read_exr(&asset("courtyard.exr")).unwrap();
    assert!(raw.data.iter().flatten().any(|v| *v < 0.0));
    let env = EnvMap::load(&asset("courtyard.exr")).unwrap();
    for (a, b) in raw.data.iter().zip(env.data()) {
        for c in 0..3 {
            assert_eq!(b[c], a[c].max(0.0));
        }
    }
}

/// A map that is black except pixel `(x, y)`.
fn sun(w: usize, h: usize, x: usize, y: usize, rgb: [f32; 3]) -> EnvMap {
    EnvMap::from_fn(w, h, |i, k| if (i, k) == (x, y) { rgb } else { [0.0; 3] }).unwrap()
}

#[test]
fn one_pixel_sun_keeps_its_energy_in_its_texel() {
    let (w, h) = (512, 256);
    let n = 4;
    let rgb = [5000.0f32, 2500.0, 100.0];
    // Pixels at texel centres (well inside their texel) and anywhere else.
    let mut pixels = vec![(100, 40), (3, 0), (511, 255), (257, 128), (128, 128)];
    for j in [0, 9, 21, 40, 63, 70, 95] {
        let d = ltm_codec::cubemap::texel_direction(n, j).as_dvec3();
        let (u, v) = latlong_uv(d);
        pixels.push(((u * w as f64) as usize, (v * h as f64) as usize));
    }
    for (x, y) in pixels {
        let env = sun(w, h, x, y, rgb);
        let energy = env.pixel_solid_angle(y);
        for rot in [
            Rotation::IDENTITY,
            Rotation::yaw(90.0),
            Rotation::new(17.0, 33.0, 51.0),
        ] {
            let cube = env.to_cubemap(n, &rot);
            assert_power(
                &env,
                &cube,
                n,
                &format!("sun at ({x}, {y}), rotation {rot}"),
            );
            let d = rot.apply(env.pixel_direction(x, y));
            let j = texel_of(n, d);
            // The whole pixel lies in texel j when its corners do.
            let corners_inside =
                [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
                    .iter()
                    .all(|&(a, b)| {
                        let c = ltm_codec::cubemap::latlong_direction(
                            (x as f64 + a) / w as f64,
                            (y as f64 + b) / h as f64,
                        );
                        texel_of(n, rot.apply(c)) == j
                    });
            let best = (0..cube.len())
                .max_by(|&a, &b| cube[a][0].total_cmp(&cube[b][0]))
                .unwrap();
            assert_eq!(best, j, "sun at ({x}, {y}), rotation {rot}");
            if corners_inside && y > 0 && y < h - 1 {
                for (k, l) in cube.iter().enumerate() {
                    if k == j {
                        let want = rgb[0] as f64 * energy / texel_solid_angle(n, j);
                        let rel = (l[0] as f64 - want).abs() / want;
                        assert!(rel < 1e-5, "texel {j}: {} vs {want}", l[0]);
                    } else {
                        assert!(
                            l.iter().all(|v| v.abs() < 1e-9),
                            "sun at ({x}, {y}), rotation {rot}: texel {k} = {l:?}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn yaw_moves_a_light_from_z_to_x() {
    // The pixel looking down +Z (u = 0.5, v = 0.5) lands on face +Z, and
    // on face +X after a yaw of 90 degrees.
    let (w, h) = (256, 128);
    let n = 8;
    let env = sun(w, h, 128, 64, [1.0; 3]);
    let lit = |rot: Rotation| {
        let cube = env.to_cubemap(n, &rot);
        (0..cube.len())
            .max_by(|&a, &b| cube[a][0].total_cmp(&cube[b][0]))
            .unwrap()
    };
    assert_eq!(lit(Rotation::IDENTITY) / (n * n), 4, "face +Z");
    let j = lit(Rotation::yaw(90.0));
    assert_eq!(j / (n * n), 0, "face +X");
    let rot = Rotation::yaw(90.0);
    assert!((rot.apply(DVec3::Z) - DVec3::X).length() < 1e-15);
    assert!((Rotation::new(0.0, 90.0, 0.0).apply(DVec3::Y) - DVec3::Z).length() < 1e-15);
    assert!((Rotation::new(0.0, 0.0, 90.0).apply(DVec3::X) - DVec3::Y).length() < 1e-15);
}

#[test]
#[cfg(feature = "exr")]
fn full_turn_of_yaw_is_the_identity() {
    let env = EnvMap::load(&asset("sunset.exr")).unwrap();
    for n in [4usize, 16] {
        let a = env.to_cubemap(n, &Rotation::IDENTITY);
        let b = env.to_cubemap(n, &Rotation::yaw(360.0));
        let c = env.to_cubemap(n, &Rotation::new(-720.0, 360.0, 1080.0));
        assert_eq!(a, b);
        assert_eq!(a, c);
    }
    // Four quarter turns by matrices equal one full turn.
    let q = Rotation::yaw(90.0).matrix();
    let m = q * q * q * q;
    assert!((m - glam::DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .all(|v| v.abs() < 1e-15));
}

#[test]
fn lat_long_convention_matches_the_cubemap() {
    // A small bright patch around u = 0.25, v = 0.5 (direction +X) lights
    // face +X; u = 0.5 is +Z, u = 0 is −Z, the top row is +Y.
    let (w, h) = (128, 64);
    let n = 4;
    for (u, v, dir, face) in [
        (0.25, 0.5, Vec3::X, 0),
        (0.75, 0.5, Vec3::NEG_X, 1),
        (0.5, 0.5, Vec3::Z, 4),
        (0.0, 0.5, Vec3::NEG_Z, 5),
        (0.3, 0.0, Vec3::Y, 2),
        (0.3, 1.0, Vec3::NEG_Y, 3),
    ] {
        let env = EnvMap::from_fn(w, h, |x, y| {
            let du = ((x as f64 + 0.5) / w as f64 - u).abs();
            let du = du.min(1.0 - du);
            let dv = ((y as f64 + 0.5) / h as f64 - v).abs();
            if du < 0.02 && dv < 0.04 {
                [1.0; 3]
            } else {
                [0.0; 3]
            }
        })
        .unwrap();
        let cube = env.to_cubemap(n, &Rotation::IDENTITY);
        let lit: f64 = cube[face * n * n..(face + 1) * n * n]
            .iter()
            .enumerate()
            .map(|(i, l)| l[0] as f64 * texel_solid_angle(n, face * n * n + i))
            .sum();
        let total = cubemap_power(&cube, n)[0];
        assert!(
            lit > 0.999 * total,
            "patch at u = {u}, v = {v}: face {face} holds {lit} of {total}"
        );
        if v == 0.5 {
            let j = direction_texel(n, dir * 1.0 + Vec3::new(0.0, -1e-3, 0.0));
            let best = (0..cube.len())
                .max_by(|&a, &b| cube[a][0].total_cmp(&cube[b][0]))
                .unwrap();
            assert_eq!(j / (n * n), face);
            assert!(cube[j][0] > 0.0);
            assert_eq!(best / (n * n), face);
        }
    }
}

#[test]
fn rotation_parses_from_the_command_line_form() {
    assert_eq!(
        "90,-10.5, 3".parse::<Rotation>().unwrap(),
        Rotation::new(90.0, -10.5, 3.0)
    );
    assert_eq!("45".parse::<Rotation>().unwrap(), Rotation::yaw(45.0));
    for bad in ["", "a,b,c", "1,2,3,4", "nan,0,0", "inf", "1,,2"] {
        let e = bad.parse::<Rotation>().unwrap_err();
        assert!(!e.to_string().is_empty(), "{bad}");
    }
    let r = Rotation::new(1.5, -2.0, 370.0);
    assert_eq!(r.to_string().parse::<Rotation>().unwrap(), r);
}

fn expect_env_error(r: Result<EnvMap, RelightError>, needle: &str) {
    match r {
        Ok(_) => panic!("expected an error mentioning '{needle}'"),
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains(needle), "error '{msg}' lacks '{needle}'");
        }
    }
}

#[test]
fn bad_maps_are_errors() {
    let mut data = vec![[1.0f32; 3]; 8 * 4];
    data[2 * 8 + 5][1] = f32::NAN;
    expect_env_error(EnvMap::new(8, 4, data.clone()), "x = 5, y = 2");
    expect_env_error(EnvMap::new(8, 4, data), "NaN");
    let mut data = vec![[1.0f32; 3]; 8 * 4];
    data[3][2] = f32::INFINITY;
    expect_env_error(EnvMap::new(8, 4, data), "inf");
    expect_env_error(EnvMap::new(1, 1, vec![[1.0; 3]]), "1×1");
    expect_env_error(EnvMap::constant(1, 1, [1.0; 3]), "at least 2");
    expect_env_error(EnvMap::constant(12, 4, [1.0; 3]), "3.000:1");
    expect_env_error(EnvMap::constant(0, 0, [1.0; 3]), "0×0");
    expect_env_error(EnvMap::new(8, 4, vec![[1.0; 3]; 5]), "holds 5 pixels");
    // Negative values are clamped.
    let env = EnvMap::constant(8, 4, [-1.0, 0.5, -0.0]).unwrap();
    assert!(env.data().iter().all(|p| *p == [0.0, 0.5, 0.0]));
    assert!(env.to_cubemap(0, &Rotation::IDENTITY).is_empty());
}

/// Writes an RGB f32 EXR with any values (the product's writer refuses
/// non-finite ones).
#[cfg(all(feature = "exr", feature = "hdr"))]
fn write_raw_exr(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3] + Sync) {
    exr::prelude::write_rgb_file(path, w, h, |x, y| {
        let p = f(x, y);
        (p[0], p[1], p[2])
    })
    .unwrap();
}

#[test]
#[cfg(all(feature = "exr", feature = "hdr"))]
fn bad_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);

    expect_env_error(EnvMap::load(&p("missing.exr")), "missing.exr");
    assert!(matches!(
        EnvMap::load(&p("missing.exr")),
        Err(RelightError::Io { .. })
    ));
    expect_env_error(EnvMap::load(&p("missing.hdr")), "missing.hdr");

    for name in [
        "garbage.exr",
        "garbage.hdr",
        "empty.exr",
        "empty.hdr",
        "short.exr",
    ] {
        let bytes: Vec<u8> = match name {
            "empty.exr" | "empty.hdr" => Vec::new(),
            // A valid magic number and version, then nothing.
            "short.exr" => vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0],
            _ => (0..4096u32)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
                .collect(),
        };
        std::fs::write(p(name), bytes).unwrap();
        let e = EnvMap::load(&p(name)).unwrap_err();
        assert!(e.to_string().contains(name), "{e}");
    }
    std::fs::write(p("map.png"), b"not a map").unwrap();
    expect_env_error(EnvMap::load(&p("map.png")), "unsupported");

    write_raw_exr(&p("nan.exr"), 16, 8, |x, y| {
        if (x, y) == (3, 6) {
            [0.0, 0.0, f32::NAN]
        } else {
            [1.0; 3]
        }
    });
    expect_env_error(EnvMap::load(&p("nan.exr")), "x = 3, y = 6");
    write_raw_exr(&p("inf.exr"), 16, 8, |x, _| {
        [if x == 1 { f32::INFINITY } else { 1.0 }; 3]
    });
    expect_env_error(EnvMap::load(&p("inf.exr")), "inf");
    write_raw_exr(&p("tiny.exr"), 1, 1, |_, _| [1.0; 3]);
    expect_env_error(EnvMap::load(&p("tiny.exr")), "1×1");
    write_raw_exr(&p("wide.exr"), 48, 16, |_, _| [1.0; 3]);
    expect_env_error(EnvMap::load(&p("wide.exr")), "not 2:1");
    write_raw_exr(&p("good.exr"), 32, 16, |x, y| [x as f32, y as f32, -0.001]);
    let env = EnvMap::load(&p("good.exr")).unwrap();
    assert_eq!(env.pixel(5, 7), Some([5.0, 7.0, 0.0]));
}

#[test]
#[cfg(feature = "hdr")]
fn radiance_hdr_loads() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (64usize, 32usize);
    let value = |x: usize, y: usize| [1.0 + x as f32, 0.5 + y as f32 * 0.25, 100.0];
    let pixels: Vec<image::Rgb<f32>> = (0..w * h)
        .map(|i| image::Rgb(value(i % w, i / w)))
        .collect();
    let path = dir.path().join("map.hdr");
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    image::codecs::hdr::HdrEncoder::new(file)
        .encode(&pixels, w, h)
        .unwrap();
    let env = EnvMap::load(&path).unwrap();
    assert_eq!((env.width(), env.height()), (w, h));
    for y in 0..h {
        for x in 0..w {
            let (got, want) = (env.pixel(x, y).unwrap(), value(x, y));
            for c in 0..3 {
                // RGBE: 8 bits of mantissa shared under the largest channel.
                assert!((got[c] - want[c]).abs() <= 0.01 * want[2], "({x}, {y})");
            }
        }
    }
    // A wrong shape in an HDR file is refused before decoding.
    let path = dir.path().join("wide.hdr");
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    image::codecs::hdr::HdrEncoder::new(file)
        .encode(&vec![image::Rgb([1.0f32; 3]); 30 * 10], 30, 10)
        .unwrap();
    expect_env_error(EnvMap::load(&path), "30×10");
}
