//! Relighting on the linear bases (PCA, spherical harmonics) against the
//! dense product `T̂·L` of their reconstruction, and the three relighters
//! behind one `dyn Relight`.

use ltm_codec::baseline::sh;
use ltm_codec::compress::{compress, CompressOptions};
use ltm_codec::{cubemap, Dims, Limits, PcaBasis, RawStore, ShProjection};
use ltm_relight::{
    reference, relative_l2, BasisRelighter, Frame, Relight, Relighter, Request, Weighting,
};
use ltm_testkit::{block_bytes, write_raw, Rng};

fn dims(width: u32, height: u32, face_res: u32, channels: u32) -> Dims {
    Dims::image(width, height, face_res, channels)
}

/// A deterministic random matrix with every third pixel zero.
fn random_matrix(d: Dims, seed: u64) -> Vec<f32> {
    let mut rng = Rng(seed);
    let row = d.row_len();
    let mut t = vec![0.0f32; d.pixels() * row];
    for p in (0..d.pixels()).filter(|p| p % 3 != 1) {
        for v in &mut t[p * row..(p + 1) * row] {
            *v = (rng.uniform() * 1e-2) as f32;
        }
    }
    t
}

fn random_light(m: usize) -> Vec<[f32; 3]> {
    let mut rng = Rng(9);
    (0..m)
        .map(|_| [0, 1, 2].map(|_| (rng.uniform() * 3.0) as f32))
        .collect()
}

/// The store as a dense matrix, rows (pixel, channel), f64.
fn dense(raw: &RawStore) -> Vec<Vec<f64>> {
    let d = raw.dims();
    let c = d.channels as usize;
    let mut t = Vec::new();
    raw.read_rows(0..d.pixels(), &mut t).unwrap();
    (0..d.pixels() * c)
        .map(|r| {
            (0..d.lights())
                .map(|j| t[(r / c) * d.row_len() + j * c + r % c] as f64)
                .collect()
        })
        .collect()
}

/// The SH reconstruction `T̂_L` of a dense matrix: `F = T·Y`, then
/// `T̂[r, j] = Σ_{a<L²} F[r, a]·Y_a(ω_j)·dω_j`.
fn dense_sh(a: &[Vec<f64>], n: usize, order: usize) -> Vec<Vec<f64>> {
    let m = cubemap::texel_count(n);
    let k = order * order;
    let y: Vec<Vec<f64>> = (0..m)
        .map(|j| {
            let mut v = vec![0.0; k];
            let d = cubemap::texel_direction(n, j).as_dvec3().normalize();
            sh::eval(order, d, &mut v).unwrap();
            v
        })
        .collect();
    a.iter()
        .map(|t| {
            let f: Vec<f64> = (0..k)
                .map(|b| (0..m).map(|j| t[j] * y[j][b]).sum())
                .collect();
            (0..m)
                .map(|j| {
                    (0..k).map(|b| f[b] * y[j][b]).sum::<f64>() * cubemap::texel_solid_angle(n, j)
                })
                .collect()
        })
        .collect()
}

/// `T̂·L` per pixel and channel (grey rows multiply every light channel),
/// times the albedo.
fn dense_image(
    recon: &[Vec<f64>],
    d: Dims,
    light: &[[f32; 3]],
    albedo: Option<&[f32]>,
) -> Vec<[f64; 3]> {
    let c = d.channels as usize;
    (0..d.pixels())
        .map(|p| {
            [0, 1, 2].map(|ch| {
                let r = if c == 3 { 3 * p + ch } else { p };
                let v: f64 = (0..d.lights())
                    .map(|j| recon[r][j] * light[j][ch] as f64)
                    .sum();
                albedo.map_or(v, |al| v * al[3 * p + ch] as f64)
            })
        })
        .collect()
}

fn assert_close(got: &Frame, want: &[[f64; 3]], what: &str) {
    let scale = want.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
    for (p, (g, w)) in got.image.data.iter().zip(want).enumerate() {
        for ch in 0..3 {
            assert!(
                (g[ch] as f64 - w[ch]).abs() <= 1e-6 * scale + 1e-30,
                "{what} pixel {p} channel {ch}: {} vs {}",
                g[ch],
                w[ch]
            );
        }
    }
}

/// Relights at every order up to 4 and compares with `T̂_L·L` formed
/// densely.
fn check_sh_relight(d: Dims, albedo: Option<Vec<f32>>) {
    let dir = tempfile::tempdir().unwrap();
    let t = random_matrix(d, 5);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("t.raw"),
        d,
        &t,
        albedo.as_deref(),
        block_bytes(d, 3),
    ))
    .unwrap();
    let relighter = BasisRelighter::sh(ShProjection::fit(&raw, 4).unwrap(), &raw).unwrap();
    assert_eq!(relighter.max_terms(), 4);
    let n = d.face_res() as usize;
    let light = random_light(d.lights());
    let a = dense(&raw);
    let mut frame = relighter.frame().unwrap();
    for order in 0..=4 {
        let want = dense_image(&dense_sh(&a, n, order), d, &light, albedo.as_deref());
        let request = Request {
            terms: order,
            weighting: Weighting::Transport,
        };
        let stats = relighter.relight(&light, &request, &mut frame).unwrap();
        assert_eq!(stats.lights, order * order);
        let scale = want.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
        assert!(order == 0 || scale > 0.0);
        assert_close(&frame, &want, &format!("order {order}"));
    }
    let five = Request {
        terms: 5,
        weighting: Weighting::Unweighted,
    };
    let e = relighter.relight(&light, &five, &mut frame).unwrap_err();
    assert!(e.to_string().contains("order = 5") && e.to_string().contains("0..=4"));
    let two = Request { terms: 2, ..five };
    assert!(relighter.relight(&light[1..], &two, &mut frame).is_err());
}

/// A basis relighter's frames are charged to the limits its raw store was
/// opened with (not the machine's budget): a budget that holds the store's
/// tables but not a frame's image refuses the frame, naming it.
#[test]
fn frames_are_charged_to_the_stores_limits() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims(48, 32, 2, 3);
    let t = random_matrix(d, 7);
    let path = write_raw(&dir.path().join("t.raw"), d, &t, None, block_bytes(d, 3));
    let roomy = RawStore::open_with_limits(&path, &Limits::with_max_alloc(1 << 30)).unwrap();
    let tables = roomy.limits().used_bytes();
    let projection = ShProjection::fit(&roomy, 2).unwrap();
    let light = random_light(d.lights());
    let request = Request {
        terms: 2,
        weighting: Weighting::Transport,
    };
    // The image is 48·32·12 bytes: 18 KiB.
    let tight = RawStore::open_with_limits(&path, &Limits::with_max_alloc(tables + 4096)).unwrap();
    let relighter = BasisRelighter::sh(projection.clone(), &tight).unwrap();
    let err = relighter
        .frame()
        .and_then(|mut f| relighter.relight(&light, &request, &mut f).map(drop))
        .unwrap_err()
        .to_string();
    assert!(err.contains("relit image"), "{err}");
    let relighter = BasisRelighter::sh(projection, &roomy).unwrap();
    let mut frame = relighter.frame().unwrap();
    relighter.relight(&light, &request, &mut frame).unwrap();
}

#[test]
fn sh_relight_matches_dense_product_rgb() {
    check_sh_relight(dims(5, 4, 4, 3), None);
}

#[test]
fn sh_relight_matches_dense_product_grey_albedo() {
    let d = dims(5, 4, 4, 1);
    let albedo: Vec<f32> = (0..3 * d.pixels())
        .map(|i| 0.2 + 0.03 * (i % 17) as f32)
        .collect();
    check_sh_relight(d, Some(albedo));
}

#[test]
fn pca_relight_matches_dense_product_and_full_rank_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims(4, 3, 2, 1); // 12 rows, 24 lights
    let albedo: Vec<f32> = (0..3 * d.pixels()).map(|i| 0.5 + 0.01 * i as f32).collect();
    let t = random_matrix(d, 3);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("t.raw"),
        d,
        &t,
        Some(&albedo),
        block_bytes(d, 2),
    ))
    .unwrap();
    let basis = PcaBasis::fit(&raw, 6, 1).unwrap();
    let relighter = BasisRelighter::pca(&basis, &raw).unwrap();
    let light = random_light(d.lights());
    let (a, m) = (dense(&raw), d.lights());
    let v = basis.vectors();
    let mut frame = Frame::default();
    for k in 0..=6 {
        // T̂_k = (T·V_k)·V_kᵀ.
        let recon: Vec<Vec<f64>> = a
            .iter()
            .map(|t| {
                let c: Vec<f64> = (0..k)
                    .map(|i| (0..m).map(|j| t[j] * v[i * m + j]).sum())
                    .collect();
                (0..m)
                    .map(|j| (0..k).map(|i| c[i] * v[i * m + j]).sum())
                    .collect()
            })
            .collect();
        let want = dense_image(&recon, d, &light, Some(&albedo));
        let request = Request {
            terms: k,
            weighting: Weighting::Area,
        };
        let stats = relighter.relight(&light, &request, &mut frame).unwrap();
        assert_eq!((stats.lights, stats.nonzeros), (k, 12 * k as u64));
        assert_close(&frame, &want, &format!("rank {k}"));
    }
    let seven = Request {
        terms: 7,
        weighting: Weighting::Area,
    };
    assert!(relighter.relight(&light, &seven, &mut frame).is_err());

    // At full rank the basis spans every row: the image is T·L.
    let full = BasisRelighter::pca(&PcaBasis::fit(&raw, 12, 1).unwrap(), &raw).unwrap();
    let request = Request { terms: 12, ..seven };
    full.relight(&light, &request, &mut frame).unwrap();
    let exact = reference(&raw, &light).unwrap();
    let err = relative_l2(&frame.image, &exact).unwrap();
    assert!(err < 1e-6, "full-rank PCA relit error {err}");

    // A basis fitted to another store is refused.
    let d2 = dims(3, 4, 2, 1);
    let dir2 = tempfile::tempdir().unwrap();
    let raw2 = RawStore::open(&write_raw(
        &dir2.path().join("t.raw"),
        d2,
        &t,
        None,
        block_bytes(d2, 2),
    ))
    .unwrap();
    assert!(BasisRelighter::pca(&basis, &raw2).is_err());
}

#[test]
fn three_relighters_behind_one_trait_share_a_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims(8, 6, 4, 3);
    let t = random_matrix(d, 11);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("t.raw"),
        d,
        &t,
        None,
        block_bytes(d, 5),
    ))
    .unwrap();
    let ltm = dir.path().join("t.ltm");
    compress(
        &raw,
        &ltm,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let relighters: Vec<Box<dyn Relight + Send + Sync>> = vec![
        Box::new(Relighter::open(&ltm).unwrap()),
        Box::new(BasisRelighter::pca(&PcaBasis::fit(&raw, 8, 2).unwrap(), &raw).unwrap()),
        Box::new(BasisRelighter::sh(ShProjection::fit(&raw, 3).unwrap(), &raw).unwrap()),
    ];
    let light = random_light(d.lights());
    // One frame through every relighter, twice: each image equals the one
    // from the relighter's own frame.
    let mut shared = Frame::default();
    for _ in 0..2 {
        for r in &relighters {
            assert_eq!((r.lights(), r.size()), (d.lights(), (8, 6)));
            let request = Request {
                terms: r.max_terms(),
                weighting: Weighting::Transport,
            };
            let mut own = r.frame().unwrap();
            r.relight(&light, &request, &mut own).unwrap();
            r.relight(&light, &request, &mut shared).unwrap();
            assert_eq!(own.image, shared.image);
        }
    }
}
