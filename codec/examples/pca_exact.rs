//! The uncentred PCA baseline's randomized rank errors against the exact
//! ones (the eigenvalues of the dense Gram matrix `AᵀA` of the (pixel,
//! channel) rows) on a raw store with few lights (at most 6144):
//!
//! ```sh
//! cargo run --release -p ltm-codec --example pca_exact -- STORE.raw [RANK]
//! ```
//!
//! Prints, for ranks 1, 2, 4, … up to RANK (default 256), both errors and
//! their ratio; the randomized error may not be below the exact one, and
//! should stay within a few per cent of it.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par, Side};
use ltm_codec::{PcaBasis, RawStore};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .ok_or("usage: pca_exact STORE.raw [RANK]")?;
    let rank: usize = std::env::args().nth(2).map_or(Ok(256), |r| r.parse())?;
    let raw = RawStore::open(Path::new(&path))?;
    let dims = raw.dims();
    let (m, c) = (dims.lights(), dims.channels as usize);
    if m > 6144 {
        return Err(format!("{m} lights: the dense Gram matrix needs at most 6144").into());
    }
    let mut gram = Mat::<f64>::zeros(m, m);
    let mut norm2 = 0.0;
    let step = (1 << 22) / (m * c).max(1);
    let mut rows = Vec::new();
    for start in (0..dims.pixels()).step_by(step.max(1)) {
        let end = (start + step.max(1)).min(dims.pixels());
        raw.read_rows(start..end, &mut rows)?;
        let n = (end - start) * c;
        let a = Mat::<f64>::from_fn(n, m, |r, j| rows[((r / c) * m + j) * c + r % c] as f64);
        norm2 += rows.iter().map(|&v| v as f64 * v as f64).sum::<f64>();
        matmul(
            gram.as_mut(),
            Accum::Add,
            a.transpose(),
            a.as_ref(),
            1.0,
            Par::rayon(0),
        );
    }
    let mut eig = gram
        .as_ref()
        .self_adjoint_eigenvalues(Side::Lower)
        .map_err(|e| format!("eigenvalues: {e:?}"))?;
    eig.reverse();
    let rank = rank.min(m.min(dims.pixels() * c));
    let basis = PcaBasis::fit(&raw, rank, 1)?;
    let mut k = 1;
    while k <= rank {
        let error = basis.rank_errors()[k];
        let exact = (eig[k..].iter().sum::<f64>().max(0.0) / norm2).sqrt();
        println!(
            "rank {k:4}: randomized {error:.6}, exact {exact:.6}, ratio {:.5}",
            error / exact
        );
        k *= 2;
    }
    Ok(())
}
