//! Times the report's baselines on a raw store: lossless zstd of the raw
//! matrix, the spherical-harmonics fit at orders 2 to 20, and one frame
//! relit from the order-20 projection (with its error against the exact
//! image under uniform light).
//!
//! `cargo run --release -p ltm-tools --example baseline_timing -- RAW`
//! (`RAW`: a raw store, e.g. from `ltm bake`).

#[path = "../src/report/baselines.rs"]
mod baselines;

use ltm_codec::RawStore;
use ltm_relight::{reference, relative_l2, BasisRelighter, Relight, Request, Weighting};
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let Some(path) = std::env::args().nth(1) else {
        anyhow::bail!("usage: baseline_timing RAW (a raw store)");
    };
    let raw = RawStore::open(std::path::Path::new(&path))?;
    println!(
        "{path}: {:?}, {} threads",
        raw.dims(),
        rayon::current_num_threads()
    );
    let t0 = Instant::now();
    let z = baselines::zstd_raw(&raw, 3)?;
    println!(
        "zstd-raw level 3: {:.2} s, {z:?}",
        t0.elapsed().as_secs_f64()
    );
    let t0 = Instant::now();
    let (points, projection) = baselines::sh(&raw, &(2..=20).collect::<Vec<_>>())?;
    println!("sh: {:.2} s", t0.elapsed().as_secs_f64());
    for p in &points {
        println!("  {p:?}");
    }
    let relighter = BasisRelighter::sh(projection, &raw)?;
    let light = vec![[1.0f32; 3]; raw.dims().lights()];
    let mut frame = relighter.frame()?;
    let request = Request {
        terms: 20,
        weighting: Weighting::Transport,
    };
    let stats = relighter.relight(&light, &request, &mut frame)?;
    let exact = reference(&raw, &light)?;
    println!(
        "sh relight order 20: {:.3} s, image error under uniform light {:.4}",
        stats.total().as_secs_f64(),
        relative_l2(&frame.image, &exact)?
    );
    Ok(())
}
