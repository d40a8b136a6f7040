//! What every fuzz target runs: a file given as bytes goes through the
//! decoder's public entry points as an embedding program would use them.

use ltm_codec::{ColumnDecoder, Limits, LtmFile};

/// The budget of a run: small enough that a hostile header cannot slow
/// the fuzzer down.
const BUDGET: u64 = 64 << 20;

/// Opens `bytes` with [`LtmFile::from_bytes`], reads every column and, for
/// small images, decodes it to the pixel domain with [`ColumnDecoder`]. Any
/// outcome but a panic is fine.
pub fn decode_through_public_api(bytes: &[u8]) {
    let limits = Limits::with_max_alloc(BUDGET);
    let Ok(file) = LtmFile::from_bytes(bytes, &limits) else {
        return;
    };
    let dims = file.meta().dims;
    if let (Some(surface), false) = (file.surface(), dims.rows.is_texture()) {
        // Image rows' surface records fix their camera's eye, or are
        // refused: a recovered eye is finite.
        if let Ok(camera) = ltm_codec::ImageCamera::recover(surface, dims.width() as usize) {
            assert!(camera.eye().iter().all(|v| v.is_finite()));
        }
    }
    if let Some(model) = file.pca() {
        // A pca file: reconstruct its first rows (every value must be
        // finite or the decode an error, never a panic).
        let mut rows = Vec::new();
        let _ = model.reconstruct_rows(0, dims.pixels().min(16), &mut rows);
        return;
    }
    let Ok(decoder) = ColumnDecoder::for_file(&file, &limits) else {
        return;
    };
    let small = dims.pixels() <= 1 << 12;
    let mut plane = vec![0.0f32; if small { dims.pixels() } else { 0 }];
    let mut work = plane.clone();
    for j in 0..file.columns().len() {
        let Ok(col) = file.column(j) else { continue };
        if small {
            for c in 0..dims.channels as usize {
                let _ = decoder.decode(&col, c, &mut plane, &mut work);
            }
        }
    }
}

/// Writes `bytes` to a temporary file, opens it with
/// [`ltm_codec::RawStore::open_with_limits`] and, when it opens, verifies
/// every block and reads every row and its zero flag.
pub fn read_raw_store(bytes: &[u8]) {
    let Ok(dir) = tempfile::tempdir() else { return };
    let path = dir.path().join("f.raw");
    if std::fs::write(&path, bytes).is_err() {
        return;
    }
    let Ok(raw) = ltm_codec::RawStore::open_with_limits(&path, &Limits::with_max_alloc(BUDGET)) else {
        return;
    };
    for b in 0..raw.header().block_count() {
        let _ = raw.verify_block(b);
    }
    for p in 0..raw.dims().pixels() {
        let _ = (raw.read_row(p).map(|r| r.len()), raw.is_zero_row(p));
    }
    let _ = raw.albedo();
}

/// Writes `bytes` to a file and reads it as each file of a sharded
/// compression: a coded part (`read_coded_header`: framing, checksums,
/// header and every column record), a plan and an analysis part (JSON,
/// every field validated). Each must give a value or an error.
pub fn read_shard_files(bytes: &[u8]) {
    use ltm_codec::compress::shard::{read_coded_header, read_json, AnalysisPart, PlanFile};
    let Ok(dir) = tempfile::tempdir() else { return };
    let path = dir.path().join("f.part");
    if std::fs::write(&path, bytes).is_err() {
        return;
    }
    let limits = Limits::with_max_alloc(BUDGET);
    let _ = read_coded_header(&path, &limits).map(|h| h.columns.len());
    let _ = read_json::<PlanFile>(&path, &limits).map(|p| p.step.plan.columns());
    let _ = read_json::<AnalysisPart>(&path, &limits).map(|a| a.columns);
}

/// A valid `pca` file of a small matrix (10×7 pixels, n = 2, RGB, rank 4),
/// made once per process, for the `pca_decode` target to mutate.
pub fn small_pca_file() -> Option<Vec<u8>> {
    static FILE: std::sync::OnceLock<Option<Vec<u8>>> = std::sync::OnceLock::new();
    FILE.get_or_init(|| {
        let dir = tempfile::tempdir().ok()?;
        let dims = ltm_codec::Dims::image(10, 7, 2, 3);
        let t: Vec<f32> = (0..dims.pixels() * dims.row_len())
            .map(|i| ((i % 37) as f32 * 0.3).sin().abs() * 1e-2)
            .collect();
        let header = ltm_codec::RawHeader::new(dims, false, 1 << 16);
        let raw = ltm_codec::RawWriter::write_dense(&dir.path().join("t.raw"), header, &t, None).ok()?;
        let raw = ltm_codec::RawStore::open(&raw).ok()?;
        let out = dir.path().join("t.ltm");
        let opts = ltm_codec::PcaOptions {
            rank: Some(4),
            ..Default::default()
        };
        ltm_codec::compress_pca(&raw, &out, &opts, ltm_codec::Progress::NONE).ok()?;
        std::fs::read(&out).ok()
    })
    .clone()
}
