//! The near-field frame rate of a file (issue's speed check): the median
//! time of a frame of the Mitsuba check's softbox (0.8 × 0.6 at
//! (0.15, 0.25), intensity 4) by the wavelet method, at 1 % source and 20 %
//! target terms unless said, and by the exact method, on every thread
//! rayon has.
//!
//! ```text
//! cargo run --release --example nearfield_frames -- FILE.ltm [FRAMES [IMAGE.f32 [SOURCE TARGET]]]
//! ```
//!
//! FRAMES (default 31) frames each. IMAGE (`-` for none) receives the
//! wavelet image as little-endian f32 RGB, row after row, for comparing
//! builds. SOURCE and TARGET are the shares of terms (0, 1].

#[path = "common/softbox.rs"]
mod softbox;

use ltm::relight::nearfield::{NearField, NearFieldMethod, NearFieldTerms, Targets};
use softbox::{relative_l2, softbox_light, time, Outcome, WAVELET_1_20};

fn main() -> Outcome<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        return Err("usage: nearfield_frames FILE.ltm [FRAMES [IMAGE.f32 [SOURCE TARGET]]]".into());
    };
    let frames = args.get(1).map(|n| n.parse()).transpose()?.unwrap_or(31);
    let limits = ltm::Limits::default();
    let mut file = ltm::LtmFile::open(std::path::Path::new(path))?;
    let near = NearField::take(&mut file, &limits)?;
    let light = softbox_light()?;
    let method = match (args.get(3), args.get(4)) {
        (Some(source), Some(target)) => NearFieldMethod::Wavelet(NearFieldTerms {
            source: source.parse()?,
            targets: Targets::Share(target.parse()?),
        }),
        _ => WAVELET_1_20,
    };
    let (wavelet_ms, wavelet) = time(&near, &light, method, frames)?;
    let (exact_ms, exact) = time(&near, &light, NearFieldMethod::Exact, frames)?;
    println!(
        "{path}: wavelet {method:?}: {wavelet_ms:.2} ms ({:.1} frames/s), relative L2 {:.4} against the exact method's {exact_ms:.2} ms ({:.1} frames/s); medians of {frames}",
        1e3 / wavelet_ms,
        relative_l2(&wavelet, &exact),
        1e3 / exact_ms
    );
    if let Some(out) = args.get(2).filter(|o| *o != "-") {
        let bytes: Vec<u8> = wavelet
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        std::fs::write(out, bytes)?;
    }
    Ok(())
}
