//! Tests of the wavelet rotation (Wang et al. 2006).

use super::maps::*;
use super::matrix::{exact_rows, resampling, Bases, RotationMatrix};
use super::*;
use std::f64::consts::PI;
use std::sync::Arc;

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn f64(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn dir(&mut self) -> DVec3 {
        let z = 2.0 * self.f64() - 1.0;
        let phi = 2.0 * PI * self.f64();
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// Three procedural maps: a sky gradient with a sun, a checker of bands,
/// and a sum of lobes.
fn maps_for(n: usize) -> Vec<OctMap> {
    let sun = DVec3::new(0.3, 0.5, 0.8).normalize();
    let sky = move |d: DVec3| {
        let s = if d.dot(sun) > 0.98 { 50.0 } else { 0.0 };
        let base = (0.5 + 0.5 * d.z) as f32;
        [base + s, base * 0.8 + s, 0.3 + s]
    };
    let bands = |d: DVec3| {
        let k = ((d.x * 5.0).floor() + (d.y * 3.0).floor() + (d.z * 4.0).floor()) as i64;
        let v = if k.rem_euclid(2) == 0 { 1.0 } else { 0.1 };
        [v, 0.5 * v, 0.2]
    };
    let lobes = |d: DVec3| {
        let a = d.dot(DVec3::new(1.0, 0.0, 0.0)).max(0.0).powi(20) as f32;
        let b = d.dot(DVec3::new(0.0, -0.6, -0.8)).max(0.0).powi(5) as f32;
        [3.0 * a + b, a + 2.0 * b, 0.1 + b]
    };
    vec![
        OctMap::from_fn(n, 2, sky).unwrap(),
        OctMap::from_fn(n, 2, bands).unwrap(),
        OctMap::from_fn(n, 2, lobes).unwrap(),
    ]
}

fn flatten(v: &[[f32; 3]]) -> Vec<f64> {
    v.iter().flatten().map(|&x| f64::from(x)).collect()
}

fn rel_rms(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let (a, b) = (flatten(a), flatten(b));
    let num: f64 = a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den).sqrt()
}

fn haar_rgb(texels: &[[f32; 3]], m: usize) -> Vec<[f32; 3]> {
    let map = OctMap::new(m, texels.to_vec()).unwrap();
    map.haar(None).unwrap()
}

#[test]
fn octahedral_maps_round_trip() {
    let mut rng = Rng(7);
    for _ in 0..2000 {
        let d = rng.dir();
        let (u, v) = oct_encode(d);
        assert!(oct_decode(u, v).0.distance(d) < 1e-12, "{d}");
        let h = DVec3::new(d.x, d.y, d.z.abs());
        let (u, v) = hemi_encode(h);
        assert!(hemi_decode(u, v).0.distance(h) < 1e-12, "{h}");
    }
}

#[test]
fn solid_angles_cover_the_sphere_and_hemisphere() {
    let oct: f64 = solid_angles(32, 8, |u, v| oct_decode(u, v).1).iter().sum();
    let hemi: f64 = solid_angles(16, 8, |u, v| hemi_decode(u, v).1).iter().sum();
    assert!(
        (oct - 4.0 * PI).abs() < 1e-3 * 4.0 * PI,
        "octahedral map covers {oct}"
    );
    assert!(
        (hemi - 2.0 * PI).abs() < 1e-3 * 2.0 * PI,
        "hemi-octahedral map covers {hemi}"
    );
}

#[test]
fn frames_are_orthonormal_and_right_handed() {
    let mut rng = Rng(11);
    for _ in 0..1000 {
        let n = rng.dir();
        let f = Frame::new(n);
        assert!((f.s.length() - 1.0).abs() < 1e-12 && (f.t.length() - 1.0).abs() < 1e-12);
        assert!(f.s.dot(f.t).abs() < 1e-12 && f.s.dot(n).abs() < 1e-12);
        assert!(f.s.cross(f.t).distance(n) < 1e-12);
        let d = rng.dir();
        assert!(f.to_local(f.to_global(d)).distance(d) < 1e-12);
    }
}

#[test]
fn bilinear_weights_sum_to_one_and_hit_grid_normals() {
    let mut rng = Rng(5);
    for _ in 0..1000 {
        let w: f64 = oct_bilinear(8, rng.dir()).iter().map(|p| p.1).sum();
        assert!((w - 1.0).abs() < 1e-12);
    }
    let cfg = RotationConfig {
        normals: 8,
        ..RotationConfig::default()
    };
    for i in 0..64 {
        let taps = oct_bilinear(8, cfg.grid_normal(i));
        let at: f64 = taps.iter().filter(|p| p.0 == i).map(|p| p.1).sum();
        assert!(at > 1.0 - 1e-9, "grid normal {i} weighs {at} on itself");
    }
}

#[test]
fn haar_impulses_match_the_codec_transform() {
    let n = 8;
    for t in 0..n * n {
        let mut img = vec![0.0f32; n * n];
        img[t] = 1.0;
        haar::forward(&mut img, n).unwrap();
        let mut sparse = vec![0.0f64; n * n];
        for (i, v) in haar::delta(n, t) {
            sparse[i as usize] += v;
        }
        for i in 0..n * n {
            assert!(
                (f64::from(img[i]) - sparse[i]).abs() < 1e-6,
                "texel {t} coefficient {i}"
            );
        }
    }
}

#[test]
fn haar_is_orthonormal_and_inverts() {
    let n = 32;
    let mut rng = Rng(3);
    let img: Vec<f32> = (0..n * n).map(|_| rng.f64() as f32 - 0.5).collect();
    let mut c = img.clone();
    haar::forward(&mut c, n).unwrap();
    let e0: f64 = img.iter().map(|&x| f64::from(x).powi(2)).sum();
    let e1: f64 = c.iter().map(|&x| f64::from(x).powi(2)).sum();
    assert!((e0 - e1).abs() < 1e-5 * e0, "energy {e0} became {e1}");
    haar::inverse(&mut c, n).unwrap();
    assert!(img.iter().zip(&c).all(|(a, b)| (a - b).abs() < 1e-5));
}

/// The bound of `|(R_q − R)·L|` per row: half a step per entry of the exact
/// row (every dropped or rounded entry moves by at most half a step with
/// threshold 1), plus f32 accumulation.
fn row_bounds(rows: &[Vec<(u32, f64)>], scale: f64, light: &[[f32; 3]]) -> Vec<f64> {
    rows.iter()
        .map(|row| {
            let l1: f64 = row
                .iter()
                .map(|&(j, _)| {
                    light[j as usize]
                        .iter()
                        .map(|v| f64::from(v.abs()))
                        .fold(0.0, f64::max)
                })
                .sum();
            0.5 * scale * l1 + 1e-5 * (1.0 + l1)
        })
        .collect()
}

#[test]
fn rotation_equals_the_haar_of_the_spatially_rotated_map() {
    let cfg = RotationConfig {
        n: 16,
        normals: 4,
        supersample: 3,
        threshold: 1,
    };
    let bases = Bases::new(cfg.n);
    let mut rng = Rng(19);
    for map in maps_for(cfg.n) {
        for _ in 0..4 {
            let normal = rng.dir();
            let rows = exact_rows(&cfg, &bases, normal);
            let mat = RotationMatrix::quantize(&rows, 1, false);
            let light = map.haar(None).unwrap();
            let mut out = vec![[0.0f32; 3]; cfg.m() * cfg.m()];
            mat.apply(&light, &mut out);
            let reference = haar_rgb(&resample_local(&map, normal, cfg.supersample), cfg.m());
            let bounds = row_bounds(&rows, f64::from(mat.scale()), &light);
            for (r, (o, e)) in out.iter().zip(&reference).enumerate() {
                for c in 0..3 {
                    let err = f64::from((o[c] - e[c]).abs());
                    assert!(
                        err <= bounds[r],
                        "normal {normal} row {r}: {err} > {}",
                        bounds[r]
                    );
                }
            }
            assert!(rel_rms(&out, &reference) < 1e-3);
        }
    }
}

/// `H` of a side-`n` map as a dense matrix (column `t` = transform of an
/// impulse at `t`), from the codec's dense transform.
fn dense_haar(n: usize) -> Vec<Vec<f64>> {
    let mut h = vec![vec![0.0; n * n]; n * n];
    for t in 0..n * n {
        let mut img = vec![0.0f32; n * n];
        img[t] = 1.0;
        haar::forward(&mut img, n).unwrap();
        for (r, &v) in img.iter().enumerate() {
            h[r][t] = f64::from(v);
        }
    }
    h
}

#[test]
fn quantized_sparse_product_matches_a_dense_f64_reference() {
    let cfg = RotationConfig {
        n: 16,
        normals: 4,
        supersample: 2,
        threshold: 4,
    };
    let (n2, m2) = (cfg.n * cfg.n, cfg.m() * cfg.m());
    let (hn, hm) = (dense_haar(cfg.n), dense_haar(cfg.m()));
    let normal = DVec3::new(0.4, -0.7, 0.2).normalize();
    // Dense W·Hₙᵀ, then Hₘ·(W·Hₙᵀ).
    let w = resampling(&cfg, normal);
    let mut wh = vec![vec![0.0; n2]; m2];
    for (t, taps) in w.iter().enumerate() {
        for &(k, wk) in taps {
            for j in 0..n2 {
                wh[t][j] += wk * hn[j][k as usize];
            }
        }
    }
    let mut dense = vec![vec![0.0; n2]; m2];
    for r in 0..m2 {
        for t in 0..m2 {
            if hm[r][t] != 0.0 {
                for j in 0..n2 {
                    dense[r][j] += hm[r][t] * wh[t][j];
                }
            }
        }
    }
    let mat = RotationMatrix::build(&cfg, normal).unwrap();
    let step = f64::from(mat.scale());
    let mut stored = vec![vec![None; n2]; m2];
    for (r, row) in stored.iter_mut().enumerate() {
        for (j, q) in mat.row(r) {
            row[j] = Some(f64::from(q) * step);
        }
    }
    for r in 0..m2 {
        for j in 0..n2 {
            let bound = match stored[r][j] {
                Some(_) => 0.5 * step,
                None => (f64::from(cfg.threshold) - 0.5) * step,
            };
            let err = (stored[r][j].unwrap_or(0.0) - dense[r][j]).abs();
            assert!(err <= bound + 1e-7, "entry ({r}, {j}): {err} > {bound}");
        }
    }
    // The product, in both index widths, against the dense one.
    let light = maps_for(cfg.n)[2].haar(None).unwrap();
    let rows = exact_rows(&cfg, &Bases::new(cfg.n), normal);
    let wide = RotationMatrix::quantize(&rows, cfg.threshold, true);
    let (mut a, mut b) = (vec![[0.0f32; 3]; m2], vec![[0.0f32; 3]; m2]);
    mat.apply(&light, &mut a);
    wide.apply(&light, &mut b);
    assert_eq!(a, b);
    for r in 0..m2 {
        let l1: f64 = (0..n2).map(|j| f64::from(light[j][0].abs())).sum();
        let exact: f64 = (0..n2).map(|j| dense[r][j] * f64::from(light[j][0])).sum();
        let bound = (f64::from(cfg.threshold) - 0.5) * step * l1 + 1e-4;
        assert!((f64::from(a[r][0]) - exact).abs() <= bound, "row {r}");
    }
}

#[test]
fn sizes_and_parameters_are_validated() {
    let limits = Limits::default();
    for bad in [
        RotationConfig {
            n: 48,
            ..RotationConfig::default()
        },
        RotationConfig {
            n: 512,
            ..RotationConfig::default()
        },
        RotationConfig {
            normals: 0,
            ..RotationConfig::default()
        },
        RotationConfig {
            supersample: 17,
            ..RotationConfig::default()
        },
        RotationConfig {
            threshold: 40000,
            ..RotationConfig::default()
        },
    ] {
        let err = RotationSet::build(bad, &limits).unwrap_err().to_string();
        assert!(err.contains("valid"), "{err}");
    }
    assert!(OctMap::new(12, vec![[0.0; 3]; 144]).is_err());
    assert!(OctMap::new(8, vec![[0.0; 3]; 63]).is_err());
    assert!(OctMap::new(4, vec![[f32::NAN; 3]; 16]).is_err());
    assert!(Brdf::Ggx {
        alpha: 0.0,
        f0: [1.0; 3]
    }
    .validate()
    .is_err());
    assert!(Brdf::Lambert {
        albedo: [1.5, 0.0, 0.0]
    }
    .validate()
    .is_err());
    assert!(SliceConfig {
        keep: 0.0,
        ..SliceConfig::default()
    }
    .validate()
    .is_err());
    // A budget too small for the set is an error, not an abort.
    let small = Limits::with_max_alloc(1000);
    let cfg = RotationConfig {
        n: 16,
        normals: 4,
        ..RotationConfig::default()
    };
    assert!(RotationSet::build(cfg, &small).is_err());
}

fn shader(cfg: RotationConfig, brdf: Brdf, slices: SliceConfig) -> Shader {
    let limits = Limits::default();
    let set = Arc::new(RotationSet::build(cfg, &limits).unwrap());
    let slices = Arc::new(BrdfSlices::build(brdf, slices, &limits).unwrap());
    Shader::new(set, slices, &limits).unwrap()
}

#[test]
fn lambert_under_a_constant_map_reflects_its_albedo() {
    // B = ∫ (ρ/π)·1·cos θ dω = ρ.
    let cfg = RotationConfig {
        n: 16,
        normals: 4,
        supersample: 2,
        threshold: 1,
    };
    let albedo = [0.8, 0.5, 0.2];
    let slices = SliceConfig {
        m: 8,
        views: 8,
        supersample: 8,
        keep: 0.05,
        residuals: true,
    };
    let mut sh = shader(cfg, Brdf::Lambert { albedo }, slices);
    let wrong = OctMap::from_fn(32, 1, |_| [1.0; 3]).unwrap();
    let err = sh.light(&wrong, None).unwrap_err().to_string();
    assert!(err.contains("lighting map side = 32"), "{err}");
    let other = SliceConfig { m: 16, ..slices };
    let glossy = BrdfSlices::build(
        Brdf::Ggx {
            alpha: 0.2,
            f0: [1.0; 3],
        },
        other,
        &Limits::default(),
    );
    assert!(sh.set_brdf(Arc::new(glossy.unwrap())).is_err());
    sh.light(&OctMap::from_fn(16, 1, |_| [1.0; 3]).unwrap(), None)
        .unwrap();
    let mut rng = Rng(23);
    for _ in 0..200 {
        let normal = rng.dir();
        let mut view = rng.dir();
        if view.dot(normal) < 0.0 {
            view = -view;
        }
        let b = sh.shade(normal, view);
        for c in 0..3 {
            assert!((b[c] - albedo[c]).abs() < 2e-3, "{b:?} against {albedo:?}");
        }
    }
}

/// `∫ f_r(ω, ω_o) cos θ dω` by the midpoint rule in (θ, φ).
fn albedo_brute_force(brdf: &Brdf, wo: DVec3) -> [f64; 3] {
    let (nt, np) = (1024, 2048);
    let mut acc = [0.0; 3];
    for i in 0..nt {
        let theta = (i as f64 + 0.5) * 0.5 * PI / nt as f64;
        let w = theta.sin() * theta.cos() * (0.5 * PI / nt as f64) * (2.0 * PI / np as f64);
        for k in 0..np {
            let phi = (k as f64 + 0.5) * 2.0 * PI / np as f64;
            let wi = DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            let f = brdf.eval(wi, wo);
            (0..3).for_each(|c| acc[c] += f[c] * w);
        }
    }
    acc
}

#[test]
fn glossy_brdfs_under_a_white_map_reflect_their_directional_albedo() {
    let cfg = RotationConfig {
        n: 32,
        normals: 4,
        supersample: 2,
        threshold: 1,
    };
    let slices = SliceConfig {
        m: 16,
        views: 16,
        supersample: 8,
        keep: 0.05,
        residuals: true,
    };
    let brdfs = [
        Brdf::Ggx {
            alpha: 0.3,
            f0: [0.95, 0.6, 0.3],
        },
        Brdf::Ggx {
            alpha: 0.1,
            f0: [0.95, 0.6, 0.3],
        },
        Brdf::Phong {
            exponent: 30.0,
            specular: [0.9, 0.5, 0.2],
        },
        Brdf::Plastic {
            albedo: [0.7, 0.2, 0.1],
            alpha: 0.2,
            ior: 1.5,
        },
    ];
    for brdf in brdfs {
        let mut sh = shader(cfg, brdf.clone(), slices);
        sh.light(&OctMap::from_fn(32, 1, |_| [1.0; 3]).unwrap(), None)
            .unwrap();
        let frame = Frame::new(cfg.grid_normal(5));
        for view in [3usize, 40, 77, 120, 136] {
            let (u, v) = texel_center(16, view);
            let wo = hemi_decode(u, v).0;
            let b = sh.shade(cfg.grid_normal(5), frame.to_global(wo));
            let e = albedo_brute_force(&brdf, wo);
            for c in 0..3 {
                let rel = (f64::from(b[c]) - e[c]).abs() / e[c];
                assert!(rel < 0.01, "{brdf:?}, view {wo}: {b:?} against {e:?}");
                assert!(e[c] < 1.0 + 1e-3, "{brdf:?} reflects {e:?} at {wo}");
            }
        }
    }
}

#[test]
fn a_small_bright_source_highlights_the_mirror_direction() {
    let cfg = RotationConfig {
        n: 64,
        normals: 4,
        supersample: 2,
        threshold: 1,
    };
    let slices = SliceConfig {
        m: 32,
        views: 32,
        supersample: 2,
        keep: 0.03,
        residuals: true,
    };
    let brdf = Brdf::Ggx {
        alpha: 0.1,
        f0: [1.0; 3],
    };
    let mut sh = shader(cfg, brdf, slices);
    let normal = cfg.grid_normal(6);
    let frame = Frame::new(normal);
    let light_local = DVec3::new(0.55, -0.3, 0.78).normalize();
    let light = frame.to_global(light_local);
    let map = OctMap::from_fn(64, 4, |d| {
        if d.dot(light) > 0.997 {
            [100.0; 3]
        } else {
            [0.0; 3]
        }
    });
    sh.light(&map.unwrap(), Some(256)).unwrap();
    let mirror = 2.0 * normal.dot(light) * normal - light;
    let (mut best, mut best_dir) = (0.0f32, DVec3::ZERO);
    for v in 0..64 * 64 {
        let (u, w) = texel_center(64, v);
        let view = frame.to_global(hemi_decode(u, w).0);
        let b = sh.shade(normal, view)[0];
        if b > best {
            (best, best_dir) = (b, view);
        }
    }
    let angle = best_dir.dot(mirror).clamp(-1.0, 1.0).acos().to_degrees();
    assert!(
        angle < 6.0,
        "brightest view is {angle}° from the mirror direction"
    );
    let away = frame.to_global(DVec3::new(0.5, 0.3, 0.81).normalize());
    println!("highlight {angle:.2}° from the mirror direction");
    assert!(sh.shade(normal, away)[0] < 0.05 * best);
}

/// The plastic coat's Fresnel against Snell's law and the s and p
/// amplitudes written out separately.
#[test]
fn dielectric_fresnel_matches_snell_and_its_limits() {
    for eta in [1.01f64, 1.33, 1.5, 2.4, 3.0] {
        let normal = ((eta - 1.0) / (eta + 1.0)).powi(2);
        assert!((brdf::fresnel_dielectric(eta, 1.0) - normal).abs() < 1e-12);
        assert!((brdf::fresnel_dielectric(eta, 0.0) - 1.0).abs() < 1e-12);
        for k in 1..100 {
            let ci = k as f64 / 100.0;
            let ct = (1.0 - (1.0 - ci * ci) / (eta * eta)).sqrt();
            let rs = (ci - eta * ct) / (ci + eta * ct);
            let rp = (eta * ci - ct) / (eta * ci + ct);
            let f = brdf::fresnel_dielectric(eta, ci);
            assert!(
                (f - 0.5 * (rs * rs + rp * rp)).abs() < 1e-12,
                "eta {eta} cos {ci}: {f}"
            );
        }
    }
}

/// A sun 10⁴ times brighter than its sky: a slice keeping 3 % of its terms
/// is far off where the sun falls on a coefficient it dropped; with each
/// normal's largest local-lighting terms dotted with the slice's residual
/// the product drops only terms where both are small (25 % and 4.2 %
/// when measured).
#[test]
fn a_sun_is_shaded_through_the_lightings_own_largest_terms() {
    let cfg = RotationConfig {
        n: 32,
        normals: 8,
        supersample: 8,
        threshold: 1,
    };
    let slices = SliceConfig {
        m: 16,
        views: 32,
        supersample: 4,
        keep: 0.03,
        residuals: true,
    };
    let brdf = Brdf::Lambert { albedo: [0.8; 3] };
    let mut sh = shader(cfg, brdf.clone(), slices);
    let sun = DVec3::new(0.4, 0.7, 0.3).normalize();
    let map = OctMap::from_fn(32, 16, |d| {
        let s = if d.dot(sun) > 0.9995 { 1e4 } else { 0.0 };
        [0.3 + s, 0.4 + s, 0.5 + s]
    })
    .unwrap();
    let limits = Limits::default();
    let mut rng = Rng(3);
    let points: Vec<(DVec3, DVec3, [f64; 3])> = (0..40)
        .map(|_| {
            let n = (sun + 0.8 * rng.dir()).normalize();
            let v = (n + 0.5 * rng.dir()).normalize();
            (n, v, shade_brute_force(&map, &brdf, n, v))
        })
        .collect();
    let mut error = |keep: f64| {
        sh.set_local_keep(keep, &limits).unwrap();
        sh.light(&map, None).unwrap();
        let (mut num, mut den) = (0.0, 0.0);
        for (n, v, exact) in &points {
            let b = sh.shade(*n, *v);
            for c in 0..3 {
                num += (f64::from(b[c]) - exact[c]).powi(2);
                den += exact[c] * exact[c];
            }
        }
        (num / den).sqrt()
    };
    let (alone, with_local) = (error(0.0), error(0.1));
    println!("sun, Lambert, slices keep 3 %: {alone:.4} alone, {with_local:.4} with local terms");
    assert!(
        with_local < 0.06 && with_local < alone / 3.0,
        "{alone} {with_local}"
    );
    assert!(sh.set_local_keep(1.5, &limits).is_err());
}

/// Surface normals between grid normals: blending the four grid normals'
/// shading must not smear a glossy highlight. Each grid normal is shaded
/// from the view it mirrors into the surface's own mirror direction
/// (`Shader::shade`); blending the plain view instead put the lobe's peak
/// up to twice the grid's spacing off: 16.8 % here, against 5.4 %.
#[test]
fn off_grid_normals_keep_the_highlight_where_the_surface_mirrors() {
    let cfg = RotationConfig {
        n: 32,
        normals: 8,
        supersample: 4,
        threshold: 1,
    };
    let slices = SliceConfig {
        m: 16,
        views: 32,
        supersample: 4,
        keep: 1.0,
        residuals: true,
    };
    let brdf = Brdf::Ggx {
        alpha: 0.3,
        f0: [1.0; 3],
    };
    let mut sh = shader(cfg, brdf.clone(), slices);
    let map = maps_for(32).swap_remove(2);
    sh.light(&map, None).unwrap();
    let mut rng = Rng(11);
    let (mut num, mut den) = (0.0, 0.0);
    for _ in 0..60 {
        let n = rng.dir();
        let mut v = rng.dir();
        if v.dot(n) < 0.2 {
            v = (v - (v.dot(n) - 0.2 - rng.f64() * 0.7) * n).normalize();
        }
        let exact = shade_brute_force(&map, &brdf, n, v);
        let b = sh.shade(n, v);
        for c in 0..3 {
            num += (f64::from(b[c]) - exact[c]).powi(2);
            den += exact[c] * exact[c];
        }
    }
    let e = (num / den).sqrt();
    println!("off-grid normals, 8² grid, GGX alpha 0.3: relative L2 {e:.4}");
    assert!(e < 0.08, "relative L2 {e}");
}

/// Relative RMS of rotated lighting against the Haar of the spatially
/// rotated map, per number of lighting terms (Fig. 7 of the paper).
fn accuracy_table(n: usize, normals: usize) {
    let cfg = RotationConfig {
        n,
        normals: 1,
        supersample: 4,
        threshold: 1,
    };
    let bases = Bases::new(n);
    let mut rng = Rng(99);
    let dirs: Vec<DVec3> = (0..normals).map(|_| rng.dir()).collect();
    let mats: Vec<RotationMatrix> = dirs
        .iter()
        .map(|&d| RotationMatrix::quantize(&exact_rows(&cfg, &bases, d), 1, false))
        .collect();
    for (name, map) in ["sky+sun", "bands", "lobes"].iter().zip(maps_for(n)) {
        let mut line = format!("n={n} {name:8}");
        for terms in [Some(128), Some(256), Some(2048), None] {
            let light = map.haar(terms).unwrap();
            let mut err = 0.0;
            for (d, mat) in dirs.iter().zip(&mats) {
                let mut out = vec![[0.0f32; 3]; cfg.m() * cfg.m()];
                mat.apply(&light, &mut out);
                let reference = haar_rgb(&resample_local(&map, *d, 4), cfg.m());
                err += rel_rms(&out, &reference) / dirs.len() as f64;
            }
            let t = terms.map_or("all".to_string(), |t| t.to_string());
            line += &format!("  {t}: {err:.4}");
        }
        println!("{line}");
    }
}

#[test]
fn accuracy_against_lighting_terms_is_printed() {
    accuracy_table(32, 4);
}

/// Figures for the report: `cargo test -p ltm-relight --lib rotation::tests::figures
/// -- --ignored --nocapture`.
#[test]
#[ignore]
fn figures() {
    use std::time::Instant;
    let limits = Limits::default();
    for n in [32usize, 64] {
        let cfg = RotationConfig {
            n,
            ..RotationConfig::default()
        };
        let t0 = Instant::now();
        let set = Arc::new(RotationSet::build(cfg, &limits).unwrap());
        let build = t0.elapsed().as_secs_f64();
        let s = set.stats();
        println!(
            "n={n} normals=32² precompute {build:.1} s: {} nonzeros, {:.1} per row, density {:.2} %, {:.1} MB",
            s.nonzeros, s.per_row, 100.0 * s.density, s.bytes as f64 / 1e6
        );
        for threshold in [8u16, 32, 128] {
            let c = RotationConfig {
                normals: 8,
                threshold,
                ..cfg
            };
            let st = RotationSet::build(c, &limits).unwrap().stats();
            println!(
                "  threshold {threshold} (8² normals): {:.1} per row",
                st.per_row
            );
        }
        let sc = SliceConfig {
            m: n / 2,
            views: 64,
            supersample: 4,
            keep: 0.03,
            residuals: true,
        };
        let t0 = Instant::now();
        let slices = Arc::new(
            BrdfSlices::build(
                Brdf::Ggx {
                    alpha: 0.2,
                    f0: [0.9; 3],
                },
                sc,
                &limits,
            )
            .unwrap(),
        );
        println!(
            "  GGX slices (64² views, {} terms each): {:.1} s, {:.1} MB",
            sc.terms(),
            t0.elapsed().as_secs_f64(),
            slices.bytes() as f64 / 1e6
        );
        let mut sh = Shader::new(set, slices, &limits).unwrap();
        let map = &maps_for(n)[0];
        for terms in [Some(256), None] {
            let t0 = Instant::now();
            for _ in 0..5 {
                sh.light(map, terms).unwrap();
            }
            println!(
                "  step 1 (terms {terms:?}): {:.1} ms",
                t0.elapsed().as_secs_f64() * 200.0
            );
        }
        let mut rng = Rng(1);
        let points: Vec<(DVec3, DVec3)> = (0..256 * 256).map(|_| (rng.dir(), rng.dir())).collect();
        let t0 = Instant::now();
        let sum: f32 = points.par_iter().map(|&(a, b)| sh.shade(a, b)[0]).sum();
        println!(
            "  step 2, 256² points: {:.1} ms ({sum:.1})",
            t0.elapsed().as_secs_f64() * 1e3
        );
        accuracy_table(n, 8);
        if n == 64 {
            render_accuracy(&mut sh, &limits);
        }
    }
}

/// `∫ L(R·ω) f_r(ω, ω_o) cos θ dω` by the midpoint rule in (θ, φ) over the
/// local hemisphere, `L` the map's piecewise-constant texels.
fn shade_brute_force(map: &OctMap, brdf: &Brdf, normal: DVec3, view: DVec3) -> [f64; 3] {
    let frame = Frame::new(normal);
    let wo = frame.to_local(view);
    let (nt, np) = (256, 512);
    let mut acc = [0.0; 3];
    for i in 0..nt {
        let theta = (i as f64 + 0.5) * 0.5 * PI / nt as f64;
        let w = theta.sin() * theta.cos() * (0.5 * PI / nt as f64) * (2.0 * PI / np as f64);
        for k in 0..np {
            let phi = (k as f64 + 0.5) * 2.0 * PI / np as f64;
            let wi = DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            let f = brdf.eval(wi, wo);
            let l = map.lookup(frame.to_global(wi));
            (0..3).for_each(|c| acc[c] += f[c] * f64::from(l[c]) * w);
        }
    }
    acc
}

/// Relative L2 of shaded radiance against [`shade_brute_force`] over
/// random surface points, per GGX roughness and lighting terms (n = 64).
fn render_accuracy(sh: &mut Shader, limits: &Limits) {
    let mut rng = Rng(77);
    let points: Vec<(DVec3, DVec3)> = (0..200)
        .map(|_| {
            let n = rng.dir();
            let mut v = rng.dir();
            if v.dot(n) < 0.0 {
                v = -v;
            }
            (n, v)
        })
        .collect();
    let maps = maps_for(64);
    for alpha in [0.1f32, 0.2, 0.5] {
        let brdf = Brdf::Ggx {
            alpha,
            f0: [0.9, 0.7, 0.5],
        };
        let sc = SliceConfig {
            m: 32,
            views: 64,
            supersample: 4,
            keep: 0.03,
            residuals: true,
        };
        sh.set_brdf(Arc::new(
            BrdfSlices::build(brdf.clone(), sc, limits).unwrap(),
        ))
        .unwrap();
        for (name, map) in [("sky+sun", &maps[0]), ("lobes", &maps[2])] {
            let exact: Vec<[f64; 3]> = points
                .par_iter()
                .map(|&(n, v)| shade_brute_force(map, &brdf, n, v))
                .collect();
            let mut line = format!("GGX alpha {alpha} {name:8} rel. L2 of radiance:");
            for terms in [Some(256), Some(2048), None] {
                sh.light(map, terms).unwrap();
                let (mut num, mut den) = (0.0, 0.0);
                for (&(n, v), e) in points.iter().zip(&exact) {
                    let b = sh.shade(n, v);
                    for c in 0..3 {
                        num += (f64::from(b[c]) - e[c]).powi(2);
                        den += e[c] * e[c];
                    }
                }
                let t = terms.map_or("all".to_string(), |t| t.to_string());
                line += &format!("  {t}: {:.4}", (num / den).sqrt());
            }
            println!("{line}");
        }
    }
}

#[test]
fn the_cache_round_trips_and_refuses_bad_input() {
    let limits = Limits::default();
    let cfg = RotationConfig {
        n: 8,
        normals: 2,
        supersample: 2,
        threshold: 1,
    };
    let set = RotationSet::build(cfg, &limits).unwrap();
    let bytes = set.to_bytes();
    let back = RotationSet::from_bytes(&bytes, &limits).unwrap();
    assert_eq!(back.config(), set.config());
    assert_eq!(back.to_bytes(), bytes);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rot.ltmr");
    set.write(&path).unwrap();
    assert_eq!(RotationSet::read(&path, &limits).unwrap().to_bytes(), bytes);
    // Every truncation, and every flipped byte, is an error.
    for len in 0..bytes.len() {
        assert!(
            RotationSet::from_bytes(&bytes[..len], &limits).is_err(),
            "length {len}"
        );
    }
    for i in 0..bytes.len() {
        let mut b = bytes.clone();
        b[i] ^= 0x5a;
        assert!(RotationSet::from_bytes(&b, &limits).is_err(), "byte {i}");
    }
    // With the CRC repaired, any byte changed parses or fails, never panics.
    let mut rng = Rng(42);
    for _ in 0..3000 {
        let mut b = bytes.clone();
        let i = (rng.f64() * (b.len() - 4) as f64) as usize;
        b[i] = (rng.f64() * 256.0) as u8;
        let end = b.len() - 4;
        let crc = crc32fast::hash(&b[..end]).to_le_bytes();
        b[end..].copy_from_slice(&crc);
        let _ = RotationSet::from_bytes(&b, &limits);
    }
    // A header asking for more than the budget is refused before allocation.
    let small = Limits::with_max_alloc(64);
    assert!(RotationSet::from_bytes(&bytes, &small).is_err());
    let err = RotationSet::read(&path, &small).unwrap_err().to_string();
    assert!(err.contains("rotation cache"), "{err}");
}

/// Relative L2 of radiance against BRDF terms and the normal grid:
/// `cargo test -p ltm-relight --lib rotation::tests::error_sources -- --ignored --nocapture`.
#[test]
#[ignore]
fn error_sources() {
    let limits = Limits::default();
    let mut rng = Rng(78);
    let map = &maps_for(64)[2];
    let brdf = Brdf::Ggx {
        alpha: 0.2,
        f0: [0.9, 0.7, 0.5],
    };
    for normals in [8usize, 32] {
        let cfg = RotationConfig {
            n: 64,
            normals,
            ..RotationConfig::default()
        };
        let set = Arc::new(RotationSet::build(cfg, &limits).unwrap());
        // Points at grid normals and view-texel centres isolate the BRDF
        // terms; random points add the normal and view interpolation.
        let frames: Vec<(DVec3, DVec3)> = (0..100)
            .map(|k| {
                let i = (k * 7919) % (normals * normals);
                let n = cfg.grid_normal(i);
                let (u, v) = texel_center(64, (k * 104_729) % 4096);
                (n, Frame::new(n).to_global(hemi_decode(u, v).0))
            })
            .collect();
        let random: Vec<(DVec3, DVec3)> = (0..100)
            .map(|_| {
                let n = rng.dir();
                let v = rng.dir();
                (n, if v.dot(n) < 0.0 { -v } else { v })
            })
            .collect();
        for keep in [0.03, 0.1, 1.0] {
            let sc = SliceConfig {
                m: 32,
                views: 64,
                supersample: 4,
                keep,
                residuals: true,
            };
            let slices = Arc::new(BrdfSlices::build(brdf.clone(), sc, &limits).unwrap());
            let mut sh = Shader::new(set.clone(), slices, &limits).unwrap();
            sh.light(map, None).unwrap();
            let mut line = format!("normals {normals}² keep {keep}:");
            for (what, pts) in [("grid", &frames), ("random", &random)] {
                let (mut num, mut den) = (0.0, 0.0);
                for &(n, v) in pts.iter() {
                    let e = shade_brute_force(map, &brdf, n, v);
                    let b = sh.shade(n, v);
                    for c in 0..3 {
                        num += (f64::from(b[c]) - e[c]).powi(2);
                        den += e[c] * e[c];
                    }
                }
                line += &format!("  {what}: {:.4}", (num / den).sqrt());
            }
            println!("{line}");
        }
    }
}

/// Table 2's figures at n = 128 (about 1.2 GB):
/// `cargo test -p ltm-relight --lib rotation::tests::figures_128 -- --ignored --nocapture`.
#[test]
#[ignore]
fn figures_128() {
    use std::time::Instant;
    let cfg = RotationConfig {
        n: 128,
        ..RotationConfig::default()
    };
    let t0 = Instant::now();
    let set = RotationSet::build(cfg, &Limits::default()).unwrap();
    let s = set.stats();
    println!(
        "n=128 normals=32² precompute {:.1} s: {:.1} per row, density {:.2} %, {:.1} MB",
        t0.elapsed().as_secs_f64(),
        s.per_row,
        100.0 * s.density,
        s.bytes as f64 / 1e6
    );
}

/// The lighting side follows the sharpest lobe: 64 where `64·α` reaches
/// [`LOBE_TEXELS`] and for Lambert, 128 for sharper lobes and for a
/// measured table.
#[test]
fn the_lighting_side_follows_the_lobe() {
    let side = |spec: &str| {
        Brdf::from_spec(spec, &Limits::default())
            .unwrap()
            .lighting_side()
    };
    assert_eq!(side("lambert"), 64);
    assert_eq!(side("ggx:0.5"), 64);
    assert_eq!(side("ggx:0.4"), 64);
    assert_eq!(side("ggx:0.38"), 128);
    assert_eq!(side("ggx:0.2"), 128);
    assert_eq!(side("ggx:0.01"), 128);
    assert_eq!(side("plastic:0.5"), 64);
    assert_eq!(side("plastic:0.1"), 128);
    // e = 10: α = √(2/12) ≈ 0.41; e = 20: 0.30.
    assert_eq!(side("phong:10"), 64);
    assert_eq!(side("phong:20"), 128);
    // Sharp analytic lobes keep fewer terms; broad ones and tables more.
    let kept = |spec: &str, n: usize| {
        Brdf::from_spec(spec, &Limits::default())
            .unwrap()
            .kept_fractions(n)
    };
    assert_eq!(kept("ggx:0.2", 128), (0.03, 0.03));
    assert_eq!(kept("plastic:0.1", 128), (0.03, 0.03));
    assert_eq!(kept("ggx:0.2", 64), (0.1, 0.1));
    assert_eq!(kept("ggx:0.5", 128), (0.1, 0.1));
    assert_eq!(kept("lambert", 128), (0.1, 0.1));
    let table = MeasuredBrdf::tabulate("t", |_, _| [0.1; 3], &Limits::default()).unwrap();
    assert_eq!(
        Brdf::Measured(Arc::new(table)).kept_fractions(128),
        (0.1, 0.1)
    );
}

/// Step 2 through the pair table gives the same bits as computing every
/// pair where it is used, across changes of eye, lighting, BRDF, view grid
/// and keep (a table that kept a pair over a change would differ).
#[test]
fn the_pair_table_changes_nothing_and_forgets_on_every_change() {
    let cfg = RotationConfig {
        n: 16,
        normals: 8,
        supersample: 2,
        threshold: 1,
    };
    let slices = SliceConfig {
        m: 8,
        views: 16,
        supersample: 2,
        keep: 0.1,
        residuals: true,
    };
    let ggx = Brdf::Ggx {
        alpha: 0.2,
        f0: [0.9, 0.8, 0.7],
    };
    let mut table = shader(cfg, ggx.clone(), slices);
    let mut direct = shader(cfg, ggx, slices);
    assert!(!direct.set_pair_table(false));
    assert_eq!(direct.pairs_kept(), None);
    let mut rng = Rng(41);
    let points: Vec<ltm_codec::SurfacePoint> = (0..3000)
        .map(|_| {
            let n = rng.dir().as_vec3().to_array();
            ltm_codec::SurfacePoint::new(n, n)
        })
        .collect();
    let limits = Limits::default();
    let maps = maps_for(16);
    let check = |table: &Shader, direct: &Shader, rng: &mut Rng| {
        let eye = 4.0 * rng.dir();
        let mut a = vec![[0.0f32; 3]; points.len()];
        let mut b = a.clone();
        table.shade_points(&points, eye, &mut a).unwrap();
        direct.shade_points(&points, eye, &mut b).unwrap();
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
        let kept = table.pairs_kept().unwrap();
        assert!(kept > 0 && (kept as usize) < 4 * points.len(), "{kept}");
    };
    for map in &maps {
        for sh in [&mut table, &mut direct] {
            sh.light(map, None).unwrap();
        }
        assert_eq!(table.pairs_kept(), Some(0));
        check(&table, &direct, &mut rng);
        check(&table, &direct, &mut rng);
    }
    let lambert = Brdf::Lambert { albedo: [0.5; 3] };
    for views in [16, 8] {
        let cfg = SliceConfig { views, ..slices };
        let s = Arc::new(BrdfSlices::build(lambert.clone(), cfg, &limits).unwrap());
        for sh in [&mut table, &mut direct] {
            sh.set_brdf(s.clone()).unwrap();
        }
        assert_eq!(table.pairs_kept(), Some(0));
        check(&table, &direct, &mut rng);
    }
    for sh in [&mut table, &mut direct] {
        sh.set_local_keep(0.3, &limits).unwrap();
    }
    check(&table, &direct, &mut rng);
    // A table over its cap, or over the budget, is not made.
    assert!(pairs::PairTable::new(1 << 16, 1 << 16, &limits).is_none());
    assert!(pairs::PairTable::new(64, 256, &Limits::with_max_alloc(1000)).is_none());
    assert!(pairs::PairTable::new(64, 256, &limits).is_some());
}

/// Slices built once per orbit of the square's symmetries (and moved onto
/// the orbit's other views) equal slices built for every view, for each
/// kind of BRDF, on even and odd view grids: the symmetries leave each
/// BRDF unchanged (a measured table only under quarter turns).
#[test]
fn slices_built_per_orbit_equal_slices_built_per_view() {
    use super::spatial::Square;
    let limits = Limits::default();
    let ggx = Brdf::Ggx {
        alpha: 0.15,
        f0: [0.9, 0.6, 0.3],
    };
    let analytic = ggx.clone();
    let table = MeasuredBrdf::tabulate("ggx", move |wi, wo| analytic.eval(wi, wo), &limits);
    let brdfs = [
        ggx,
        Brdf::Lambert { albedo: [0.7; 3] },
        Brdf::Phong {
            exponent: 40.0,
            specular: [0.8; 3],
        },
        Brdf::Plastic {
            albedo: [0.5, 0.4, 0.3],
            alpha: 0.3,
            ior: 1.5,
        },
        Brdf::Measured(Arc::new(table.unwrap())),
    ];
    for brdf in &brdfs {
        let symmetries = Square::of(brdf);
        let expected = if matches!(brdf, Brdf::Measured(_)) {
            4
        } else {
            8
        };
        assert_eq!(symmetries.len(), expected);
        for (views, keep) in [(8, 1.0), (7, 0.1)] {
            let cfg = SliceConfig {
                m: 8,
                views,
                supersample: 3,
                keep,
                residuals: true,
            };
            let worst = worst_difference(brdf, &cfg, &symmetries);
            // The analytic BRDFs agree to the bit; a measured table's bins
            // can take a sub-sample on a bin's edge one way or the other as
            // the directions round.
            let bound = if expected == 4 { 2e-3 } else { 0.0 };
            println!("{brdf:?}, {views}² views: worst {worst:.2e}");
            assert!(worst <= bound, "{brdf:?}, {views}² views: {worst}");
        }
    }
    // A table is binned by the difference azimuth folded by reciprocity
    // alone (φ_d and φ_d + π share a bin, φ_d and −φ_d do not), so a table
    // that tells them apart is unchanged by quarter turns, not by mirrors.
    // (In-plane pairs lie on the bin edges φ_d = 0 and π/2, where rounding
    // picks the bin either way; this table steps there, so the quarter
    // turns differ too, but 17× less than the mirrors.)
    // Bin centres have φ_h = 0; there `ω_i.x > ω_o.x` where φ_d < π/2.
    let chiral = |wi: DVec3, wo: DVec3| [0.1 + 0.5 * f64::from(u8::from(wi.x > wo.x)); 3];
    let chiral = Brdf::Measured(Arc::new(
        MeasuredBrdf::tabulate("c", chiral, &limits).unwrap(),
    ));
    let cfg = SliceConfig {
        m: 8,
        views: 8,
        supersample: 3,
        keep: 1.0,
        residuals: true,
    };
    let all = Square::of(&Brdf::Lambert { albedo: [1.0; 3] });
    let worst = |symmetries: &[Square]| worst_difference(&chiral, &cfg, symmetries);
    let (turns, mirrors) = (worst(&Square::of(&chiral)), worst(&all));
    println!("chiral table: quarter turns {turns:.2e}, with mirrors {mirrors:.2e}");
    assert!(mirrors > 0.5 && turns < mirrors / 10.0, "{turns} {mirrors}");
}

/// The largest difference between slices built once per orbit under
/// `symmetries` and slices built per view, over every Haar coefficient
/// (kept or residual) and channel, relative to the view's largest.
fn worst_difference(brdf: &Brdf, cfg: &SliceConfig, symmetries: &[super::spatial::Square]) -> f32 {
    use super::brdf::{split_slices, SplitSlice};
    let dense = |(kept, rest): &SplitSlice| {
        let mut all = rest.clone();
        kept.iter().for_each(|&(i, v)| all[i as usize] = v);
        all
    };
    let fast = split_slices(brdf, cfg, symmetries).unwrap();
    let slow = split_slices(brdf, cfg, &symmetries[..1]).unwrap();
    let mut worst = 0f32;
    for (a, b) in fast.iter().zip(&slow) {
        let (a, b) = (dense(a), dense(b));
        let scale = b.iter().flatten().fold(0f32, |s, x| s.max(x.abs()));
        let diff = a.iter().flatten().zip(b.iter().flatten());
        worst = worst.max(diff.fold(0f32, |s, (x, y)| s.max((x - y).abs())) / scale);
    }
    worst
}

/// Step 2's view filter: bilinear weights sum to one and pick a texel at
/// its centre; on a grid normal, bilinear shading equals nearest at view
/// texel centres and is continuous between them, where nearest steps (a
/// sharp lobe under a lamp, views swept 0.05° apart).
#[test]
fn bilinear_views_are_continuous_where_nearest_steps() {
    let mut rng = Rng(9);
    for _ in 0..1000 {
        let (u, v) = (rng.f64() * 1.2 - 0.1, rng.f64() * 1.2 - 0.1);
        let taps = square_bilinear(16, u, v);
        let w: f64 = taps.iter().map(|p| p.1).sum();
        assert!((w - 1.0).abs() < 1e-12 && taps.iter().all(|p| p.0 < 256 && p.1 >= 0.0));
    }
    let cfg = RotationConfig {
        n: 32,
        normals: 4,
        supersample: 2,
        threshold: 1,
    };
    let slices = SliceConfig {
        m: 16,
        views: 16,
        supersample: 2,
        keep: 0.1,
        residuals: true,
    };
    let brdf = Brdf::Ggx {
        alpha: 0.1,
        f0: [1.0; 3],
    };
    let mut sh = shader(cfg, brdf, slices);
    let normal = cfg.grid_normal(6);
    let frame = Frame::new(normal);
    let light = frame.to_global(DVec3::new(0.5, -0.3, 0.8).normalize());
    let map = OctMap::from_fn(32, 4, |d| match d.dot(light) > 0.99 {
        true => [50.0; 3],
        false => [0.2; 3],
    });
    sh.light(&map.unwrap(), None).unwrap();
    let mut shade = |filter, view| {
        sh.set_view_filter(filter);
        sh.shade(normal, view)[0]
    };
    for t in [0, 37, 100, 255] {
        let (u, v) = texel_center(16, t);
        let view = frame.to_global(hemi_decode(u, v).0);
        let (a, b) = (
            shade(ViewFilter::Nearest, view),
            shade(ViewFilter::Bilinear, view),
        );
        assert!(
            (a - b).abs() <= 1e-5 * a.abs().max(1e-3),
            "texel {t}: {a} vs {b}"
        );
    }
    // Views swept through the mirror direction of the lamp.
    let mirror = 2.0 * normal.dot(light) * normal - light;
    let axis = mirror.cross(normal).normalize();
    let mut steps = |filter| {
        let values: Vec<f32> = (0..600)
            .map(|k| {
                let a = (f64::from(k) * 0.05 - 15.0).to_radians();
                let view = mirror * a.cos() + axis.cross(mirror) * a.sin();
                shade(filter, view)
            })
            .collect();
        let top = values.iter().copied().fold(0.0f32, f32::max);
        let step = values
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f32::max);
        step / top
    };
    let (nearest, bilinear) = (steps(ViewFilter::Nearest), steps(ViewFilter::Bilinear));
    println!("largest step between views 0.05° apart: nearest {nearest:.4}, bilinear {bilinear:.4} of the peak");
    assert!(nearest > 0.05, "nearest should step: {nearest}");
    assert!(
        bilinear < 0.25 * nearest,
        "bilinear {bilinear} vs nearest {nearest}"
    );
}
