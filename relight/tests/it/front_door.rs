//! The front door: `ltm_relight::open` takes any mode from a path or from
//! bytes and says how to light it, every frame is charged to one budget,
//! and a relighter defined outside the crate implements `Relight` and keeps
//! its own scratch in a `Frame`.

use ltm_codec::compress::{compress, CodeOptions};
use ltm_codec::{
    compress_pca, Dims, LightBasis, Limits, Mode, PcaOptions, RawHeader, RawStore, RawWriter,
};
use ltm_relight::{
    open, Frame, FrameStats, PcaRelighter, Relight, RelightError, Request, TermBasis, Weighting,
};
use std::path::{Path, PathBuf};

/// A raw store of `dims` and its `.ltm` in `mode`.
fn files(dir: &Path, dims: Dims, mode: Mode) -> (RawStore, PathBuf) {
    let raw_path = dir.join(format!("{}.raw", mode.name()));
    let rows: Vec<f32> = (0..dims.pixels() * dims.row_len())
        .map(|i| ((i % 83) as f32 * 0.05).sin().abs() * 1e-2)
        .collect();
    let header = RawHeader::new(dims, false, 1 << 20);
    let raw =
        RawStore::open(&RawWriter::write_dense(&raw_path, header, &rows, None).unwrap()).unwrap();
    let ltm = dir.join(format!("{}.ltm", mode.name()));
    if mode == Mode::Pca {
        let opts = PcaOptions {
            rank: Some(8),
            ..Default::default()
        };
        compress_pca(&raw, &ltm, &opts, ltm_codec::Progress::NONE).unwrap();
    } else {
        let opts = CodeOptions {
            mode,
            ..CodeOptions::default()
        };
        compress(&raw, &ltm, &opts.into(), ltm_codec::Progress::NONE).unwrap();
    }
    (raw, ltm)
}

fn request(terms: usize) -> Request {
    Request {
        terms,
        weighting: Weighting::Transport,
    }
}

#[test]
fn open_takes_every_mode_from_a_path_or_bytes_and_reports_its_basis() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(8, 6, 4, 3);
    for (mode, basis) in [
        (Mode::Adaptive, TermBasis::Wavelet),
        (Mode::TwoD, TermBasis::Wavelet),
        (Mode::Pca, TermBasis::Linear),
    ] {
        let (_, path) = files(dir.path(), dims, mode);
        let limits = Limits::with_max_alloc(64 << 20);
        let from_path = open(&path, &limits).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let from_bytes = open(bytes, &limits.clone()).unwrap();
        for r in [&from_path, &from_bytes] {
            assert_eq!(r.term_basis(), basis, "{}", mode.name());
            assert_eq!(r.light_basis(), LightBasis::Cubemap { n: 4 });
            assert_eq!((r.face_res(), r.lights(), r.size()), (4, 96, (8, 6)));
        }
        // Both files and their frames are charged to the one budget, and
        // given back when dropped.
        let opened = limits.used_bytes();
        assert!(opened > 0, "{}", mode.name());
        let light = vec![[1.0f32, 0.5, 0.25]; from_path.lights()];
        let terms = from_path.max_terms().min(20);
        let mut a = from_path.frame().unwrap();
        assert!(limits.used_bytes() > opened);
        from_path.relight(&light, &request(terms), &mut a).unwrap();
        let mut b = Frame::default();
        from_bytes.relight(&light, &request(terms), &mut b).unwrap();
        assert_eq!(a.image, b.image, "{}", mode.name());
        drop((a, b, from_path, from_bytes));
        assert_eq!(limits.used_bytes(), 0, "{}", mode.name());
    }
    // A pca file opens on its own as well, owning what it needs.
    let (_, pca) = files(dir.path(), dims, Mode::Pca);
    let r = PcaRelighter::open(pca.as_path(), &Limits::default()).unwrap();
    assert_eq!(r.term_basis(), TermBasis::Linear);
}

#[test]
fn frames_beyond_the_budget_are_errors_that_name_it() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = files(dir.path(), Dims::image(64, 64, 4, 3), Mode::Adaptive);
    // Enough to open the file, not for a frame's pixel planes as well.
    let probe = Limits::with_max_alloc(1 << 30);
    let r = open(&path, &probe).unwrap();
    let opened = probe.used_bytes();
    drop(r);
    // Opening also needs two work planes of the band weights for a while.
    let limits = Limits::with_max_alloc(opened + 2 * 4 * 64 * 64 + 1024);
    let r = open(&path, &limits).unwrap();
    let e = r.frame().err().expect("a frame beyond the budget");
    let text = e.to_string();
    assert!(text.contains("memory budget"), "{text}");
    let light = vec![[1.0f32; 3]; r.lights()];
    let e = r
        .relight(&light, &request(10), &mut Frame::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("memory budget"), "{e}");
    assert!(open(&path, &Limits::with_max_alloc(1024)).is_err());
}

/// A relighter outside the crate: every pixel the sum of the lighting times
/// a weight, with its scratch (the summed light) kept in the frame.
struct Outside {
    n: u32,
    size: (usize, usize),
    limits: Limits,
}

/// The outside relighter's scratch.
struct Sums {
    total: [f32; 3],
    frames: usize,
}

impl Relight for Outside {
    fn light_basis(&self) -> LightBasis {
        LightBasis::Cubemap { n: self.n }
    }
    fn term_basis(&self) -> TermBasis {
        TermBasis::Linear
    }
    fn size(&self) -> (usize, usize) {
        self.size
    }
    fn max_terms(&self) -> usize {
        1
    }
    fn held_bytes(&self) -> usize {
        0
    }
    fn relight(
        &self,
        light: &[[f32; 3]],
        _request: &Request,
        frame: &mut Frame,
    ) -> Result<FrameStats, RelightError> {
        if light.len() != self.lights() {
            return Err(RelightError::Invalid("wrong lighting".into()));
        }
        frame.fit_image(self.size.0, self.size.1, &self.limits)?;
        let fresh = || {
            Ok(Sums {
                total: [0.0; 3],
                frames: 0,
            })
        };
        let (sums, image) = frame.scratch(|_: &Sums| true, fresh)?;
        sums.total = [0.0; 3];
        for l in light {
            for (t, v) in sums.total.iter_mut().zip(l) {
                *t += v;
            }
        }
        sums.frames += 1;
        for (i, px) in image.data.iter_mut().enumerate() {
            *px = sums.total.map(|t| t * i as f32);
        }
        Ok(FrameStats {
            lights: self.lights(),
            ..FrameStats::default()
        })
    }
}

#[test]
fn a_relighter_outside_the_crate_keeps_its_scratch_in_the_frame() {
    let outside = Outside {
        n: 2,
        size: (3, 2),
        limits: Limits::with_max_alloc(1 << 20),
    };
    let boxed: Box<dyn Relight + Send + Sync> = Box::new(outside);
    assert_eq!((boxed.lights(), boxed.face_res()), (24, 2));
    let mut frame = boxed.frame().unwrap();
    let light = vec![[1.0f32, 2.0, 0.5]; 24];
    for k in 1..=3 {
        boxed.relight(&light, &request(1), &mut frame).unwrap();
        let (sums, _) = frame
            .scratch(|_: &Sums| true, || panic!("the scratch is kept"))
            .unwrap();
        assert_eq!((sums.frames, sums.total), (k, [24.0, 48.0, 12.0]));
    }
    assert_eq!(frame.image.data[5], [120.0, 240.0, 60.0]);
    // A crate relighter given this frame replaces the scratch with its own,
    // and the outside one then starts afresh.
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = files(dir.path(), Dims::image(3, 2, 2, 3), Mode::Adaptive);
    let inside = open(&path, &Limits::default()).unwrap();
    inside.relight(&light, &request(5), &mut frame).unwrap();
    assert_eq!(frame.image.data.len(), 6);
    boxed.relight(&light, &request(1), &mut frame).unwrap();
    let (sums, _) = frame
        .scratch(|_: &Sums| true, || panic!("the scratch is kept"))
        .unwrap();
    assert_eq!(sums.frames, 1);
}
