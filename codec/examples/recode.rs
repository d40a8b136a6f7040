//! Re-encodes every range-codable column of an `.ltm` file with column
//! encodings 3, 4, 5 and 6 and prints, for each, the payload bytes per
//! kept coefficient and the single-threaded decode time (the fastest of
//! `ROUNDS` rounds, default 5, alternating the encodings). Encoding 6
//! starts from priors tallied from the file's own columns in encoding 5,
//! as `LtmWriter::finish` does; the time of that tally and of coding
//! encoding 6 (one thread) is printed once.
//!
//! ```sh
//! cargo run --release -p ltm-codec --example recode -- FILE.ltm
//! ```
//!
//! It first times the file's columns as stored (`LtmFile::column`: CRC,
//! payload decode and checks, one thread), so that a `--entropy zstd`
//! file and a range-coded one of the same matrix compare directly.
//!
//! `ONLY=3` (or 4, 5, 6) decodes one encoding only (for a profiler;
//! `ONLY=stored` the stored columns only), and `COLS=K` takes the first
//! `K` columns.

use ltm_codec::entropy::{
    decode, encode, encode_primed, ColumnShape, PriorTally, Priors, ValueCoding,
};
use ltm_codec::{LtmFile, SparseColumn};
use std::time::Instant;

type Payloads = Vec<Option<Vec<u8>>>;

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
    let rounds = env("ROUNDS").map_or(Ok(5), |r| r.parse())?;
    let stored = (0..rounds)
        .map(|_| {
            let start = Instant::now();
            (0..cols.len()).try_for_each(|j| file.column(j).map(drop))?;
            Ok(start.elapsed().as_secs_f64())
        })
        .collect::<Result<Vec<f64>, ltm_codec::Error>>()?;
    let stored = stored.iter().copied().fold(f64::INFINITY, f64::min);
    println!(
        "as stored: {nnz} coefficients in {} columns, decode {stored:.4} s ({:.1} ns per coefficient; fastest of {rounds})",
        cols.len(),
        stored * 1e9 / nnz as f64
    );
    println!(
        "the range decoder alone: {:.2} ns per adaptive binary decision (4 M bits, p(1) = 0.1, 8 contexts; fastest of {rounds})",
        decision_ns(rounds)?
    );
    if env("ONLY").is_some_and(|o| o == "stored") {
        return Ok(());
    }
    let (priors, primed) = prime(&cols, &shape)?;
    let codings = [
        (3, ValueCoding::ExpGolomb),
        (4, ValueCoding::Classes),
        (5, ValueCoding::Compact),
        (6, ValueCoding::Primed),
    ];
    let mut best = [f64::INFINITY; 4];
    for _ in 0..rounds {
        for (k, &(encoding, coding)) in codings.iter().enumerate() {
            if env("ONLY").is_some_and(|o| o != encoding.to_string()) {
                continue;
            }
            let payloads = match coding {
                ValueCoding::Primed => primed.clone(),
                _ => encode_each(&cols, |c| encode(c, &shape, coding)),
            };
            let start = Instant::now();
            decode_all(&cols, &payloads, &shape, coding, &priors)?;
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

/// Each nonempty column's payload by `code`.
fn encode_each(cols: &[SparseColumn], code: impl Fn(&SparseColumn) -> Option<Vec<u8>>) -> Payloads {
    cols.iter()
        .map(|c| (!c.indices.is_empty()).then(|| code(c)).flatten())
        .collect()
}

/// The priors of the columns coded in encoding 5, and the columns in
/// encoding 6; prints the time of both steps (one thread).
fn prime(
    cols: &[SparseColumn],
    shape: &ColumnShape,
) -> Result<(Priors, Payloads), Box<dyn std::error::Error>> {
    let compact = encode_each(cols, |c| encode(c, shape, ValueCoding::Compact));
    let start = Instant::now();
    let mut tally = PriorTally::default();
    for (c, p) in cols.iter().zip(&compact) {
        if let Some(p) = p {
            tally.add_column(p, c.indices.len(), shape, c.depth)?;
        }
    }
    let priors = tally.priors();
    let tallied = start.elapsed().as_secs_f64();
    let primed = encode_each(cols, |c| encode_primed(c, shape, &priors));
    println!(
        "priors: tally {tallied:.3} s, encoding 6 {:.3} s (one thread)",
        start.elapsed().as_secs_f64() - tallied
    );
    Ok((priors, primed))
}

/// Decodes every payload and checks it against its column.
#[inline(never)]
fn decode_all(
    cols: &[SparseColumn],
    payloads: &[Option<Vec<u8>>],
    shape: &ColumnShape,
    coding: ValueCoding,
    priors: &Priors,
) -> Result<(), Box<dyn std::error::Error>> {
    for (c, p) in cols.iter().zip(payloads) {
        if let Some(p) = p {
            let back = decode(p, c.indices.len(), shape, c.depth, coding, Some(priors))?;
            if &back != c {
                return Err("a column decoded differently".into());
            }
        }
    }
    Ok(())
}

/// The decoder's time per binary decision with nothing around it: the
/// floor under a column's decode, whose decisions depend on each other.
fn decision_ns(rounds: usize) -> Result<f64, Box<dyn std::error::Error>> {
    use ltm_codec::entropy::range::{Context, Decoder, Encoder};
    let n = 1 << 22;
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    let bits: Vec<bool> = (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x.is_multiple_of(10)
        })
        .collect();
    let mut enc = Encoder::new();
    let mut ctx = [Context::default(); 8];
    for (i, &b) in bits.iter().enumerate() {
        enc.bit(&mut ctx[i & 7], b);
    }
    let bytes = enc.finish();
    let mut best = f64::INFINITY;
    for _ in 0..rounds {
        let start = Instant::now();
        let mut dec = Decoder::new(&bytes)?;
        let mut ctx = [Context::default(); 8];
        let ones = (0..n).filter(|i| dec.bit(&mut ctx[i & 7])).count();
        best = best.min(start.elapsed().as_secs_f64());
        if ones != bits.iter().filter(|&&b| b).count() {
            return Err("the bits decoded differently".into());
        }
    }
    Ok(best * 1e9 / n as f64)
}
