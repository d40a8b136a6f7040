use super::*;

/// A torus (genus 1) of `n × m` quads.
fn torus(n: usize, m: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let tau = std::f32::consts::TAU;
    let mut p = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (i as f32 / n as f32 * tau, j as f32 / m as f32 * tau);
            let r = 1.0 + 0.3 * v.cos();
            p.push([r * u.cos(), 0.3 * v.sin(), r * u.sin()]);
        }
    }
    let id = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    let mut t = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            t.push([a, b, c]);
            t.push([a, c, d]);
        }
    }
    (p, t)
}

fn pack(resolution: u32) -> PackOptions {
    PackOptions {
        resolution,
        texels_per_unit: 0.0,
        padding: 2,
    }
}

/// Twice the signed area of a triangle's texture image.
fn uv_area2(a: &Atlas, t: &[u32; 3]) -> f32 {
    let [p, q, r] = t.map(|k| a.vertices[k as usize].uv);
    (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
}

#[test]
fn a_torus_packs_into_one_texture_without_overlap() {
    let (p, t) = torus(48, 16);
    let a = generate(
        MeshInput {
            positions: &p,
            triangles: &t,
        },
        &pack(128),
    )
    .unwrap();
    assert_eq!(a.triangles.len(), t.len());
    assert!(
        a.width <= 128 && a.height <= 128,
        "{}×{}",
        a.width,
        a.height
    );
    assert!(
        a.charts >= 2,
        "a torus cannot be one flat chart: {}",
        a.charts
    );
    for v in &a.vertices {
        assert!((v.source as usize) < p.len());
        assert!(v.uv.iter().all(|c| (0.0..=128.0).contains(c)), "{:?}", v.uv);
    }
    // Every triangle keeps its corners' source vertices.
    for (out, input) in a.triangles.iter().zip(&t) {
        assert_eq!(out.map(|k| a.vertices[k as usize].source), *input);
    }
    // No texel centre lies strictly inside two triangles' images.
    let mut hits = vec![0u8; 128 * 128];
    for tri in &a.triangles {
        let c = tri.map(|k| a.vertices[k as usize].uv);
        let area = uv_area2(&a, tri);
        assert!(area.abs() > 0.0);
        for y in 0..128 {
            for x in 0..128 {
                let q = [x as f32 + 0.5, y as f32 + 0.5];
                let side = |a: [f32; 2], b: [f32; 2]| {
                    ((b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0])) * area.signum()
                };
                if side(c[0], c[1]) > 1e-3 && side(c[1], c[2]) > 1e-3 && side(c[2], c[0]) > 1e-3 {
                    hits[y * 128 + x] += 1;
                }
            }
        }
    }
    assert!(hits.iter().all(|&h| h <= 1), "overlapping charts");
    assert!(hits.iter().filter(|&&h| h == 1).count() > 128 * 128 / 4);
}

#[test]
fn the_same_mesh_gives_the_same_atlas() {
    let (p, t) = torus(40, 12);
    let input = MeshInput {
        positions: &p,
        triangles: &t,
    };
    let a = generate(input, &pack(96)).unwrap();
    let b = generate(input, &pack(96)).unwrap();
    assert_eq!(a, b);
}

#[test]
fn a_density_sets_the_texture_size() {
    let (p, t) = torus(32, 12);
    let input = MeshInput {
        positions: &p,
        triangles: &t,
    };
    let small = generate(
        input,
        &PackOptions {
            resolution: 0,
            texels_per_unit: 20.0,
            padding: 2,
        },
    )
    .unwrap();
    let large = generate(
        input,
        &PackOptions {
            resolution: 0,
            texels_per_unit: 40.0,
            padding: 2,
        },
    )
    .unwrap();
    assert_eq!(small.texels_per_unit, 20.0);
    let ratio =
        large.width as f32 * large.height as f32 / (small.width as f32 * small.height as f32);
    assert!((2.5..6.0).contains(&ratio), "{ratio}");
}

#[test]
fn too_dense_for_the_size_is_an_error_naming_both() {
    let (p, t) = torus(32, 12);
    let input = MeshInput {
        positions: &p,
        triangles: &t,
    };
    let e = generate(
        input,
        &PackOptions {
            resolution: 32,
            texels_per_unit: 200.0,
            padding: 2,
        },
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, AtlasError::DoesNotFit { .. }) && msg.contains("32×32") && msg.contains("200"),
        "{msg}"
    );
}

#[test]
fn bad_meshes_are_errors_not_crashes() {
    let (p, t) = torus(8, 4);
    let nan = {
        let mut q = p.clone();
        q[3][1] = f32::NAN;
        q
    };
    type Case = (Vec<[f32; 3]>, Vec<[u32; 3]>, &'static str);
    let cases: Vec<Case> = vec![
        (vec![], vec![], "at least one"),
        (p.clone(), vec![[0, 1, 99]], "below 32"),
        (nan, t.clone(), "non-finite"),
    ];
    for (pos, tri, want) in cases {
        let e = generate(
            MeshInput {
                positions: &pos,
                triangles: &tri,
            },
            &pack(64),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains(want), "{e}");
    }
    let e = generate(
        MeshInput {
            positions: &p,
            triangles: &t,
        },
        &PackOptions {
            resolution: 64,
            texels_per_unit: f32::NAN,
            padding: 1,
        },
    );
    assert!(e.is_err());
    // Only degenerate triangles: an atlas with no chart, not a crash.
    let flat = vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    let r = generate(
        MeshInput {
            positions: &flat,
            triangles: &[[0, 1, 2]],
        },
        &pack(16),
    );
    if let Ok(a) = r {
        assert_eq!(a.triangles.len(), 1);
    }
}

/// Densities far beyond any texture are refused before xatlas runs, and
/// one just inside the limit packs.
#[test]
fn huge_densities_are_refused_not_crashes() {
    let (p, t) = torus(32, 12);
    let input = MeshInput {
        positions: &p,
        triangles: &t,
    };
    for tpu in [900000.0, 1e30, f32::MAX] {
        let e = generate(
            input,
            &PackOptions {
                resolution: 0,
                texels_per_unit: tpu,
                padding: 2,
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("lower the texel density"), "{e}");
    }
    // Area about 11.8: 1500 texels per unit is about 5150² texels.
    let a = generate(
        input,
        &PackOptions {
            resolution: 0,
            texels_per_unit: 1500.0,
            padding: 2,
        },
    )
    .unwrap();
    assert!(a.width <= 2 * MAX_SIDE && a.height <= 2 * MAX_SIDE);
    let e = generate(
        input,
        &PackOptions {
            resolution: 16,
            texels_per_unit: 500.0,
            padding: 2,
        },
    )
    .unwrap_err();
    assert!(matches!(e, AtlasError::DoesNotFit { .. }), "{e}");
}
