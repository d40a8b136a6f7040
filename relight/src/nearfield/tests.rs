//! Near-field tests: couplings against numerical integration of eq. 8,
//! propagation and shading against an exact pixel-domain resampling of the
//! light, and hostile placements.

use super::acc::{coupling, couplings};
use super::shading_rows::ShadingRows;
use super::*;
use ltm_testkit::haar::{amplitude, basis, integrate};
use ltm_testkit::Rng;
use std::sync::Arc;

fn random_affine(rng: &mut Rng) -> (f64, f64) {
    let s = 10f64.powf(rng.uniform() * 3.0 - 1.5);
    let o = (rng.uniform() * 1.4 - 0.2) - 0.5 * s;
    (s, o)
}

#[test]
fn couplings_match_numerical_integration_of_eq_8() {
    let mut rng = Rng::new(7);
    let samples = 1 << 17;
    for _ in 0..300 {
        let (s, o) = random_affine(&mut rng);
        let i = (rng.next_u64() % 32) as usize;
        let k = (rng.next_u64() % 32) as usize;
        let exact = coupling(i, k, s, o);
        let numeric = integrate(i, k, s, o, samples);
        // Each of at most 6 breaks costs the midpoint rule one sample.
        let bound = 6.0 * amplitude(i) * amplitude(k) / samples as f64;
        assert!(
            (exact - numeric).abs() <= bound,
            "D_{i},{k}({s}, {o}) = {exact}, numerically {numeric}"
        );
    }
}

#[test]
fn identity_map_gives_the_kronecker_delta_and_eq_13_holds() {
    for i in 0..32 {
        for k in 0..32 {
            let expected = if i == k { 1.0 } else { 0.0 };
            assert!(
                (coupling(i, k, 1.0, 0.0) - expected).abs() < 1e-12,
                "{i} {k}"
            );
        }
    }
    let mut rng = Rng::new(3);
    for _ in 0..500 {
        let (s, o) = random_affine(&mut rng);
        let (i, j) = (
            (rng.next_u64() % 64) as usize,
            (rng.next_u64() % 64) as usize,
        );
        let left = coupling(i, j, s, o);
        let right = coupling(j, i, 1.0 / s, -o / s) / s;
        assert!(
            (left - right).abs() < 1e-9 * (1.0 + left.abs()),
            "{i} {j} {s} {o}"
        );
    }
}

#[test]
fn sparse_couplings_are_every_nonzero_coefficient() {
    let mut rng = Rng::new(11);
    let mut cases: Vec<(f64, f64)> = (0..200).map(|_| random_affine(&mut rng)).collect();
    cases.extend([
        (1.0, 0.0),
        (1e-6, 0.3),
        (1e6, -5e5),
        (0.5, 0.25),
        (2.0, -1.0),
        (1e-9, 1.0),
    ]);
    let order = 64;
    let mut list = Vec::new();
    let mut total = 0;
    for &(s, o) in &cases {
        for i in 0..order {
            list.clear();
            couplings(i, order, s, o, &mut list);
            let dense: Vec<(u32, f64)> = (0..order)
                .map(|k| (k as u32, coupling(i, k, s, o)))
                .filter(|&(_, d)| d.abs() > 1e-12)
                .collect();
            let kept: Vec<(u32, f64)> = list
                .iter()
                .copied()
                .filter(|&(_, d)| d.abs() > 1e-12)
                .collect();
            assert_eq!(kept.len(), dense.len(), "i {i}, s {s}, o {o}");
            for (a, b) in kept.iter().zip(&dense) {
                assert!(a.0 == b.0 && (a.1 - b.1).abs() < 1e-12);
            }
            total += list.len();
        }
    }
    // O(N log N) per (s, o): at most 1 + 3·log₂N targets per source.
    assert!(total <= cases.len() * order * (1 + 3 * 6));
}

/// The exact mean of `f(s·w + o)` over `w ∈ [a, b)` for a function that is
/// `values[p]` on `[p/len, (p+1)/len)` and zero outside `[0, 1)`.
fn mean_1d(values: &[f64], s: f64, o: f64, a: f64, b: f64) -> f64 {
    let (lo, hi) = (s * a + o, s * b + o);
    let n = values.len() as f64;
    let mut sum = 0.0;
    for (p, v) in values.iter().enumerate() {
        let start = (p as f64 / n).max(lo);
        let end = ((p + 1) as f64 / n).min(hi);
        if end > start {
            sum += v * (end - start);
        }
    }
    sum / (hi - lo)
}

/// The face texels' exact mean radiance in the pixel domain, for a
/// grey `side × side` texture that is separable: `fx[x]·fy[y]`.
fn face_means(fx: &[f64], fy: &[f64], axes: [(f64, f64); 2], order: usize) -> Vec<f64> {
    let h = 1.0 / order as f64;
    let mx: Vec<f64> = (0..order)
        .map(|j| mean_1d(fx, axes[0].0, axes[0].1, j as f64 * h, (j + 1) as f64 * h))
        .collect();
    let my: Vec<f64> = (0..order)
        .map(|j| mean_1d(fy, axes[1].0, axes[1].1, j as f64 * h, (j + 1) as f64 * h))
        .collect();
    my.iter()
        .flat_map(|y| mx.iter().map(move |x| x * y))
        .collect()
}

fn separable_light(fx: &[f64], fy: &[f64]) -> LightTexture {
    let texels = fy
        .iter()
        .flat_map(|y| fx.iter().map(move |x| [(x * y) as f32; 3]))
        .collect();
    LightTexture::new(fx.len(), fy.len(), texels).unwrap()
}

fn receivers(rng: &mut Rng, count: usize) -> Vec<Receiver> {
    (0..count)
        .map(|_| Receiver {
            depth: 10f64.powf(rng.uniform() * 2.0 - 1.5),
            position: [rng.uniform() * 3.0 - 1.5, rng.uniform() * 2.0 - 1.0],
        })
        .collect()
}

#[test]
fn propagated_light_and_shading_equal_the_exact_resampled_light() {
    let mut rng = Rng::new(5);
    let order = 16;
    // A separable texture at the face's order, so the light's box average is
    // the texture itself and the reference is exact.
    let fx: Vec<f64> = (0..order).map(|_| rng.uniform() * 4.0).collect();
    let fy: Vec<f64> = (0..order).map(|_| rng.uniform() * 2.0 + 0.1).collect();
    let light = separable_light(&fx, &fy);
    let placement = Placement {
        center: [0.2, -0.1],
        size: [1.5, 0.8],
        intensity: 3.0,
    };
    let face = PlaneFace {
        order,
        side: DEFAULT_FACE_SIDE,
    };
    let source = SourceCoefficients::new(&light, &placement, order, usize::MAX).unwrap();
    let mut propagator = Propagator::new(face).unwrap();
    for receiver in receivers(&mut rng, 40) {
        assert!(propagator
            .prepare(&source, &placement, &receiver, Targets::All)
            .unwrap());
        let axes = affine(&face, &placement, &receiver);
        let means: Vec<[f64; 3]> = face_means(&fx, &fy, axes, order)
            .iter()
            .map(|m| [m * placement.intensity; 3])
            .collect();
        let reference = haar_2d(&means, order, 1.0).unwrap();
        let got = propagator.incident();
        let norm: f64 = reference.iter().map(|c| c[0] * c[0]).sum::<f64>().sqrt();
        let diff: f64 = got
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a[1] - b[1]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            diff <= 1e-5 * norm + 1e-9,
            "{receiver:?}: {diff} against {norm}"
        );

        // Shading: a random transport row against Σ_j mean_j·t_j.
        let per_texel: Vec<f32> = (0..order * order)
            .map(|_| rng.uniform() as f32 * 1e-3)
            .collect();
        let exact: f64 = means
            .iter()
            .zip(&per_texel)
            .map(|(m, t)| m[0] * f64::from(*t))
            .sum();
        let transport = transport_coefficients(&per_texel, order).unwrap();
        let b = propagator.shade(&transport);
        assert!(
            (b[2] - exact).abs() <= 1e-5 * exact.abs() + 1e-12,
            "{b:?} against {exact}"
        );
    }
}

/// The stored rows' shading sums in f32 (`shade_indexed`, and
/// `shade_bands` over the bands of `band_starts`); they must agree with the
/// f64 `shade` relative to the terms' magnitudes, on HDR lights and rows of
/// mixed sign from 1e-6 to 1e5, ignore indices past the face, and read
/// nothing past the row from hostile band starts.
#[test]
fn f32_indexed_shading_agrees_with_the_f64_shading() {
    let mut rng = Rng::new(41);
    let order = 32;
    let face = PlaneFace {
        order,
        side: DEFAULT_FACE_SIDE,
    };
    let placement = Placement {
        center: [0.1, 0.3],
        size: [0.7, 1.2],
        intensity: 30.0,
    };
    let light = hdr_texture(&mut rng, 24, 17);
    let source = SourceCoefficients::new(&light, &placement, order, usize::MAX).unwrap();
    let mut propagator = Propagator::new(face).unwrap();
    let mut checked = 0;
    for receiver in receivers(&mut rng, 30) {
        if !propagator
            .prepare(&source, &placement, &receiver, Targets::Share(0.3))
            .unwrap()
        {
            continue;
        }
        let mut indices: Vec<u16> = (0..(order * order) as u16)
            .filter(|_| rng.uniform() < 0.4)
            .collect();
        indices.push(u16::MAX);
        let values: Vec<f32> = indices
            .iter()
            .map(|_| {
                let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
                (sign * 10f64.powf(rng.uniform() * 11.0 - 6.0)) as f32
            })
            .collect();
        let row: Vec<(u32, f32)> = indices
            .iter()
            .map(|&k| u32::from(k))
            .zip(values.iter().copied())
            .collect();
        let mut bands = vec![0u32; order];
        band_starts(&indices, order, &mut bands);
        let naive: Vec<u32> = (0..order)
            .map(|ky| {
                indices
                    .iter()
                    .filter(|&&k| usize::from(k) < ky * order)
                    .count() as u32
            })
            .collect();
        assert_eq!(bands, naive);
        let want = propagator.shade(&row);
        let got = propagator.shade_indexed(&indices, &values);
        let banded = propagator.shade_bands(&indices, &values, &bands);
        for c in 0..3 {
            let scale: f64 = row
                .iter()
                .map(|&(k, t)| (propagator.coefficient(k as usize)[c] * f64::from(t)).abs())
                .sum();
            for (what, value) in [("indexed", got[c]), ("banded", banded[c])] {
                assert!(
                    (value - want[c]).abs() <= 1e-5 * scale,
                    "{receiver:?} channel {c}, {what}: {value} against {} (terms {scale})",
                    want[c]
                );
            }
        }
        for hostile in [
            vec![u32::MAX; order],
            vec![7; 3],
            Vec::new(),
            (0..order as u32).rev().collect(),
        ] {
            let b = propagator.shade_bands(&indices, &values, &hostile);
            assert!(b.iter().all(|v| v.is_finite()), "{b:?}");
        }
        checked += 1;
    }
    assert!(checked > 20, "only {checked} points lit");
}

/// A propagator reused point after point (its incident light cleared box
/// by box, targets pruned by the threshold) gives what a new one gives at
/// each point, with points behind the plane between them.
#[test]
fn a_reused_propagator_equals_a_new_one_at_every_point() {
    let mut rng = Rng::new(77);
    let order = 16;
    let face = PlaneFace {
        order,
        side: DEFAULT_FACE_SIDE,
    };
    let placement = Placement {
        center: [-0.2, 0.1],
        size: [0.9, 0.5],
        intensity: 3.0,
    };
    let light = hdr_texture(&mut rng, 20, 13);
    let mut points = receivers(&mut rng, 40);
    points[7].depth = -1.0;
    points[19].depth = 0.0;
    for (share, targets) in [
        (0.05, Targets::Share(0.02)),
        (0.3, Targets::Share(0.2)),
        (1.0, Targets::All),
    ] {
        let keep = ((share * (order * order) as f64).ceil() as usize).max(1);
        let source = SourceCoefficients::new(&light, &placement, order, keep).unwrap();
        let mut reused = Propagator::new(face).unwrap();
        let mut pruned = false;
        for receiver in &points {
            let lit = reused
                .prepare(&source, &placement, receiver, targets)
                .unwrap();
            let mut fresh = Propagator::new(face).unwrap();
            assert_eq!(
                fresh
                    .prepare(&source, &placement, receiver, targets)
                    .unwrap(),
                lit
            );
            assert_eq!(
                reused.incident(),
                fresh.incident(),
                "{receiver:?} at {targets:?}"
            );
            pruned |= reused.pruned();
            if let (Targets::Share(share), true) = (targets, lit) {
                assert_selected(&reused, &mut fresh, (&source, &placement, receiver), share);
            }
        }
        // The smallest share must prune, and every target never does.
        assert_eq!(pruned, targets != Targets::All, "{targets:?}");
    }
}

/// Eq. 32 from scratch: under `share`, the targets whose constant-light
/// product `|D_{0 k_x}·D_{0 k_y}|` is among the largest `share·order²` keep
/// the value every target gives them, and the others are 0.
fn assert_selected(
    selected: &Propagator,
    all: &mut Propagator,
    (source, placement, receiver): (&SourceCoefficients, &Placement, &Receiver),
    share: f64,
) {
    let order = source.order;
    let face = PlaneFace {
        order,
        side: DEFAULT_FACE_SIDE,
    };
    let [px, py] = affine(&face, placement, receiver).map(|(s, o)| {
        let mut list = Vec::new();
        couplings(0, order, s, o, &mut list);
        let mut dense = vec![0.0f64; order];
        list.iter().for_each(|&(k, d)| dense[k as usize] = d.abs());
        dense
    });
    let product = |k: usize| px[k % order] * py[k / order];
    let mut products: Vec<f64> = (0..order * order)
        .map(product)
        .filter(|&p| p > 0.0)
        .collect();
    products.sort_by(|a, b| b.total_cmp(a));
    let count = ((share * (order * order) as f64).ceil() as usize).max(1);
    let threshold = if count > products.len() {
        0.0
    } else {
        products[count - 1]
    };
    assert!(all
        .prepare(source, placement, receiver, Targets::All)
        .unwrap());
    for k in 0..order * order {
        let want = if product(k) >= threshold {
            all.coefficient(k)
        } else {
            [0.0; 3]
        };
        assert_eq!(selected.coefficient(k), want, "target {k} of {receiver:?}");
    }
}

#[test]
fn fewer_terms_lose_accuracy_gracefully_and_all_terms_are_exact() {
    let mut rng = Rng::new(9);
    let order = 32;
    let fx: Vec<f64> = (0..order)
        .map(|x| if (x / 4) % 2 == 0 { 5.0 } else { 0.2 })
        .collect();
    let fy: Vec<f64> = (0..order).map(|_| rng.uniform() + 0.5).collect();
    let light = separable_light(&fx, &fy);
    let placement = Placement {
        center: [0.0, 0.0],
        size: [1.0, 1.0],
        intensity: 1.0,
    };
    let face = PlaneFace { order, side: 4.0 };
    let rows = receivers(&mut rng, 30);
    let transport: Vec<Vec<(u32, f32)>> = rows
        .iter()
        .map(|_| {
            let t: Vec<f32> = (0..order * order).map(|_| rng.uniform() as f32).collect();
            transport_coefficients(&t, order).unwrap()
        })
        .collect();
    let shade_all = |keep: usize, targets: Targets| -> Vec<f64> {
        let source = SourceCoefficients::new(&light, &placement, order, keep).unwrap();
        let mut p = Propagator::new(face).unwrap();
        rows.iter()
            .zip(&transport)
            .map(|(r, t)| {
                p.prepare(&source, &placement, r, targets).unwrap();
                p.shade(t)[0]
            })
            .collect()
    };
    let exact = shade_all(usize::MAX, Targets::All);
    let error = |got: &[f64]| -> f64 {
        let num: f64 = got.iter().zip(&exact).map(|(a, b)| (a - b).powi(2)).sum();
        (num / exact.iter().map(|b| b * b).sum::<f64>()).sqrt()
    };
    assert!(error(&shade_all(usize::MAX, Targets::Share(1.0))) < 1e-12);
    let coarse = error(&shade_all(4, Targets::Share(0.05)));
    let middle = error(&shade_all(64, Targets::Share(0.3)));
    let fine = error(&shade_all(512, Targets::Share(0.8)));
    assert!(coarse > middle && middle > fine, "{coarse} {middle} {fine}");
    assert!(fine < 0.05, "{fine}");
}

#[test]
fn box_average_keeps_the_mean_of_any_texture_shape() {
    let mut rng = Rng::new(2);
    for (w, h) in [
        (1, 1),
        (7, 5),
        (16, 16),
        (33, 2),
        (1, 8192),
        (8192, 1),
        (100, 3),
    ] {
        let texels: Vec<[f32; 3]> = (0..w * h)
            .map(|_| [rng.uniform() as f32, 1.0, 0.0])
            .collect();
        let mean: f64 = texels.iter().map(|t| f64::from(t[0])).sum::<f64>() / (w * h) as f64;
        let light = LightTexture::new(w, h, texels).unwrap();
        for order in [1, 4, 32] {
            let avg = light.box_average(order);
            let got: f64 = avg.iter().map(|a| a[0]).sum::<f64>() / (order * order) as f64;
            assert!((got - mean).abs() < 1e-9, "{w}x{h} at {order}");
            assert!(avg.iter().all(|a| (a[1] - 1.0).abs() < 1e-9 && a[2] == 0.0));
        }
    }
}

#[test]
fn source_coefficients_are_projections_onto_the_basis() {
    let mut rng = Rng::new(4);
    let order = 8;
    let texels: Vec<[f32; 3]> = (0..order * order)
        .map(|_| [rng.uniform() as f32; 3])
        .collect();
    let light = LightTexture::new(order, order, texels.clone()).unwrap();
    let averages: Vec<[f64; 3]> = texels.iter().map(|t| [f64::from(t[0]); 3]).collect();
    let got = haar_2d(&averages, order, 1.0).unwrap();
    let h = 1.0 / order as f64;
    for (k, coefficient) in got.iter().enumerate() {
        let (kx, ky) = (k % order, k / order);
        let expected: f64 = averages
            .iter()
            .enumerate()
            .map(|(j, a)| {
                let (x, y) = ((j % order) as f64 + 0.5, (j / order) as f64 + 0.5);
                a[0] * basis(kx, x * h) * basis(ky, y * h) * h * h
            })
            .sum();
        assert!((coefficient[0] - expected).abs() < 1e-6, "{k}");
    }
    let all = SourceCoefficients::new(
        &light,
        &Placement {
            center: [0.0; 2],
            size: [1.0; 2],
            intensity: 1.0,
        },
        order,
        64,
    )
    .unwrap();
    assert!((all.kept_energy() - 1.0).abs() < 1e-12);
}

const OK: Placement = Placement {
    center: [0.0; 2],
    size: [1.0; 2],
    intensity: 1.0,
};

/// Placements that are NaN, of zero or infinite size, negative, or so
/// bright that radiance × intensity overflows f32.
fn bad_placements() -> [Placement; 4] {
    [
        Placement {
            center: [f64::NAN, 0.0],
            ..OK
        },
        Placement {
            size: [0.0, 1.0],
            ..OK
        },
        Placement {
            size: [1.0, f64::INFINITY],
            ..OK
        },
        Placement {
            intensity: -1.0,
            ..OK
        },
    ]
}

#[test]
fn hostile_lights_and_faces_are_errors() {
    let light = LightTexture::constant([1.0; 3]).unwrap();
    for p in bad_placements() {
        let err = SourceCoefficients::new(&light, &p, 8, 10)
            .unwrap_err()
            .to_string();
        assert!(err.contains("valid"), "{p:?}: {err}");
    }
    assert!(SourceCoefficients::new(&light, &OK, 6, 10).is_err());
    assert!(SourceCoefficients::new(&light, &OK, 8, 0).is_err());
    // Far beyond f32 is taken (scaled); beyond f64 is refused.
    let huge = Placement {
        intensity: 1e300,
        ..OK
    };
    assert!(SourceCoefficients::new(&light, &huge, 8, 10).is_ok());
    let bright = LightTexture::constant([4.0; 3]).unwrap();
    let beyond = Placement {
        intensity: f64::MAX,
        ..OK
    };
    let err = SourceCoefficients::new(&bright, &beyond, 8, 10)
        .unwrap_err()
        .to_string();
    assert!(err.contains("within f64"), "{err}");
    assert!(LightTexture::new(2, 1, vec![[f32::NAN, 0.0, 0.0]; 2]).is_err());
    assert!(LightTexture::new(0, 1, vec![]).is_err());
    assert!(LightTexture::new(1, 1, vec![[-1.0, 0.0, 0.0]]).is_err());
    assert!(Propagator::new(PlaneFace {
        order: 8,
        side: 0.0
    })
    .is_err());
    assert!(Propagator::new(PlaneFace {
        order: 12,
        side: 4.0
    })
    .is_err());
}

#[test]
fn hostile_points_and_placements_error_or_go_dark() {
    let light = LightTexture::constant([1.0; 3]).unwrap();
    let face = PlaneFace {
        order: 8,
        side: 4.0,
    };
    let source = SourceCoefficients::new(&light, &OK, 8, 64).unwrap();
    let mut p = Propagator::new(face).unwrap();
    let row = [(0u32, 1.0f32)];
    for depth in [0.0, -1.0, -1e300] {
        let r = Receiver {
            depth,
            position: [0.0; 2],
        };
        assert!(!p.prepare(&source, &OK, &r, Targets::All).unwrap());
        assert_eq!(p.shade(&row), [0.0; 3]);
    }
    for r in [
        Receiver {
            depth: f64::NAN,
            position: [0.0; 2],
        },
        Receiver {
            depth: 1.0,
            position: [f64::INFINITY, 0.0],
        },
    ] {
        assert!(p.prepare(&source, &OK, &r, Targets::All).is_err());
    }
    // Extreme but valid: on the plane, very far, far to the side: defined,
    // finite and not negative.
    for (depth, x) in [(1e-300, 0.2), (1e12, 0.0), (1.0, 1e9), (1e-3, 1e-3)] {
        let r = Receiver {
            depth,
            position: [x, 0.0],
        };
        p.prepare(&source, &OK, &r, Targets::Share(0.2)).unwrap();
        let b = p.shade(&row);
        assert!(
            b.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{depth} {x}: {b:?}"
        );
    }
    // A bad placement at propagation time is an error too, never NaN.
    let r = Receiver {
        depth: 1.0,
        position: [0.0; 2],
    };
    for bad in &bad_placements()[..3] {
        assert!(
            p.prepare(&source, bad, &r, Targets::All).is_err(),
            "{bad:?}"
        );
    }
    let mismatched = SourceCoefficients::new(&light, &OK, 16, 4).unwrap();
    assert!(p.prepare(&mismatched, &OK, &r, Targets::All).is_err());
}

#[test]
fn a_constant_light_overhead_gives_the_lit_solid_angle_of_a_unit_transport() {
    // Transport = solid angle per face texel (V = ρ = cos = 1), so B is
    // the solid angle of the light seen through the face times radiance.
    // A 2×2 light at depth 1 under a face of side 4 lies inside the face
    // and subtends 4·asin(a·b/√((a² + 4d²)(b² + 4d²))) = 4·asin(1/2).
    let order = 64;
    let face = PlaneFace { order, side: 4.0 };
    let h = face.side / order as f64;
    let per_texel: Vec<f32> = (0..order * order)
        .map(|j| {
            let vx = ((j % order) as f64 + 0.5) * h - 2.0;
            let vy = ((j / order) as f64 + 0.5) * h - 2.0;
            (h * h / (1.0 + vx * vx + vy * vy).powf(1.5)) as f32
        })
        .collect();
    let transport = transport_coefficients(&per_texel, order).unwrap();
    let light = LightTexture::constant([2.0, 1.0, 0.5]).unwrap();
    let placement = Placement {
        center: [0.0; 2],
        size: [2.0; 2],
        intensity: 1.0,
    };
    let source = SourceCoefficients::new(&light, &placement, order, 1).unwrap();
    let mut p = Propagator::new(face).unwrap();
    p.prepare(
        &source,
        &placement,
        &Receiver {
            depth: 1.0,
            position: [0.0; 2],
        },
        Targets::All,
    )
    .unwrap();
    let b = p.shade(&transport);
    let omega = 4.0 * 0.5f64.asin();
    for (c, radiance) in [2.0, 1.0, 0.5].into_iter().enumerate() {
        assert!(
            (b[c] / radiance - omega).abs() < 2e-3 * omega,
            "{b:?} against {omega}"
        );
    }
}

/// A texture of `w × h` texels with values spread over 1e-6..1e5 (and some
/// zeros), for the summed-area table's precision.
fn hdr_texture(rng: &mut Rng, w: usize, h: usize) -> LightTexture {
    let texels = (0..w * h)
        .map(|_| match rng.next_u64() % 7 {
            0 => [0.0; 3],
            _ => std::array::from_fn(|_| 10f64.powf(rng.uniform() * 11.0 - 6.0) as f32),
        })
        .collect();
    LightTexture::new(w, h, texels).unwrap()
}

/// The integral over `[x0, x1] × [y0, y1]` (texture coordinates), texel by
/// texel, in texel units.
fn naive_mass(t: &LightTexture, x: [f64; 2], y: [f64; 2], intensity: f64) -> [f64; 3] {
    let (w, h) = (t.width(), t.height());
    let overlap = |a: [f64; 2], i: usize, n: usize| {
        let lo = a[0].clamp(0.0, 1.0) * n as f64;
        let hi = a[1].clamp(0.0, 1.0) * n as f64;
        (hi.min(i as f64 + 1.0) - lo.max(i as f64)).max(0.0)
    };
    let mut sum = [0.0f64; 3];
    for j in 0..h {
        let wy = overlap(y, j, h);
        if wy == 0.0 {
            continue;
        }
        for i in 0..w {
            let wx = overlap(x, i, w);
            let texel = t.texel(i, j);
            (0..3).for_each(|c| sum[c] += wx * wy * f64::from(texel[c]) * intensity);
        }
    }
    sum
}

fn total(t: &LightTexture) -> f64 {
    naive_mass(t, [0.0, 1.0], [0.0, 1.0], 1.0).iter().sum()
}

#[test]
fn table_masses_equal_a_texel_by_texel_sum_from_slivers_to_the_whole_light() {
    let mut rng = Rng::new(31);
    for (w, h) in [(1, 1), (3, 7), (64, 48), (100, 37), (5, 200)] {
        let texture = hdr_texture(&mut rng, w, h);
        let table = LightTable::new(&texture, 2.5).unwrap();
        let everything = 2.5 * total(&texture);
        for k in 0..400 {
            // Widths from 1e-9 of the light to twice it, anywhere near it.
            let span = |rng: &mut Rng| {
                let width = 10f64.powf(rng.uniform() * 9.3 - 9.0);
                let start = rng.uniform() * 1.4 - 0.2 - if k % 5 == 0 { width } else { 0.0 };
                [start, start + width]
            };
            let (x, y) = (span(&mut rng), span(&mut rng));
            let got = table.mass(x, y);
            let want = naive_mass(&texture, x, y, 2.5);
            for c in 0..3 {
                let bound = 1e-12 * want[c] + 1e-14 * everything;
                assert!(
                    (got[c] - want[c]).abs() <= bound,
                    "{w}x{h}, box {x:?} × {y:?}: {} against {}",
                    got[c],
                    want[c]
                );
            }
        }
    }
}

#[test]
fn face_masses_are_each_face_texels_mass_near_and_far() {
    let mut rng = Rng::new(41);
    let order = 16;
    let texture = hdr_texture(&mut rng, 48, 20);
    let table = LightTable::new(&texture, 1.0).unwrap();
    let everything = total(&texture);
    let mut masses = super::exact::FaceMasses::default();
    let (mut wide, mut narrow) = (0, 0);
    for k in 0..300 {
        // Scales from a point touching the light (1e-7) to one far away.
        let axes: [(f64, f64); 2] = std::array::from_fn(|_| {
            let s = match k % 2 {
                0 => 10f64.powf(rng.uniform() * 7.0 - 7.0),
                _ => 1.5 + rng.uniform() * 30.0,
            };
            (s, rng.uniform() * 1.6 - 0.3 - 0.5 * s)
        });
        if !masses.compute(&table, axes, order) {
            // Nothing covered: every face texel's box misses the light.
            let face = table.mass(
                [axes[0].1, axes[0].0 + axes[0].1],
                [axes[1].1, axes[1].0 + axes[1].1],
            );
            assert!(face.iter().all(|&m| m == 0.0), "{axes:?}: {face:?}");
            continue;
        }
        let is_wide =
            axes[0].0 * 48.0 >= 2.0 * order as f64 && axes[1].0 * 20.0 >= 2.0 * order as f64;
        if is_wide {
            wide += 1;
        } else {
            narrow += 1;
        }
        let (a0, a1) = masses.columns;
        let (b0, b1) = masses.rows;
        for b in 0..order {
            for a in 0..order {
                let edge = |k: usize, (s, o): (f64, f64)| s * (k as f64 / order as f64) + o;
                let x = [edge(a, axes[0]), edge(a + 1, axes[0])];
                let y = [edge(b, axes[1]), edge(b + 1, axes[1])];
                let want = naive_mass(&texture, x, y, 1.0);
                let got = if (a0..a1).contains(&a) && (b0..b1).contains(&b) {
                    masses.masses[(b - b0) * (a1 - a0) + (a - a0)]
                } else {
                    [0.0; 3]
                };
                for c in 0..3 {
                    let bound = 1e-10 * want[c] + 1e-14 * everything;
                    assert!(
                        (got[c] - want[c]).abs() <= bound,
                        "{axes:?} texel ({a}, {b}): {} against {}",
                        got[c],
                        want[c]
                    );
                }
            }
        }
    }
    assert!(wide > 20 && narrow > 20, "{wide} wide, {narrow} narrow");
}

/// Random near-field rows over a face of `order` with `channels`.
fn random_rows(rng: &mut Rng, order: u32, channels: usize, count: usize) -> ltm_codec::PlaneRows {
    let basis = ltm_codec::PlaneBasis {
        origin: [0.0, 2.0, 0.0],
        x_axis: [1.0, 0.0, 0.0],
        y_axis: [0.0, 0.0, 1.0],
        order,
        side: 4.0,
    };
    let mut rows = ltm_codec::PlaneRows::new(basis, channels).unwrap();
    let n = (order * order) as usize * channels;
    for p in 0..count {
        let texels: Vec<f32> = match p % 9 {
            0 => vec![0.0; n],
            _ => (0..n).map(|_| rng.uniform() as f32 * 1e-3).collect(),
        };
        rows.push_texels(&texels).unwrap();
    }
    rows
}

/// The wavelet method's row layout: an RGB file's three channel rows, with
/// different coefficients (a constant channel, a sparse one, one zero on
/// some rows), merge into one list that shades each channel under that
/// channel of the light as the channel rows do one by one, and rows whose
/// channels are the same list are held once; a grey file's rows shade
/// under all three. A budget too small for the layout refuses it.
#[test]
fn shading_rows_merge_rgb_channels_and_shade_as_the_channel_rows() {
    let mut rng = Rng::new(5);
    let order = 16usize;
    let face = PlaneFace {
        order,
        side: DEFAULT_FACE_SIDE,
    };
    let placement = Placement {
        center: [0.2, -0.1],
        size: [1.1, 0.8],
        intensity: 5.0,
    };
    let light = hdr_texture(&mut rng, 19, 23);
    let source = SourceCoefficients::new(&light, &placement, order, 40).unwrap();
    let points = receivers(&mut rng, 12);
    let mut propagator = Propagator::new(face).unwrap();
    for channels in [1, 3] {
        let mut rows = random_rows(&mut rng, order as u32, channels, 0);
        for p in 0..points.len() {
            let texels: Vec<f32> = (0..order * order * channels)
                .map(|i| match (i % channels, p % 3) {
                    // A grey surface: the same list in every channel.
                    _ if p % 4 == 3 => ((i / channels * 7919) % 13) as f32 * 1e-2 - 0.05,
                    (0, _) => 1e-3,
                    (1, _) if (i / channels) % 5 == 0 => rng.uniform() as f32,
                    (2, q) if q > 0 => (rng.uniform() as f32 - 0.5) * 1e3,
                    _ => 0.0,
                })
                .collect();
            rows.push_texels(&texels).unwrap();
        }
        let shading = ShadingRows::new(&rows, &ltm_codec::Limits::default()).unwrap();
        let mut lit = 0;
        for (p, receiver) in points.iter().enumerate() {
            if !propagator
                .prepare(&source, &placement, receiver, Targets::All)
                .unwrap()
            {
                continue;
            }
            let got = shading.shade(&propagator, p);
            for (c, &got) in got.iter().enumerate() {
                let (index, value) = rows.row(p, if channels == 1 { 0 } else { c });
                let row: Vec<(u32, f32)> = index
                    .iter()
                    .map(|&k| u32::from(k))
                    .zip(value.iter().copied())
                    .collect();
                let want = propagator.shade(&row)[c];
                let scale: f64 = row
                    .iter()
                    .map(|&(k, t)| (propagator.coefficient(k as usize)[c] * f64::from(t)).abs())
                    .sum();
                assert!(
                    (got - want).abs() <= 1e-5 * scale,
                    "{channels} channels, row {p}, channel {c}: {got} against {want}"
                );
            }
            lit += 1;
        }
        assert!(lit > 6, "only {lit} rows lit");
        let tight = ltm_codec::Limits::with_max_alloc(64);
        assert!(ShadingRows::new(&rows, &tight).is_err());
    }
}

#[test]
fn exact_rendering_equals_the_texel_means_and_the_full_wavelet_propagation() {
    let mut rng = Rng::new(77);
    let order = 16usize;
    let count = 60;
    for (channels, side) in [(1usize, order), (3, order), (1, 37)] {
        let rows = random_rows(&mut rng, order as u32, channels, count);
        let mut points: Vec<Option<Receiver>> =
            receivers(&mut rng, count).into_iter().map(Some).collect();
        points[3] = None;
        points[5] = Some(Receiver {
            depth: -0.5,
            position: [0.0, 0.0],
        });
        let albedo: Option<Vec<f32>> =
            (channels == 1).then(|| (0..3 * count).map(|i| 0.2 + (i % 5) as f32 * 0.1).collect());
        let near = NearField::new(
            rows.clone(),
            points.clone(),
            albedo.clone(),
            &ltm_codec::Limits::default(),
        )
        .unwrap();
        let fx: Vec<f64> = (0..side).map(|_| rng.uniform() * 4.0).collect();
        let tall = if side == order { order } else { side + 3 };
        let fy: Vec<f64> = (0..tall).map(|_| rng.uniform() * 2.0 + 0.1).collect();
        let light = AreaLight {
            texture: separable_light(&fx, &fy),
            placement: Placement {
                center: [0.3, -0.2],
                size: [1.2, 0.7],
                intensity: 2.0,
            },
        };
        let exact = near
            .render(std::slice::from_ref(&light), NearFieldMethod::Exact)
            .unwrap();
        let face = near.face();
        let mut texels = vec![0.0f32; order * order];
        for (p, point) in points.iter().enumerate() {
            let mut want = [0.0f64; 3];
            if let Some(r) = point.filter(|r| r.depth > 0.0) {
                let means = face_means(&fx, &fy, affine(&face, &light.placement, &r), order);
                for c in 0..channels {
                    rows.texels(p, c, &mut texels).unwrap();
                    let b: f64 = means
                        .iter()
                        .zip(&texels)
                        .map(|(m, &t)| m * f64::from(t))
                        .sum::<f64>()
                        * 2.0;
                    match channels {
                        1 => want = [b; 3],
                        _ => want[c] = b,
                    }
                }
            }
            for c in 0..3 {
                let a = albedo.as_ref().map_or(1.0, |a| f64::from(a[3 * p + c]));
                let w = want[c] * a;
                let got = f64::from(exact[p][c]);
                assert!(
                    (got - w).abs() <= 1e-5 * w.abs() + 1e-12,
                    "row {p} channel {c}: {got} against {w}"
                );
            }
        }
        // With the texture at the face's order, the wavelet propagation of
        // every term is the same light.
        if side == order {
            let all = NearFieldMethod::Wavelet(NearFieldTerms::ALL);
            let wavelet = near.render(std::slice::from_ref(&light), all).unwrap();
            for (p, (a, b)) in exact.iter().zip(&wavelet).enumerate() {
                for c in 0..3 {
                    let (a, b) = (f64::from(a[c]), f64::from(b[c]));
                    assert!(
                        (a - b).abs() <= 1e-4 * b.abs() + 1e-12,
                        "row {p}: {a} against {b}"
                    );
                }
            }
        }
    }
}

#[test]
fn exact_rendering_of_hostile_lights_and_points_is_finite_and_matches_the_wavelets() {
    let mut rng = Rng::new(88);
    let order = 8usize;
    let count = 200;
    let rows = random_rows(&mut rng, order as u32, 1, count);
    // Depths from touching the plane to far beyond the light.
    let points: Vec<Option<Receiver>> = (0..count)
        .map(|p| {
            Some(Receiver {
                depth: 10f64.powf(p as f64 / count as f64 * 14.0 - 10.0),
                position: [rng.uniform() * 2.0 - 1.0, rng.uniform() * 2.0 - 1.0],
            })
        })
        .collect();
    let near = NearField::new(rows.clone(), points, None, &ltm_codec::Limits::default()).unwrap();
    let all = NearFieldMethod::Wavelet(NearFieldTerms::ALL);
    // A uniform light has one Haar coefficient: both methods are exact.
    for size in [1e-9, 0.3, 2.0, 1e6] {
        let light = AreaLight {
            texture: LightTexture::constant([1.0, 2.0, 0.5]).unwrap(),
            placement: Placement {
                center: [0.1, -0.2],
                size: [size, size * 0.5],
                intensity: 3.0,
            },
        };
        let lights = std::slice::from_ref(&light);
        let exact = near.render(lights, NearFieldMethod::Exact).unwrap();
        let wavelet = near.render(lights, all).unwrap();
        for (p, (a, b)) in exact.iter().zip(&wavelet).enumerate() {
            for c in 0..3 {
                assert!(a[c].is_finite() && a[c] >= 0.0);
                // Both carry the f32 rounding of the rows' Haar
                // coefficients, relative to the row's largest texel: a
                // speck of light over a small texel sees it magnified.
                let tolerance = 1e-3 * b[c].abs() + 1e-30;
                assert!(
                    (a[c] - b[c]).abs() <= tolerance,
                    "size {size}, row {p}: {a:?} against {b:?}"
                );
            }
        }
    }
    // Textures past the table's side, extreme radiance: finite output or
    // a clear error.
    let wide = LightTexture::new(2000, 3, vec![[1e30, 0.0, 1e-30]; 6000]).unwrap();
    let light = AreaLight {
        texture: wide,
        placement: Placement {
            center: [0.0; 2],
            size: [1.0; 2],
            intensity: 1.0,
        },
    };
    assert_eq!(
        LightTable::new(&light.texture, 1.0).unwrap().size(),
        (MAX_TABLE_SIDE, 3)
    );
    let image = near
        .render(std::slice::from_ref(&light), NearFieldMethod::Exact)
        .unwrap();
    assert!(image.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
    assert!(LightTable::new(&light.texture, 1e300).is_err());
    assert!(LightTable::new(&light.texture, f64::NAN).is_err());
    // Points that are not finite are refused when the rows are made.
    let nan = vec![
        Some(Receiver {
            depth: f64::NAN,
            position: [0.0; 2]
        });
        count
    ];
    assert!(NearField::new(rows, nan, None, &ltm_codec::Limits::default()).is_err());
}

/// The radiance-weighted power `Σ t·area` and centroid of a texture over a
/// light of `size` centred at the origin.
fn power_and_centroid(t: &LightTexture, size: [f64; 2]) -> (f64, [f64; 2]) {
    let area = size[0] * size[1] / (t.width() * t.height()) as f64;
    let (mut power, mut moment) = (0.0, [0.0; 2]);
    for j in 0..t.height() {
        for i in 0..t.width() {
            let v = f64::from(t.texel(i, j)[1]) * area;
            let x = ((i as f64 + 0.5) / t.width() as f64 - 0.5) * size[0];
            let y = ((j as f64 + 0.5) / t.height() as f64 - 0.5) * size[1];
            power += v;
            moment[0] += v * x;
            moment[1] += v * y;
        }
    }
    (power, moment.map(|m| m / power))
}

#[test]
fn rotated_lights_keep_their_power_and_turn_their_centroid() {
    let mut rng = Rng::new(12);
    // Square texels: a quarter turn lands on the same grid, texel for
    // texel (new (i, j) is old (j, H − 1 − i)).
    let texels: Vec<[f32; 3]> = (0..8).map(|_| [rng.uniform() as f32; 3]).collect();
    let t = LightTexture::new(4, 2, texels).unwrap();
    let (turned, size) = t.rotated([1.0, 0.5], 90.0).unwrap();
    assert!((size[0] - 0.5).abs() < 1e-12 && (size[1] - 1.0).abs() < 1e-12);
    assert_eq!((turned.width(), turned.height()), (2, 4));
    for j in 0..4 {
        for i in 0..2 {
            assert_eq!(turned.texel(i, j), t.texel(j, 1 - i), "({i}, {j})");
        }
    }
    // Any angle: the power stays, the centroid turns with the light.
    let texels: Vec<[f32; 3]> = (0..48 * 20)
        .map(|k| {
            [if k % 48 < 12 {
                5.0
            } else {
                rng.uniform() as f32
            }; 3]
        })
        .collect();
    let t = LightTexture::new(48, 20, texels).unwrap();
    let size = [1.2, 0.5];
    let (power, centroid) = power_and_centroid(&t, size);
    for degrees in [30.0, 45.0, -100.0, 200.0] {
        let (turned, bound) = t.rotated(size, degrees).unwrap();
        let (p, c) = power_and_centroid(&turned, bound);
        assert!(
            (p - power).abs() < 0.01 * power,
            "{degrees}°: power {p} against {power}"
        );
        let (sin, cos) = f64::to_radians(degrees).sin_cos();
        let want = [
            cos * centroid[0] - sin * centroid[1],
            sin * centroid[0] + cos * centroid[1],
        ];
        let texel = size[0] / 48.0;
        for a in 0..2 {
            assert!(
                (c[a] - want[a]).abs() < texel,
                "{degrees}°: centroid {c:?} against {want:?}"
            );
        }
    }
    assert!(t.rotated(size, f64::NAN).is_err());
    assert!(t.rotated([0.0, 1.0], 30.0).is_err());
}

/// The largest `|table − exact|` over random `(s, o)` and every source and
/// target of order 32, relative to the two functions' amplitudes.
fn table_error(table: &AccTable, cases: usize) -> f64 {
    let mut rng = Rng::new(5);
    let (mut exact, mut looked_up) = (Vec::new(), Vec::new());
    let mut worst = 0.0f64;
    for _ in 0..cases {
        let (s, o) = random_affine(&mut rng);
        for i in 0..32 {
            exact.clear();
            looked_up.clear();
            couplings(i, 32, s, o, &mut exact);
            table.couplings_where(i, s, o, |_| true, &mut looked_up);
            let mut dense = [0.0f64; 32];
            exact.iter().for_each(|&(k, d)| dense[k as usize] += d);
            looked_up.iter().for_each(|&(k, d)| dense[k as usize] -= d);
            for (k, e) in dense.iter().enumerate() {
                worst = worst.max(e.abs() / (amplitude(i) * amplitude(k)));
            }
        }
    }
    worst
}

#[test]
fn table_lookups_converge_to_the_closed_form_and_propagate_alike() {
    let limits = ltm_codec::Limits::default();
    let coarse = AccTable::new(32, 8, &limits).unwrap();
    let fine = AccTable::new(32, 64, &limits).unwrap();
    let (e_coarse, e_fine) = (table_error(&coarse, 300), table_error(&fine, 300));
    // Measured 0.27 and 0.034 of the amplitudes' product: breaks moved by
    // up to half a cell, so eight times the cells give an eighth.
    assert!(
        e_fine < 0.05 && e_fine < 0.2 * e_coarse,
        "{e_coarse} {e_fine}"
    );
    assert!(fine.bytes() > 30 * coarse.bytes() && coarse.entries() > 0);
    // Whole propagations: the incident light converges to the closed
    // form's as well.
    let (i_coarse, i_fine) = (incident_error(coarse), incident_error(fine));
    // Measured 0.35 and 0.050.
    assert!(
        i_fine < 0.075 && i_fine < 0.2 * i_coarse,
        "{i_coarse} {i_fine}"
    );
}

/// The relative L2 distance of every incident coefficient with couplings
/// from `table` to the closed form's, over 200 points and a random light.
fn incident_error(table: AccTable) -> f64 {
    let face = PlaneFace {
        order: 32,
        side: 4.0,
    };
    let texture = hdr_texture(&mut Rng::new(2), 48, 40);
    let placement = Placement {
        center: [0.2, -0.1],
        size: [1.2, 0.9],
        intensity: 1.0,
    };
    let source = SourceCoefficients::new(&texture, &placement, 32, 1024).unwrap();
    let mut exact = Propagator::new(face).unwrap();
    let mut looked_up = Propagator::with_table(face, std::sync::Arc::new(table)).unwrap();
    let (mut difference, mut norm) = (0.0, 0.0);
    for receiver in receivers(&mut Rng::new(4), 200) {
        for p in [&mut exact, &mut looked_up] {
            p.prepare(&source, &placement, &receiver, Targets::All)
                .unwrap();
        }
        for (a, b) in exact.incident().iter().zip(looked_up.incident()) {
            for c in 0..3 {
                difference += (a[c] - b[c]).powi(2);
                norm += a[c].powi(2);
            }
        }
    }
    (difference / norm).sqrt()
}

#[test]
fn hostile_tables_are_errors() {
    let limits = ltm_codec::Limits::default();
    for (order, cells) in [(0, 64), (24, 64), (2048, 64), (32, 0), (32, 7), (32, 513)] {
        assert!(
            AccTable::new(order, cells, &limits).is_err(),
            "{order} {cells}"
        );
    }
    // Order 1024 at 512 cells: more couplings than u32 starts can index,
    // refused before anything is charged or built.
    let huge = AccTable::new(1024, 512, &limits).unwrap_err().to_string();
    assert!(huge.contains("fewer cells"), "{huge}");
    let tight = ltm_codec::Limits::with_max_alloc(1 << 20);
    let err = AccTable::new(32, 256, &tight).unwrap_err().to_string();
    assert!(err.contains("coupling table"), "{err}");
    let table = std::sync::Arc::new(AccTable::new(16, 8, &limits).unwrap());
    let face = PlaneFace {
        order: 32,
        side: 4.0,
    };
    assert!(Propagator::with_table(face, table).is_err());
}

#[test]
fn stored_rows_render_alike_through_a_coupling_table() {
    let mut rng = Rng::new(31);
    let order = 16usize;
    let count = 80;
    let limits = ltm_codec::Limits::default();
    for channels in [1usize, 3] {
        let rows = random_rows(&mut rng, order as u32, channels, count);
        let points: Vec<Option<Receiver>> =
            receivers(&mut rng, count).into_iter().map(Some).collect();
        let mut near = NearField::new(rows, points, None, &limits).unwrap();
        let light = AreaLight {
            texture: hdr_texture(&mut rng, 40, 24),
            placement: Placement {
                center: [0.3, -0.2],
                size: [1.5, 1.0],
                intensity: 2.0,
            },
        };
        let lights = std::slice::from_ref(&light);
        let method = NearFieldMethod::Wavelet(NearFieldTerms {
            source: 0.2,
            targets: Targets::Share(0.5),
        });
        let closed = near.render(lights, method).unwrap();
        let wrong = AccTable::new(2 * order, 16, &limits).unwrap();
        assert!(near.set_coupling_table(Some(Arc::new(wrong))).is_err());
        let table = AccTable::new(order, 128, &limits).unwrap();
        near.set_coupling_table(Some(Arc::new(table))).unwrap();
        let looked_up = near.render(lights, method).unwrap();
        let (mut difference, mut norm) = (0.0f64, 0.0f64);
        for (a, b) in closed.iter().flatten().zip(looked_up.iter().flatten()) {
            assert!(b.is_finite() && *b >= 0.0);
            difference += (f64::from(*a) - f64::from(*b)).powi(2);
            norm += f64::from(*a).powi(2);
        }
        let relative = (difference / norm).sqrt();
        // A first-order table: measured 0.26 % and 0.27 % at 128 cells.
        assert!(relative > 0.0 && relative < 0.006, "{channels}: {relative}");
        near.set_coupling_table(None).unwrap();
        assert_eq!(near.render(lights, method).unwrap(), closed);
    }
}

#[test]
fn extreme_light_sizes_neither_panic_nor_give_nan_through_both_couplings() {
    let mut rng = Rng::new(41);
    let order = 16usize;
    let limits = ltm_codec::Limits::default();
    let rows = random_rows(&mut rng, order as u32, 1, 12);
    // Points at the light's centre and beside it, near and far.
    let points: Vec<Option<Receiver>> = (0..12)
        .map(|p| {
            Some(Receiver {
                depth: [1e-12, 1.0, 1e12][p % 3],
                position: [if p % 2 == 0 { 0.25 } else { 0.25 + 1e-9 }, -0.5],
            })
        })
        .collect();
    let mut near = NearField::new(rows, points, None, &limits).unwrap();
    let method = NearFieldMethod::Wavelet(NearFieldTerms {
        source: 0.5,
        targets: Targets::Share(0.3),
    });
    for table in [
        None,
        Some(Arc::new(AccTable::new(order, 16, &limits).unwrap())),
    ] {
        near.set_coupling_table(table).unwrap();
        for size in [1e-320, 1e-300, 1e-9, 1e9, 1e300, f64::MAX] {
            let light = AreaLight {
                texture: hdr_texture(&mut rng, 8, 8),
                placement: Placement {
                    center: [0.25, -0.5],
                    size: [size, size],
                    intensity: 1.0,
                },
            };
            let image = near.render(std::slice::from_ref(&light), method).unwrap();
            assert!(
                image.iter().flatten().all(|v| v.is_finite() && *v >= 0.0),
                "size {size}: {image:?}"
            );
        }
    }
}

/// Lights far above and below `f32`'s range give the unit light's image
/// scaled by their intensity: steps 1 and 2 run on the light divided by a
/// power of two, so no `f32` sum overflows (which made a dark pixel) or
/// flushes to zero. Past `f32`, pixels saturate at `f32::MAX`, as the
/// exact method's do, in grey and RGB files.
#[test]
fn extreme_intensities_scale_the_image_and_saturate_past_f32() {
    let mut rng = Rng::new(43);
    let (order, count) = (16usize, 60);
    let limits = ltm_codec::Limits::default();
    for channels in [1usize, 3] {
        let rows = random_rows(&mut rng, order as u32, channels, count);
        let points: Vec<Option<Receiver>> =
            receivers(&mut rng, count).into_iter().map(Some).collect();
        let near = NearField::new(rows, points, None, &limits).unwrap();
        let texture = hdr_texture(&mut rng, 24, 16);
        let render = |intensity: f64, method| {
            let light = AreaLight {
                texture: texture.clone(),
                placement: Placement {
                    center: [0.1, -0.2],
                    size: [1.2, 0.9],
                    intensity,
                },
            };
            near.render(std::slice::from_ref(&light), method).unwrap()
        };
        let wavelet = NearFieldMethod::Wavelet(NearFieldTerms {
            source: 0.3,
            targets: Targets::Share(0.5),
        });
        let unit = render(1.0, wavelet);
        assert!(unit.iter().flatten().any(|&v| v > 0.0));
        for e in [-100, -60, 60, 100, 120] {
            let s = 2f64.powi(e);
            for (a, b) in unit
                .iter()
                .flatten()
                .zip(render(s, wavelet).iter().flatten())
            {
                let want = (f64::from(*a) * s).min(f64::from(f32::MAX));
                let tolerance = if want >= f64::from(f32::MIN_POSITIVE) {
                    0.0
                } else {
                    2f64.powi(-126)
                };
                assert!(
                    (f64::from(*b) - want).abs() <= tolerance,
                    "2^{e}: {b} against {want}"
                );
            }
        }
        for method in [wavelet, NearFieldMethod::Exact] {
            let unit = render(1.0, method);
            for e in [200, 900] {
                let image = render(2f64.powi(e), method);
                for (a, b) in unit.iter().flatten().zip(image.iter().flatten()) {
                    match *a {
                        a if a > 1e-20 => assert_eq!(*b, f32::MAX, "2^{e}: {a}"),
                        0.0 => assert_eq!(*b, 0.0, "2^{e}"),
                        _ => assert!(b.is_finite() && *b >= 0.0),
                    }
                }
            }
        }
    }
}
