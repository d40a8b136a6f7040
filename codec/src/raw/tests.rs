//! Tests of the raw store's writer and reader.

use super::*;
use crate::dims::Dims;
use crate::surface::Surface;

fn header(block_bytes: u64) -> RawHeader {
    RawHeader::new(Dims::image(6, 5, 2, 1), true, block_bytes)
}

fn fill(w: &mut RawWriter, blocks: &[usize], value: f32) {
    let h = *w.header();
    for &b in blocks {
        let n = h.block_range(b).len();
        w.write_block(
            b,
            &vec![value; n * h.dims.row_len()],
            Some(&vec![0.5; 3 * n]),
        )
        .unwrap();
    }
}

/// A version-2 store keeps its identity; a header without one is
/// written as version 1, as before, and both open.
#[test]
fn identity_round_trips_and_version_1_stays() {
    let dir = tempfile::tempdir().unwrap();
    for (name, h) in [
        ("v1.raw", header(200)),
        ("v2.raw", header(200).with_input_id([7; 32])),
    ] {
        let path = dir.path().join(name);
        let mut w = RawWriter::create(&path, h).unwrap();
        fill(&mut w, &(0..h.block_count()).collect::<Vec<_>>(), 1.0);
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
            h.version()
        );
        let store = RawStore::open(&path).unwrap();
        assert_eq!(*store.header(), h);
        for b in 0..h.block_count() {
            store.verify_block(b).unwrap();
        }
        let mut row = Vec::new();
        store.read_rows(29..30, &mut row).unwrap();
        assert_eq!(row[0], 1.0);
        // A truncated header is an error, not a panic.
        let cut = dir.path().join("cut.raw");
        std::fs::write(&cut, &bytes[..70]).unwrap();
        assert!(RawStore::open(&cut).is_err());
    }
}

fn surface(rows: usize) -> Surface {
    Surface::new(
        (0..rows)
            .map(|p| {
                if p % 3 == 1 {
                    crate::SurfacePoint::INVALID
                } else {
                    crate::SurfacePoint::new([p as f32, -1.0, 2.5], [0.0, 1.0, 0.0])
                }
            })
            .collect(),
    )
    .unwrap()
}

/// Version 3 stores the row layout and the surface data, with or
/// without an identity; a texture layout needs surface data.
#[test]
fn surface_and_row_layout_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let tex = Dims::texture(6, crate::Parameterization::Sphere, 2, 1);
    let plain = RawHeader::new(tex, true, 200);
    assert!(plain.has_surface && plain.version() == 3);
    for (name, h) in [
        ("tex.raw", plain),
        ("tex-id.raw", plain.with_input_id([9; 32])),
        ("img.raw", header(200).with_surface()),
    ] {
        let path = dir.path().join(name);
        let s = surface(h.dims.pixels());
        assert!(RawWriter::create(&path, h).is_err());
        let mut w = RawWriter::create_with_surface(&path, h, Some(&s)).unwrap();
        fill(&mut w, &(0..h.block_count()).collect::<Vec<_>>(), 2.0);
        w.finish().unwrap();
        let store = RawStore::open(&path).unwrap();
        assert_eq!(*store.header(), h, "{name}");
        assert_eq!(store.surface(), Some(&s));
        let mut row = Vec::new();
        store.read_rows(7..8, &mut row).unwrap();
        assert_eq!(row[0], 2.0);
        // Any flipped bit of the surface section is caught by its CRC.
        let mut bytes = std::fs::read(&path).unwrap();
        let at = u64::from_le_bytes(bytes[92..100].try_into().unwrap()) as usize;
        bytes[at + 5] ^= 1;
        let bad = dir.path().join("bad.raw");
        std::fs::write(&bad, &bytes).unwrap();
        let e = RawStore::open(&bad).err().unwrap().to_string();
        assert!(e.contains("surface"), "{e}");
    }
    let wrong = surface(7);
    assert!(
        RawWriter::create_with_surface(&dir.path().join("w.raw"), plain, Some(&wrong)).is_err()
    );
    assert!(RawWriter::create_with_surface(
        &dir.path().join("w.raw"),
        header(200),
        Some(&surface(30))
    )
    .is_err());
    let no_surface = RawHeader {
        has_surface: false,
        ..plain
    };
    assert!(RawWriter::create(&dir.path().join("w.raw"), no_surface).is_err());
}

/// A partial file is resumed only with the same identity and layout;
/// otherwise it is started over, and the writer says why.
#[test]
fn resume_needs_the_same_identity() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.raw");
    let partial = dir.path().join("s.raw.partial");
    let (a, b) = (
        header(200).with_input_id([1; 32]),
        header(200).with_input_id([2; 32]),
    );
    let w = RawWriter::create(&path, a).unwrap();
    assert_eq!(w.resume_state(), ResumeState::New);
    let mut w = w;
    fill(&mut w, &[0, 2], 3.0);
    drop(w);
    let state = |h: RawHeader| RawWriter::create(&path, h).unwrap().resume_state();
    let total = a.block_count();
    assert_eq!(state(a), ResumeState::Resumed { kept: 2, total });
    assert_eq!(
        RawWriter::create(&path, a).unwrap().pending_blocks().len(),
        total - 2
    );
    let restarted = |why| ResumeState::Restarted(why);
    assert_eq!(state(b), restarted(RestartReason::DifferentInputs));
    assert_eq!(state(a), restarted(RestartReason::DifferentInputs));
    // Started over: nothing of the old file is kept.
    assert_eq!(state(a), ResumeState::Resumed { kept: 0, total });
    let mut w = RawWriter::create(&path, a).unwrap();
    fill(&mut w, &[1], 3.0);
    drop(w);
    let other_blocks = RawHeader {
        block_rows: a.block_rows + 1,
        ..a
    };
    assert_eq!(
        state(other_blocks),
        restarted(RestartReason::DifferentLayout)
    );
    let mut w = RawWriter::create(&path, a).unwrap();
    fill(&mut w, &[1], 3.0);
    drop(w);
    assert_eq!(
        state(RawHeader {
            input_id: None,
            ..a
        }),
        restarted(RestartReason::NoIdentity)
    );
    // Now a version-1 partial: no identity to compare.
    assert_eq!(state(a), restarted(RestartReason::NoIdentity));
    let mut w = RawWriter::create(&path, a).unwrap();
    fill(&mut w, &[1], 3.0);
    drop(w);
    let len = std::fs::metadata(&partial).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&partial)
        .unwrap()
        .set_len(len - 1)
        .unwrap();
    assert_eq!(state(a), restarted(RestartReason::WrongLength));
    std::fs::write(&partial, b"not a raw store").unwrap();
    assert_eq!(state(a), restarted(RestartReason::Unreadable));
    assert!(state(a).to_string().contains("kept 0 of"));
}

/// Shards split the rows into contiguous ranges as even as possible.
#[test]
fn shards_cover_the_rows_evenly() {
    for rows in [1u64, 7, 30, 432] {
        for count in 1..=rows.min(9) {
            let spans: Vec<RowSpan> = (0..count).map(|i| RowSpan::shard(rows, i, count)).collect();
            assert_eq!(spans[0].start, 0);
            assert_eq!(spans[spans.len() - 1].end, rows);
            for w in spans.windows(2) {
                assert_eq!(w[0].end, w[1].start);
                assert!(w[0].len() == w[1].len() || w[0].len() == w[1].len() + 1);
            }
            assert!(spans.iter().all(|s| !s.is_empty()));
        }
    }
}

/// A part (version 5) round-trips, opens only as a part, and its rows are
/// numbered from its first row; a bad range is refused.
#[test]
fn a_part_round_trips_and_is_not_a_whole_store() {
    let dir = tempfile::tempdir().unwrap();
    let whole = header(200).with_input_id([3; 32]).with_surface();
    let span = RowSpan { start: 11, end: 23 };
    let h = whole.with_part(span);
    assert_eq!((h.version(), h.stored_rows(), h.first_row()), (5, 12, 11));
    let path = dir.path().join("part.raw");
    let s = surface(30);
    let mut w = RawWriter::create_with_surface(&path, h, Some(&s)).unwrap();
    fill(&mut w, &(0..h.block_count()).collect::<Vec<_>>(), 4.0);
    w.finish().unwrap();
    let e = RawStore::open(&path).err().unwrap().to_string();
    assert!(e.contains("rows 11..23") && e.contains("ltm merge"), "{e}");
    let store = RawStore::open_part(&path, &crate::Limits::default()).unwrap();
    assert_eq!(*store.header(), h);
    assert_eq!(store.header().whole(), whole);
    assert_eq!(store.surface(), Some(&s));
    for b in 0..h.block_count() {
        store.verify_block(b).unwrap();
    }
    assert!(store.read_rows(11..13, &mut Vec::new()).is_err());
    for bad in [RowSpan { start: 5, end: 5 }, RowSpan { start: 20, end: 31 }] {
        let e = RawWriter::create_with_surface(
            &dir.path().join("b.raw"),
            whole.with_part(bad),
            Some(&s),
        );
        assert!(e.err().unwrap().to_string().contains("part rows"));
    }
}
