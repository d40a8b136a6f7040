//! Re-encodes every range-codable column of an `.ltm` file with column
//! encodings 3 and 4 and prints, for each, the payload bytes per kept
//! coefficient and the single-threaded decode time (the fastest of
//! `ROUNDS` rounds, default 5, alternating the encodings).
//!
//! ```sh
//! cargo run --release -p ltm-codec --example recode -- FILE.ltm
//! ```
//!
//! `ONLY=3` or `ONLY=4` decodes one encoding only (for a profiler), and
//! `COLS=K` takes the first `K` columns.

use ltm_codec::entropy::{decode, encode, ColumnShape, ValueCoding};
use ltm_codec::{LtmFile, SparseColumn};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: recode FILE.ltm")?;
    let env = |name: &str| std::env::var(name).ok();
    let file = LtmFile::open(std::path::Path::new(&path))?;
    let shape = ColumnShape::of(file.meta());
    let count = env("COLS").map_or(Ok(file.columns().len()), |k| k.parse())?;
    let cols = (0..count.min(file.columns().len()))
        .map(|j| file.column(j))
        .collect::<Result<Vec<_>, _>>()?;
    let nnz: usize = cols.iter().map(|c| c.indices.len()).sum();
    let codings = [(3, ValueCoding::ExpGolomb), (4, ValueCoding::Classes)];
    let mut best = [f64::INFINITY; 2];
    let rounds = env("ROUNDS").map_or(Ok(5), |r| r.parse())?;
    for _ in 0..rounds {
        for (k, &(encoding, coding)) in codings.iter().enumerate() {
            if env("ONLY").is_some_and(|o| o != encoding.to_string()) {
                continue;
            }
            let payloads: Vec<Option<Vec<u8>>> = cols
                .iter()
                .map(|c| {
                    (!c.indices.is_empty())
                        .then(|| encode(c, &shape, coding))
                        .flatten()
                })
                .collect();
            let start = Instant::now();
            decode_all(&cols, &payloads, &shape, coding)?;
            best[k] = best[k].min(start.elapsed().as_secs_f64());
            let bytes: usize = payloads.iter().flatten().map(Vec::len).sum();
            println!(
                "encoding {encoding}: {bytes} bytes, {:.3} bytes per coefficient, decode {:.3} s ({:.1} ns per coefficient; fastest round so far)",
                bytes as f64 / nnz as f64,
                best[k],
                best[k] * 1e9 / nnz as f64,
            );
        }
    }
    Ok(())
}

/// Decodes every payload and checks it against its column.
#[inline(never)]
fn decode_all(
    cols: &[SparseColumn],
    payloads: &[Option<Vec<u8>>],
    shape: &ColumnShape,
    coding: ValueCoding,
) -> Result<(), Box<dyn std::error::Error>> {
    for (c, p) in cols.iter().zip(payloads) {
        if let Some(p) = p {
            let back = decode(p, c.indices.len(), shape, c.depth, coding)?;
            if &back != c {
                return Err("a column decoded differently".into());
            }
        }
    }
    Ok(())
}
