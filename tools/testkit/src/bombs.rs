//! Small files that claim huge matrices, for the memory-budget tests.

use ltm_codec::column::{EncodedColumn, SparseColumn};
use ltm_codec::compress::Mode;
use ltm_codec::container::{LtmWriter, Meta};
use ltm_codec::{Dims, Filter};
use std::path::{Path, PathBuf};

/// Writes `DIR/claims-8192.ltm`: an 8192² grey image file of six lights
/// (face resolution 1), one coefficient per column, a few hundred bytes
/// whose frames would need gigabytes.
pub fn ltm_claiming_8192(dir: &Path) -> PathBuf {
    let dims = Dims::image(8192, 8192, 1, 1);
    let meta = Meta {
        dims,
        mode: Mode::Adaptive,
        row_filter: Filter::Haar,
        col_filter: Filter::LeGall53,
        bits: 12,
        seed: 0,
        target_error: 0.1,
        achieved_error: 0.1,
        terms: 0,
        norm: 1.0,
    };
    let path = dir.join("claims-8192.ltm");
    let mut writer = LtmWriter::create(&path, meta, None).unwrap();
    let columns = (0..dims.lights())
        .map(|j| {
            let col = SparseColumn {
                depth: 0,
                // Scale 2^((32768 − 32768)/256) = 1.
                scale_codes: vec![32768],
                indices: vec![j as u32],
                values: vec![100],
            };
            EncodedColumn::new(&col, 1, 3)
        })
        .collect();
    writer.push_columns(0, columns).unwrap();
    writer.finish(0.1).unwrap();
    let len = std::fs::metadata(&path).unwrap().len();
    assert!(len < 1024, "the crafted file has {len} bytes");
    path
}
