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

use ltm::relight::nearfield::{
    acc, AccTable, AreaLight, LightTexture, NearField, NearFieldMethod, NearFieldTerms, Placement,
    Targets,
};
use std::error::Error;
use std::sync::Arc;
use std::time::Instant;

type Outcome<T> = Result<T, Box<dyn Error>>;

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

fn softbox() -> Result<LightTexture, Box<dyn Error>> {
    let (w, h) = (64usize, 48usize);
    let mut texels = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (u, v) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
            let left = u < 0.5;
            let mut t = [
                if left { 1.6 } else { 0.5 },
                0.9,
                if left { 0.4 } else { 1.5 },
            ];
            if ((v * 6.0).floor() as i32) % 2 == 1 && u > 0.2 && u < 0.8 {
                t.iter_mut().for_each(|c| *c *= 0.15);
            }
            if (u - 0.8).powi(2) + (v - 0.2).powi(2) < 0.01 {
                t = [6.0, 6.0, 5.0];
            }
            texels.push(t);
        }
    }
    Ok(LightTexture::new(w, h, texels)?)
}

/// Median frame time in ms of `frames` renders, and the last image.
fn time(
    near: &NearField,
    light: &AreaLight,
    method: NearFieldMethod,
    frames: usize,
) -> Outcome<(f64, Vec<[f32; 3]>)> {
    let mut times = Vec::with_capacity(frames);
    let mut image = Vec::new();
    for _ in 0..frames {
        let start = Instant::now();
        image = near.render(std::slice::from_ref(light), method)?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok((times[frames / 2], image))
}

fn relative_l2(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let (mut e, mut n) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
        e += (f64::from(*x) - f64::from(*y)).powi(2);
        n += f64::from(*y).powi(2);
    }
    (e / n.max(f64::MIN_POSITIVE)).sqrt()
}

fn frames(path: &str, frames: usize) -> Result<(), Box<dyn Error>> {
    let limits = ltm::Limits::default();
    let mut file = ltm::LtmFile::open(std::path::Path::new(path))?;
    let mut near = NearField::take(&mut file, &limits)?;
    let light = AreaLight {
        texture: softbox()?,
        placement: Placement {
            center: [0.15, 0.25],
            size: [0.8, 0.6],
            intensity: 4.0,
        },
    };
    let wavelet = NearFieldMethod::Wavelet(NearFieldTerms {
        source: 0.01,
        targets: Targets::Share(0.2),
    });
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
