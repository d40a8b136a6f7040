//! The files of a sharded compression through the library
//! (`compress::shard`): a run in three shards assembles the file
//! `compress` writes; every single-byte change of a coded part is refused
//! (its checksums), and with its checksums recomputed it is refused or
//! assembles into a file that opens, never a panic.

use ltm_codec::compress::shard::{
    analyze_shard, assemble, code_shard, merge_analyses, plan_first, plan_next, read_coded_header,
};
use ltm_codec::compress::{compress, CodeOptions, CompressOptions, Target, TransposeOptions};
use ltm_codec::{Dims, Limits, Progress, RawStore};
use std::path::{Path, PathBuf};

/// A small matrix with structure: smooth in pixels and lights, some
/// empty rows.
fn matrix(dims: Dims) -> Vec<f32> {
    let (p, m, c) = (dims.pixels(), dims.lights(), dims.channels as usize);
    (0..p * m * c)
        .map(|i| {
            let (row, j) = (i / (m * c), (i / c) % m);
            if row % 11 == 3 {
                0.0
            } else {
                (((row * 7 + j * 3) % 23) as f32 * 0.1).sin().abs() * 1e-2 + 1e-4
            }
        })
        .collect()
}

/// [`matrix`] of `dims` as the raw store `dir/m.raw`.
fn store(dir: &Path, dims: Dims) -> RawStore {
    let path = ltm_testkit::write_raw(&dir.join("m.raw"), dims, &matrix(dims), None, 1 << 14);
    RawStore::open(&path).unwrap()
}

/// Runs the stages in `shards` shards in `dir` (one plan per coding until
/// the loop keeps one): the last coding's parts.
fn sharded(raw: &RawStore, opts: &CodeOptions, shards: u64, dir: &Path) -> Vec<PathBuf> {
    let transpose = TransposeOptions::default();
    let limits = Limits::default();
    let parts: Vec<(PathBuf, _)> = (0..shards)
        .map(|i| {
            let part = analyze_shard(raw, &transpose, opts, (i, shards), Progress::NONE).unwrap();
            (dir.join(format!("a-{i}.json")), part)
        })
        .collect();
    let (run, analysis) = merge_analyses(parts).unwrap();
    let mut plan = Some(plan_first(&run, analysis.as_ref()).unwrap());
    let mut coded = Vec::new();
    let mut k = 0;
    while let Some(p) = plan {
        k += 1;
        coded = (0..shards)
            .map(|i| {
                let out = dir.join(format!("c-{k}-{i}.part"));
                code_shard(raw, &transpose, &p, i, &out, Progress::NONE).unwrap();
                out
            })
            .collect();
        plan = plan_next(&run, analysis.as_ref(), &coded, &limits).unwrap();
    }
    coded
}

/// Recomputes the section and trailer checksums of a coded part
/// (docs/FORMAT.md, "Coded part").
fn repair(b: &mut [u8]) {
    let t = b.len() - 48;
    let len =
        |i: usize| u64::from_le_bytes(b[t + 8 * i..t + 8 * i + 8].try_into().unwrap()) as usize;
    let (payloads, measures, header) = (len(0), len(1), len(2));
    let sections = [16..16 + payloads, 16 + payloads..16 + payloads + measures];
    let header_at = 16 + payloads + measures;
    let crcs = [
        crc32fast::hash(&b[sections[0].clone()]),
        crc32fast::hash(&b[sections[1].clone()]),
        crc32fast::hash(&b[header_at..header_at + header]),
    ];
    for (i, crc) in crcs.iter().enumerate() {
        b[t + 24 + 4 * i..t + 28 + 4 * i].copy_from_slice(&crc.to_le_bytes());
    }
    let crc = crc32fast::hash(&b[t..t + 36]);
    b[t + 36..t + 40].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn three_shards_assemble_the_file_of_one_machine() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(20, 14, 4, 3);
    let raw = store(dir.path(), dims);
    let opts = CodeOptions {
        target: Target::MaxError(0.02),
        ..Default::default()
    };
    let one = dir.path().join("one.ltm");
    compress(
        &raw,
        &one,
        &CompressOptions::from(opts.clone()),
        Progress::NONE,
    )
    .unwrap();
    let coded = sharded(&raw, &opts, 3, dir.path());
    let out = dir.path().join("sharded.ltm");
    assemble(&coded, &out, &Limits::default()).unwrap();
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&out).unwrap());
}

#[test]
fn damaged_coded_parts_are_refused_or_read_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(12, 9, 2, 1);
    let raw = store(dir.path(), dims);
    let opts = CodeOptions {
        target: Target::MaxError(0.05),
        ..Default::default()
    };
    let coded = sharded(&raw, &opts, 2, dir.path());
    let good = std::fs::read(&coded[1]).unwrap();
    let limits = Limits::with_max_alloc(64 << 20);
    let bad = dir.path().join("bad.part");
    let out = dir.path().join("out.ltm");
    let (mut tried, mut repaired_refused) = (0, 0);
    let parts = [coded[0].clone(), bad.clone()];
    for i in (0..good.len()).step_by(3) {
        let mut b = good.clone();
        b[i] ^= 0x5a;
        std::fs::write(&bad, &b).unwrap();
        // Checksums as they are: every change is caught (the payloads'
        // when assembling).
        assert!(
            assemble(&parts, &out, &limits).is_err(),
            "byte {i} changed, assembled"
        );
        assert!(!out.exists());
        tried += 1;
        // Checksums recomputed: the structure behind them is checked, and
        // what assembles is a file that opens.
        if (16..good.len() - 48).contains(&i) {
            repair(&mut b);
            std::fs::write(&bad, &b).unwrap();
            let _ = read_coded_header(&bad, &limits);
            match assemble(&parts, &out, &limits) {
                Err(_) => repaired_refused += 1,
                Ok(_) => assert!(ltm_codec::LtmFile::open(&out).is_ok(), "byte {i}"),
            }
            let _ = std::fs::remove_file(&out);
        }
    }
    // Forged parts (checksums recomputed) are checked field by field: some
    // are refused, and those that assemble give files that open.
    assert!(repaired_refused > 0, "{repaired_refused} of {tried}");
    for cut in [0, 1, 15, 63, good.len() / 2, good.len() - 1] {
        std::fs::write(&bad, &good[..cut]).unwrap();
        assert!(read_coded_header(&bad, &limits).is_err(), "cut at {cut}");
    }
}
