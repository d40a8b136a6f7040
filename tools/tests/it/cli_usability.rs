//! The CLI as a new user meets it (issue 33): PNG exposure, a raw store
//! where an .ltm file is wanted, the pca rank search, and readable
//! messages.

use ltm_codec::Dims;
use ltm_testkit::{block_bytes, run, write_raw};
use std::path::{Path, PathBuf};

const BIN: &str = env!("CARGO_BIN_EXE_ltm");

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn envmap() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/interior.exr")
}

/// Runs `ltm args`, which must succeed without a panic; returns stderr.
fn ok(args: &[&str]) -> String {
    let r = run(BIN, args);
    assert!(r.ok, "ltm {args:?} failed: {}", r.stderr);
    r.stderr
}

/// Runs `ltm args`, which must fail with a message and no panic; returns
/// stderr.
fn fails(args: &[&str]) -> String {
    let r = run(BIN, args);
    assert!(!r.ok, "ltm {args:?} succeeded");
    assert!(!r.stderr.contains("panicked"), "{args:?}: {}", r.stderr);
    r.stderr
}

/// A 16×16 RGB store of 96 lights whose relit image is bright (values far
/// above 1 under interior.exr) and ramps from one corner to the other.
fn bright_store(dir: &Path) -> PathBuf {
    let dims = Dims::image(16, 16, 4, 3);
    let row = dims.row_len();
    let t: Vec<f32> = (0..dims.pixels() * row)
        .map(|i| {
            let (p, j) = (i / row, i % row);
            50.0 * (1 + p) as f32 / dims.pixels() as f32 * (1.0 + (j % 7) as f32 * 0.1)
        })
        .collect();
    write_raw(&dir.join("b.raw"), dims, &t, None, block_bytes(dims, 64))
}

/// The 8-bit channels of a PNG and the fraction of them at 255.
fn png_channels(path: &Path) -> (Vec<u8>, f64) {
    let img = image::open(path).unwrap().to_rgb8().into_raw();
    let clipped = img.iter().filter(|&&v| v == 255).count() as f64 / img.len() as f64;
    (img, clipped)
}

/// The EV a command printed for its PNG.
fn printed_ev(stderr: &str) -> f32 {
    let at = stderr
        .find("EV ")
        .unwrap_or_else(|| panic!("no EV in {stderr}"));
    let num: String = stderr[at + 3..]
        .chars()
        .take_while(|c| c.is_ascii_digit() || "+-.".contains(*c))
        .collect();
    num.parse().unwrap()
}

/// `relight --png` exposes automatically by default: a bright image no
/// longer clips most pixels (as a fixed high EV does), the EV chosen is
/// printed, and a number given to `--exposure` is used as given.
#[test]
fn relight_png_exposure_is_automatic_and_a_number_is_honoured() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = bright_store(d);
    let ltm = d.join("b.ltm");
    ok(&["compress", s(&raw), "-o", s(&ltm)]);
    let env = envmap();
    let relight = |png: &str, extra: &[&str]| {
        let (exr, png) = (d.join(format!("{png}.exr")), d.join(format!("{png}.png")));
        let mut args = vec!["relight", s(&ltm), "--env", s(&env)];
        args.extend(["-o", s(&exr), "--png", s(&png)]);
        args.extend_from_slice(extra);
        let stderr = ok(&args);
        (png_channels(&png), stderr)
    };
    let ((auto, auto_clipped), stderr) = relight("auto", &[]);
    assert!(stderr.contains("auto"), "{stderr}");
    let ev = printed_ev(&stderr);
    assert!(ev < -2.0, "a bright image needs a negative EV, got {ev}");
    assert!(auto_clipped < 0.05, "auto clips {auto_clipped}");
    let ((_, zero_clipped), stderr) = relight("zero", &["--exposure", "0"]);
    assert!(zero_clipped > 0.5, "EV 0 clips only {zero_clipped}");
    assert!(
        stderr.contains("EV +0.00") && !stderr.contains("auto"),
        "{stderr}"
    );
    // The printed EV, given as a number, writes the same PNG (up to its
    // two printed decimals).
    let ((same, _), _) = relight("same", &["--exposure", &format!("{ev}")]);
    assert_eq!(auto.len(), same.len());
    let most = auto.iter().zip(&same).map(|(a, b)| a.abs_diff(*b)).max();
    assert!(most <= Some(1), "largest difference {most:?}");
    // One stop darker is darker.
    let ((dark, _), _) = relight("dark", &["--exposure", &format!("{}", ev - 1.0)]);
    let sum = |v: &[u8]| v.iter().map(|&x| u64::from(x)).sum::<u64>();
    assert!(sum(&dark) < sum(&same) * 9 / 10);
    for bad in ["nan", "65", "bright"] {
        let stderr = fails(&[
            "relight",
            s(&ltm),
            "--env",
            s(&env),
            "-o",
            s(&d.join("x.exr")),
            "--exposure",
            bad,
        ]);
        assert!(
            stderr.contains("auto") && stderr.contains("-64..=64"),
            "{stderr}"
        );
    }
}

/// A raw store given to commands that want an .ltm file is named as one,
/// with the command that compresses it; an .ltm file given to `compress`
/// is named as one too.
#[test]
fn a_raw_store_where_an_ltm_file_is_wanted_names_ltm_compress() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = bright_store(d);
    let want = format!("ltm compress {} -o {}", s(&raw), s(&d.join("b.ltm")));
    for args in ltm_readers(&raw, d) {
        let args = refs(&args);
        let stderr = fails(&args);
        assert!(stderr.contains("raw transport store"), "{stderr}");
        assert!(stderr.contains(&want), "{args:?}: {stderr}");
        assert!(!stderr.contains("magic"), "{stderr}");
    }
    let ltm = d.join("b.ltm");
    ok(&["compress", s(&raw), "-o", s(&ltm)]);
    let stderr = fails(&["compress", s(&ltm), "-o", s(&d.join("again.ltm"))]);
    assert!(
        stderr.contains("an .ltm file (already compressed)"),
        "{stderr}"
    );
}

/// The commands that read an `.ltm` file, each given `input` (outputs in
/// `dir`).
fn ltm_readers(input: &Path, dir: &Path) -> Vec<Vec<String>> {
    let env = envmap();
    vec![
        ["inspect", s(input)].map(String::from).to_vec(),
        [
            "relight",
            s(input),
            "--env",
            s(&env),
            "-o",
            s(&dir.join("r.exr")),
        ]
        .map(String::from)
        .to_vec(),
        ["export", s(input), "-o", s(&dir.join("t.npy"))]
            .map(String::from)
            .to_vec(),
    ]
}

/// A scene file where an `.ltm` file is wanted: the message names the
/// commands that make one from it, in every command that reads `.ltm`
/// files, and not the magic bytes.
#[test]
fn a_scene_file_where_an_ltm_file_is_wanted_names_bake_and_compress() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = d.join("my scene.toml");
    std::fs::write(&scene, "[scene]\nmesh = \"a.obj\"\n").unwrap();
    let raw = d.join("my scene.raw");
    let want_bake = format!("ltm bake {} -o {}", s(&scene), s(&raw));
    let want_compress = format!("ltm compress {} -o {}", s(&raw), s(&d.join("my scene.ltm")));
    for args in ltm_readers(&scene, d) {
        let args = refs(&args);
        let stderr = fails(&args);
        assert!(
            stderr.contains("a scene file, not an .ltm file"),
            "{args:?}: {stderr}"
        );
        assert!(stderr.contains(&want_bake), "{args:?}: {stderr}");
        assert!(stderr.contains(&want_compress), "{args:?}: {stderr}");
        assert!(!stderr.contains("magic"), "{args:?}: {stderr}");
    }
}

/// `compress --mode pca --max-error`: without `--max-rank` the rank grows
/// past the first fit's 256 up to the matrix's full rank until the target
/// is met; with `--max-rank` given, a target it cannot reach is refused
/// with a message that names `--max-rank`.
#[test]
fn pca_rank_grows_to_the_target_unless_max_rank_limits_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Noise of full rank min(576, 6·4²·3) = 288: rank 256 leaves far more
    // than 1 %.
    let dims = Dims::image(24, 24, 4, 3);
    let mut rng = ltm_testkit::Rng::new(7);
    let t: Vec<f32> = (0..dims.pixels() * dims.row_len())
        .map(|_| rng.uniform() as f32)
        .collect();
    let raw = write_raw(&d.join("n.raw"), dims, &t, None, block_bytes(dims, 64));
    let out = d.join("n.ltm");
    let compress = |extra: &[&str]| {
        let mut args = vec!["compress", s(&raw), "-o", s(&out), "--mode", "pca"];
        args.extend(["--max-error", "0.01"]);
        args.extend_from_slice(extra);
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    let args = compress(&["--max-rank", "256"]);
    let stderr = fails(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(stderr.contains("--max-rank 256"), "{stderr}");
    assert!(stderr.contains("full rank is 288"), "{stderr}");
    assert!(!out.exists());
    let args = compress(&[]);
    let stderr = ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let rank: usize = stderr
        .split("pca rank ")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no rank in {stderr}"));
    assert!((257..=288).contains(&rank), "rank {rank}: {stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
}

/// An image named for another format is refused before any work, for
/// every command with image outputs: `-o x.png` would write an EXR under a
/// PNG's name (it did), `--png x.exr` a PNG under an EXR's.
#[test]
fn image_outputs_named_for_another_format_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = bright_store(d);
    let ltm = d.join("b.ltm");
    ok(&["compress", s(&raw), "-o", s(&ltm)]);
    let env = envmap();
    for cmd in ["relight", "render", "reference"] {
        let input = if cmd == "reference" { &raw } else { &ltm };
        let base = [cmd, s(input), "--env", s(&env)];
        for (flags, says) in [
            (
                ["-o", "x.png", "--png", "y.png"],
                "'x.png' ends in .png, but -o writes EXR",
            ),
            (
                ["-o", "x.JPG", "--png", "y.png"],
                "ends in .jpg, but -o writes EXR",
            ),
            (
                ["-o", "x.exr", "--png", "y.exr"],
                "'y.exr' ends in .exr, but --png writes PNG",
            ),
        ] {
            let mut args = base.to_vec();
            args.extend(flags);
            let err = fails(&args);
            assert!(err.contains(says), "{cmd} {flags:?}: {err}");
        }
    }
    assert!(!d.join("x.png").exists() && !d.join("y.exr").exists());
    // Names without an image extension, or the right one, are taken.
    let out = d.join("plain");
    ok(&[
        "relight",
        s(&ltm),
        "--env",
        s(&env),
        "-o",
        s(&out),
        "--png",
        s(&d.join("p.PNG")),
    ]);
    assert!(out.exists() && d.join("p.PNG").exists());
}

/// The arguments as `&str`s.
fn refs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// A 16×16 store with surface data on the plane y = 0 (normal +Y): image
/// rows, or texture rows when `texture`.
fn plane_store(dir: &Path, texture: bool) -> PathBuf {
    use ltm_codec::{Parameterization, RawHeader, RawWriter, Surface, SurfacePoint};
    let dims = match texture {
        true => Dims::texture(16, Parameterization::Uv, 4, 3),
        false => Dims::image(16, 16, 4, 3),
    };
    let t: Vec<f32> = (0..dims.pixels() * dims.row_len())
        .map(|i| 0.01 + ((i * 7) % 11) as f32 * 0.003)
        .collect();
    let surface = Surface::new(
        (0..dims.pixels())
            .map(|p| SurfacePoint::new([(p % 16) as f32, 0.0, (p / 16) as f32], [0.0, 1.0, 0.0]))
            .collect(),
    )
    .unwrap();
    let header = RawHeader::new(dims, false, block_bytes(dims, 64)).with_surface();
    let name = if texture { "tex.raw" } else { "plane.raw" };
    RawWriter::write_dense_with_surface(&dir.join(name), header, &t, None, Some(&surface)).unwrap()
}

/// `relight --brdf` shades image rows from their camera's eye: it refuses,
/// naming the way out, a file without surface data, texture rows (whose
/// look depends on the view), rows whose eye the records cannot fix (one
/// plane) unless `--eye` is given, and flags it cannot go with.
#[test]
fn relight_brdf_refuses_what_it_cannot_shade() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let env = envmap();
    let compress = |raw: PathBuf, name: &str| {
        let out = d.join(name);
        ok(&["compress", s(&raw), "-o", s(&out)]);
        out
    };
    let (bare, plane, tex) = (
        compress(bright_store(d), "bare.ltm"),
        compress(plane_store(d, false), "plane.ltm"),
        compress(plane_store(d, true), "tex.ltm"),
    );
    let out = d.join("o.exr");
    let brdf = |file: &Path, extra: &[&str]| {
        let mut args = vec!["relight", s(file), "--env", s(&env), "--brdf", "ggx:0.3"];
        args.extend(["--glossy-n", "8", "-o", s(&out)]);
        args.extend(extra);
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    for (args, says) in [
        (brdf(&bare, &[]), "stores none"),
        (brdf(&tex, &[]), "holds texture rows"),
        (brdf(&plane, &[]), "give the camera position with --eye"),
        (brdf(&plane, &[]), "on one plane"),
        (brdf(&plane, &["--eye", "1,2"]), "has 2 coordinates"),
        (brdf(&plane, &["--eye", "1,nan,2"]), "is not finite"),
        (brdf(&plane, &["--reference", s(&out)]), "--reference"),
    ] {
        let err = fails(&refs(&args));
        assert!(err.contains(says), "{args:?}: {err}");
    }
    let err = fails(&[
        "relight",
        s(&plane),
        "--point",
        "0,1,0",
        "--intensity",
        "1",
        "--brdf",
        "ggx:0.3",
        "-o",
        s(&out),
    ]);
    assert!(err.contains("give it with --env"), "{err}");
    let err = fails(&[
        "relight",
        s(&plane),
        "--env",
        s(&env),
        "--eye",
        "0,5,0",
        "-o",
        s(&out),
    ]);
    assert!(err.contains("--brdf"), "{err}");
    assert!(!out.exists());
    // Given the eye, the plane's rows are shaded, the material on top of
    // the transport, and nothing is NaN.
    let said = ok(&refs(&brdf(&plane, &["--eye", "7.5,6,7.5"])));
    assert!(said.contains("glossy ggx:0.3"), "{said}");
    let lit = ltm_relight::Image::read_exr(&out).unwrap();
    let plain = d.join("p.exr");
    ok(&["relight", s(&plane), "--env", s(&env), "-o", s(&plain)]);
    let base = ltm_relight::Image::read_exr(&plain).unwrap();
    let added = lit
        .data
        .iter()
        .zip(&base.data)
        .all(|(a, b)| (0..3).all(|c| a[c].is_finite() && a[c] >= b[c]) && a[1] > b[1]);
    assert!(added, "the glossy part is not added to every pixel");
    // The nearest view texel instead of four: another image, as finite.
    let nearest = d.join("n.exr");
    let mut args = brdf(&plane, &["--eye", "7.5,6,7.5", "--view-filter", "nearest"]);
    *args.iter_mut().find(|a| a.ends_with("o.exr")).unwrap() = s(&nearest).into();
    ok(&refs(&args));
    let near = ltm_relight::Image::read_exr(&nearest).unwrap();
    assert!(near.data.iter().flatten().all(|v| v.is_finite()));
    assert_ne!(near.data, lit.data, "--view-filter changed nothing");
}

/// A command's help mentions only options it has: the image outputs shared
/// by `relight`, `reference` and `render` name `--views` only in `render`.
#[test]
fn help_names_views_only_where_the_command_has_them() {
    let help = |cmd: &str| ltm_testkit::run_ok(env!("CARGO_BIN_EXE_ltm"), &[cmd, "--help"]);
    for cmd in ["relight", "reference"] {
        let text = help(cmd);
        assert!(!text.contains("--views"), "ltm {cmd} --help:\n{text}");
    }
    assert!(help("render").contains("--views"));
}

/// `ltm bake` prints the scene's bounding box (what a user needs to place
/// a camera): the ground quad's and the raised mesh's corners, as the scene
/// file puts them.
#[test]
fn bake_prints_the_scene_bounding_box() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = ltm_testkit::blob_obj(3);
    std::fs::write(d.join("blob.obj"), &obj).unwrap();
    let scene = d.join("scene.toml");
    std::fs::write(&scene, ltm_testkit::scene_toml("blob.obj", 8, 6, 2)).unwrap();
    // The 4×4 ground quad at y = 0, and the mesh raised by 0.6.
    let (mut lo, mut hi) = ([-2.0f64, 0.0, -2.0], [2.0f64, 0.0, 2.0]);
    for line in obj.lines().filter(|l| l.starts_with("v ")) {
        let v: Vec<f64> = line[2..]
            .split_whitespace()
            .map(|x| x.parse().unwrap())
            .collect();
        for k in 0..3 {
            let c = v[k] + if k == 1 { 0.6 } else { 0.0 };
            lo[k] = lo[k].min(c);
            hi[k] = hi[k].max(c);
        }
    }
    let stderr = ok(&["bake", s(&scene), "-o", s(&d.join("t.raw"))]);
    let line = stderr
        .lines()
        .find(|l| l.starts_with("scene bounding box: "))
        .unwrap_or_else(|| panic!("no bounding box in:\n{stderr}"));
    let numbers: Vec<f64> = line
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .filter_map(|t| t.parse().ok())
        .collect();
    assert_eq!(numbers.len(), 9, "{line}");
    let centre = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let want = [lo, hi, centre].concat();
    for (got, want) in numbers.iter().zip(&want) {
        assert!(
            (got - want).abs() <= 1e-3 * want.abs().max(1.0),
            "{line}: want {want:?}"
        );
    }
}
