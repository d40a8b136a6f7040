//! The memory-based coupling table of Sun and Ramamoorthi 2009, §5.3.2
//! (`ltm::relight::nearfield::AccTable`): its size, build time and lookup
//! error against resolution and order, and, given a file with near-field
//! rows, the wavelet method's frame time with couplings looked up against
//! couplings evaluated in closed form.
//!
//! ```text
//! cargo run --release --example acc_table -- [FILE.ltm [FRAMES]]
//! ```
//!
//! The light of the timing is the Mitsuba check's 64 × 48 softbox
//! (`tools/validate/mitsuba_nearfield.py`), 0.8 × 0.6 at (0.15, 0.25),
//! intensity 4, at 1 % source and 20 % target terms; FRAMES (default 30)
//! frames each, median.

#[path = "common/softbox.rs"]
mod softbox;

use ltm::relight::nearfield::{acc, AccTable, NearField, NearFieldMethod};
use softbox::{relative_l2, softbox_light, time, WAVELET_1_20};
use std::error::Error;
use std::sync::Arc;
use std::time::Instant;

/// The table resolutions reported: cells a face width.
const RESOLUTIONS: [usize; 4] = [16, 32, 64, 128];

/// The largest `|table − closed form|` over a fixed spread of `(s, o)` and
/// every source and target, relative to the two functions' amplitudes.
fn lookup_error(table: &AccTable) -> f64 {
    let order = table.order();
    let amplitude = |i: usize| {
        if i == 0 {
            1.0
        } else {
            (0.5 * (i as f64).log2().floor()).exp2()
        }
    };
    let (mut exact, mut looked_up) = (Vec::new(), Vec::new());
    let mut worst = 0.0f64;
    for a in 0..60 {
        let s = 10f64.powf(a as f64 / 20.0 - 1.5);
        for b in 0..40 {
            let o = (b as f64 + 0.37) / 40.0 * 1.4 - 0.2 - 0.5 * s;
            for i in 0..order {
                exact.clear();
                looked_up.clear();
                acc::couplings(i, order, s, o, &mut exact);
                table.couplings_where(i, s, o, |_| true, &mut looked_up);
                let mut dense = vec![0.0f64; order];
                exact.iter().for_each(|&(k, d)| dense[k as usize] += d);
                looked_up.iter().for_each(|&(k, d)| dense[k as usize] -= d);
                for (k, e) in dense.iter().enumerate() {
                    worst = worst.max(e.abs() / (amplitude(i) * amplitude(k)));
                }
            }
        }
    }
    worst
}

fn sizes() -> Result<(), Box<dyn Error>> {
    println!(
        "| order | cells a face width | nodes | entries | MB | build s | largest lookup error |"
    );
    println!("|---|---|---|---|---|---|---|");
    let limits = ltm::Limits::default();
    for order in [8, 16, 32, 64] {
        for cells in RESOLUTIONS {
            let start = Instant::now();
            let table = AccTable::new(order, cells, &limits)?;
            let secs = start.elapsed().as_secs_f64();
            println!(
                "| {order} | {cells} | {} | {} | {:.1} | {secs:.3} | {:.4} |",
                table.nodes(),
                table.entries(),
                table.bytes() as f64 / 1e6,
                lookup_error(&table)
            );
        }
    }
    Ok(())
}

fn frames(path: &str, frames: usize) -> Result<(), Box<dyn Error>> {
    let limits = ltm::Limits::default();
    let mut file = ltm::LtmFile::open(std::path::Path::new(path))?;
    let mut near = NearField::take(&mut file, &limits)?;
    let light = softbox_light()?;
    let wavelet = WAVELET_1_20;
    let (exact_ms, _) = time(&near, &light, NearFieldMethod::Exact, frames)?;
    let (closed_ms, closed) = time(&near, &light, wavelet, frames)?;
    println!("{path}: exact method {exact_ms:.1} ms; wavelet 1 % / 20 %, closed-form couplings {closed_ms:.1} ms");
    println!("| table cells | MB | build s | ms (median of {frames}) | relative L2 against closed-form couplings |");
    println!("|---|---|---|---|---|");
    for cells in RESOLUTIONS {
        let start = Instant::now();
        let table = AccTable::new(near.face().order, cells, &limits)?;
        let build = start.elapsed().as_secs_f64();
        let mb = table.bytes() as f64 / 1e6;
        near.set_coupling_table(Some(Arc::new(table)))?;
        let (ms, image) = time(&near, &light, wavelet, frames)?;
        println!(
            "| {cells} | {mb:.1} | {build:.3} | {ms:.1} | {:.3} % |",
            100.0 * relative_l2(&image, &closed)
        );
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    sizes()?;
    if let Some(path) = args.first() {
        let count = args.get(1).map(|n| n.parse()).transpose()?.unwrap_or(30);
        frames(path, count)?;
    }
    Ok(())
}
