//! The `ltm` binary end to end: the demo on a tiny setting, and bad input
//! that must exit non-zero with a clear message.

use std::path::Path;

fn ltm(args: &[&str]) -> (bool, String, String) {
    ltm_testkit::run(env!("CARGO_BIN_EXE_ltm"), args).into()
}

#[test]
fn demo_runs_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let (ok, stdout, stderr) = ltm(&[
        "demo",
        "-o",
        out.to_str().unwrap(),
        "--assets",
        assets.to_str().unwrap(),
        "--size",
        "24",
        "--face-res",
        "4",
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("| adaptive"), "{stdout}");
    for f in [
        "summary.md",
        "contact-sheet.png",
        "interior-reference.exr",
        "interior-adaptive-N200.png",
        "scene-adaptive.ltm",
        "scene-2d.ltm",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    // A second run reuses the bake.
    let (ok, _, stderr) = ltm(&[
        "demo",
        "-o",
        out.to_str().unwrap(),
        "--assets",
        assets.to_str().unwrap(),
        "--size",
        "24",
        "--face-res",
        "4",
    ]);
    assert!(ok && stderr.contains("cached"), "{stderr}");
}

/// `ltm report --quick` (as CI runs it): every section, plot and measured
/// point is there and consistent. Timings are not checked.
#[test]
fn report_quick_writes_every_section() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("report");
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let env = |name: &str| assets.join("envmaps").join(name);
    let (ok, _, stderr) = ltm(&[
        "report",
        "--quick",
        "-o",
        out.to_str().unwrap(),
        "--assets",
        assets.to_str().unwrap(),
        "--env",
        env("interior.exr").to_str().unwrap(),
        "--env",
        env("sunset.exr").to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let index = std::fs::read_to_string(out.join("index.md")).unwrap();
    for heading in [
        "## Headline",
        "## 1. Size against matrix error",
        "## 2. Relit error",
        "## 3. Frame time",
        "## 4. Average column depth",
        "## 5. Speed against error",
        "**Machine:**",
        "**Date:**",
    ] {
        assert!(index.contains(heading), "index.md lacks {heading}");
    }
    // The headline's size table has no row without a size in it.
    let headline = &index[index.find("## Headline").unwrap()..index.find("## 1.").unwrap()];
    for row in headline
        .lines()
        .filter(|l| l.starts_with("| ") && l.contains('%'))
    {
        let cells: Vec<&str> = row
            .split('|')
            .map(str::trim)
            .filter(|c| !c.is_empty())
            .collect();
        if cells.len() == 8 {
            assert!(
                cells[1..5].iter().any(|c| *c != "–"),
                "a row of dashes: {row}"
            );
        }
    }
    for svg in [
        "size-error.svg",
        "relit-error-interior.svg",
        "relit-error-sunset.svg",
        "frame-time.svg",
        "dynamic-compression.svg",
        "depth-by-level.svg",
        "speed-error.svg",
    ] {
        let text = std::fs::read_to_string(out.join(svg)).unwrap();
        assert!(text.starts_with("<svg") && text.contains("<text"), "{svg}");
        assert!(
            index.contains(&format!("]({svg})")),
            "index.md does not show {svg}"
        );
    }
    // An image-space matrix has no geometry section.
    assert!(!index.contains("Geometry relighting") && !out.join("texture.png").exists());
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert!(r["texture"].is_null());
    let all = r["codings"].as_array().unwrap();
    let (pca, codings): (Vec<_>, Vec<_>) = all.iter().partition(|c| c["mode"] == "pca");
    // 3 wavelet modes × 1 bit depth × 2 target errors; the pair is among them.
    assert_eq!(codings.len(), 6);
    // pca at each target a rank up to 256 reaches: relit at N = 1, 4, 16,
    // 64, 256 clamped to its rank, and its rank, under 2 maps.
    assert!(pca.iter().any(|c| c["target_error"] == 0.01), "{pca:?}");
    for c in &pca {
        let (target, error) = (
            c["target_error"].as_f64().unwrap(),
            c["matrix_error"].as_f64().unwrap(),
        );
        assert!(c["target_met"].as_bool().unwrap() && error <= target && error > 0.0);
        let points = c["relight"].as_array().unwrap();
        assert!(
            points.len() >= 2 && points.len() <= 12 && points.len() % 2 == 0,
            "{c}"
        );
        for p in points {
            assert!(
                p["relit_error"].as_f64().unwrap().is_finite()
                    && p["frame_ms"].as_f64().unwrap() > 0.0
            );
        }
        let name = format!("pca-e{target}.ltm");
        let pair = c["quality_pair"].as_bool().unwrap();
        assert_eq!(pair, target == 0.01);
        assert_eq!(out.join("files").join(&name).is_file(), pair, "{name}");
    }
    assert!(
        index.contains("relit error, ") && index.contains("is the fastest mode"),
        "headline lacks the fastest mode at 1 %"
    );
    for c in codings.iter().copied() {
        let (target, error) = (
            c["target_error"].as_f64().unwrap(),
            c["matrix_error"].as_f64().unwrap(),
        );
        assert!(c["target_met"].as_bool().unwrap() && error <= target * 1.0001);
        let pair = c["quality_pair"].as_bool().unwrap();
        // 2 maps × 3 values of N, with 3 weightings for the pair.
        let points = c["relight"].as_array().unwrap();
        assert_eq!(points.len(), if pair { 18 } else { 6 });
        for p in points {
            let e = p["relit_error"].as_f64().unwrap();
            assert!(e.is_finite() && e >= 0.0, "{p}");
            assert!(p["frame_ms"].as_f64().unwrap() > 0.0);
            assert!(p["lights"].as_u64().unwrap() <= p["n"].as_u64().unwrap());
        }
        let name = format!(
            "{}-12b-e{}.ltm",
            c["mode"].as_str().unwrap(),
            c["target_error"].as_f64().unwrap()
        );
        assert_eq!(out.join("files").join(&name).is_file(), pair, "{name}");
    }
    let pairs = codings.iter().filter(|c| c["quality_pair"] == true).count();
    assert_eq!(pairs, 2);
    let baselines = r["baselines"].as_array().unwrap();
    let of = |m: &str| -> Vec<f64> {
        baselines
            .iter()
            .filter(|b| b["method"] == m)
            .map(|b| b["matrix_error"].as_f64().unwrap())
            .collect()
    };
    assert_eq!(of("zstd-raw"), vec![0.0]);
    // PCA is a mode now, not a baseline.
    let (pca, sh) = (of("pca"), of("sh"));
    assert_eq!((pca.len(), sh.len()), (0, 3));
    assert!(sh.windows(2).all(|w| w[1] < w[0]), "{sh:?}");
    assert_eq!(r["sh_relight"].as_array().unwrap().len(), 2 * 3);

    // --replot redraws the same page and plots from results.json alone.
    std::fs::remove_file(out.join("size-error.svg")).unwrap();
    let (ok, _, stderr) = ltm(&["report", "--replot", "-o", out.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert_eq!(
        std::fs::read_to_string(out.join("index.md")).unwrap(),
        index
    );
    assert!(out.join("size-error.svg").is_file());
    replot_with_peers(&out, &r);
    std::fs::write(out.join("results.json"), r#"{"codings": 3}"#).unwrap();
    let (ok, _, stderr) = ltm(&["report", "--replot", "-o", out.to_str().unwrap()]);
    assert!(
        !ok && stderr.contains("is not a report's results.json"),
        "{stderr}"
    );
}

/// `ltm report --replot --peers`: SZ3, ZFP and SPERR in the peers table,
/// and adaptive's size over the smallest peer's.
fn replot_with_peers(out: &std::path::Path, r: &serde_json::Value) {
    let scene = &r["scene"];
    let adaptive = |t: f64| {
        r["codings"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| c["mode"] == "adaptive" && c["target_error"] == t)
            .map(|c| c["file_bytes"].as_u64().unwrap())
            .min()
            .unwrap()
    };
    let point = |method: &str, bytes: u64, shape: &str| {
        serde_json::json!({"method": method, "param": 0, "bytes": bytes, "matrix_error": 0.0098,
            "target": 0.01, "shape": shape, "bound": 1e-4, "compress_s": 0.1,
            "decompress_s": 0.1, "frame_s": 0.01})
    };
    let peers = serde_json::json!({
        "dims": {"width": scene["width"], "height": scene["height"],
                 "face_res": scene["face_res"], "channels": scene["channels"]},
        "points": [point("sz3", 3000, "(P, M·C)"), point("zfp", 5000, "(H, W, M·C)"),
                   point("sperr", 2000, "(M·C, H, W)")],
    });
    let path = out.join("peers.json");
    std::fs::write(&path, peers.to_string()).unwrap();
    let (ok, _, stderr) = ltm(&[
        "report",
        "--replot",
        "--peers",
        path.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let index = std::fs::read_to_string(out.join("index.md")).unwrap();
    assert!(
        index.contains("| SZ3 | ZFP | SPERR | adaptive / best peer |"),
        "{index}"
    );
    let row = index
        .lines()
        .find(|l| l.starts_with("| 1.000 % |") && l.contains("[(M·C, H, W)]"))
        .unwrap_or_else(|| panic!("no peers row at 1 %: {index}"));
    let ratio = format!("| {:.2} |", adaptive(0.01) as f64 / 2000.0);
    assert!(row.ends_with(&ratio), "{row} does not end with {ratio}");
}

#[test]
fn bad_input_exits_non_zero_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.ltm");
    std::fs::write(&junk, b"definitely not an ltm file").unwrap();
    let missing = dir.path().join("missing.raw");
    let out = dir.path().join("o.ltm");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "report",
                "--raw",
                missing.to_str().unwrap(),
                "-o",
                dir.path().to_str().unwrap(),
            ],
            "missing.raw",
        ),
        (
            vec![
                "report",
                "--quick",
                "--bits",
                "20",
                "-o",
                dir.path().to_str().unwrap(),
            ],
            "--bits 20 is out of range",
        ),
        (
            vec![
                "report",
                "--quick",
                "--errors",
                "1.5",
                "-o",
                dir.path().to_str().unwrap(),
            ],
            "target error 1.5",
        ),
        (vec!["inspect", junk.to_str().unwrap()], "not an .ltm file"),
        (
            vec![
                "compress",
                missing.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            "missing.raw",
        ),
        (
            vec![
                "compress",
                junk.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            "raw transport store",
        ),
        (
            vec![
                "relight",
                junk.to_str().unwrap(),
                "--env",
                "x.exr",
                "-o",
                "y.exr",
            ],
            "not an .ltm file",
        ),
        (
            vec![
                "relight",
                junk.to_str().unwrap(),
                "--env",
                "x.exr",
                "-o",
                "y.exr",
                "--terms",
                "0",
            ],
            "positive integer",
        ),
        (
            vec![
                "compress",
                missing.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--bits",
                "20",
            ],
            "bits",
        ),
        (
            vec![
                "compress",
                missing.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--quantizer",
                "lloyd",
            ],
            "expected uniform or peak",
        ),
    ];
    for (args, expect) in cases {
        let (ok, _, stderr) = ltm(&args);
        assert!(!ok, "{args:?} succeeded");
        assert!(stderr.contains(expect), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
    assert!(!out.exists());
}

/// Writes a float32 C-order `.npy` of shape `(rows, cols)`.
fn write_npy(path: &Path, rows: usize, cols: usize, values: &[f32]) {
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    values
        .iter()
        .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
    std::fs::write(path, bytes).unwrap();
}

/// Writes `values` (`width·height` rows of `lights` columns) as `t.npy` in
/// `dir` and imports it with `ltm import` as `t.raw`.
fn import_matrix(dir: &Path, width: usize, height: usize, values: &[f32]) {
    let rows = width * height;
    write_npy(&dir.join("t.npy"), rows, values.len() / rows, values);
    let path = |n: &str| dir.join(n).to_str().unwrap().to_string();
    let (w, h) = (width.to_string(), height.to_string());
    let (ok, _, stderr) = ltm(&[
        "import",
        &path("t.npy"),
        "--width",
        &w,
        "--height",
        &h,
        "-o",
        &path("t.raw"),
    ]);
    assert!(ok, "{stderr}");
}

/// `ltm compress --keep N` keeps N coefficients per column; the old
/// spelling `--terms` (which `ltm relight` uses for lights per frame) is
/// refused with a message that names `--keep`, with or without a value;
/// an unknown `--entropy`, or one given to `--mode pca`, is refused.
#[test]
fn compress_keep_and_the_renamed_terms_flag() {
    let dir = tempfile::tempdir().unwrap();
    let (npy, raw, out) = (
        dir.path().join("t.npy"),
        dir.path().join("t.raw"),
        dir.path().join("t.ltm"),
    );
    let (p, m) = (4 * 3, 6 * 2 * 2);
    let values: Vec<f32> = (0..p * m).map(|i| ((i * 7) % 13) as f32 * 0.01).collect();
    write_npy(&npy, p, m, &values);
    let (ok, _, stderr) = ltm(&[
        "import",
        npy.to_str().unwrap(),
        "--width",
        "4",
        "--height",
        "3",
        "-o",
        raw.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let compress = |extra: &[&str]| {
        let mut args = vec![
            "compress",
            raw.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        ltm(&args)
    };
    for (extra, needle) in [
        (&["--terms", "5"][..], "--keep"),
        (&["--terms"], "--keep"),
        (&["--keep", "5", "--terms", "5"], "--keep"),
        (&["--entropy", "lz4"], "range or zstd"),
        (&["--mode", "pca", "--entropy", "zstd"], "--entropy"),
    ] {
        let (ok, _, stderr) = compress(extra);
        assert!(!ok, "{extra:?} succeeded");
        assert!(stderr.contains(needle), "{extra:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{extra:?}: {stderr}");
        assert!(!out.exists());
    }
    let (ok, _, stderr) = compress(&["--keep", "5"]);
    assert!(ok, "{stderr}");
    let (ok, stdout, stderr) = ltm(&["inspect", out.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("5 coefficients kept per column"),
        "{stdout}"
    );
}

/// `ltm compress --mode pca` end to end: inspect, export (the decoded
/// matrix within the recorded error), relight with `--terms`, and the bad
/// ranks, targets and flags that must fail with a message.
#[test]
fn pca_mode_compress_inspect_export_relight() {
    let dir = tempfile::tempdir().unwrap();
    let path = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let (p, m) = (4 * 3, 6 * 2 * 2);
    let values: Vec<f32> = (0..p * m)
        .map(|i| 0.05 + ((i * 7) % 13) as f32 * 0.01 * (1.0 + (i / m) as f32 * 0.1))
        .collect();
    import_matrix(dir.path(), 4, 3, &values);
    let (ok, _, stderr) = ltm(&[
        "compress",
        &path("t.raw"),
        "-o",
        &path("p.ltm"),
        "--mode",
        "pca",
        "--rank",
        "3",
    ]);
    assert!(ok && stderr.contains("pca rank 3"), "{stderr}");
    let (ok, stdout, stderr) = ltm(&["inspect", &path("p.ltm"), "--json"]);
    assert!(ok, "{stderr}");
    let i: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(
        (i["mode"].as_str(), i["pca_rank"].as_u64()),
        (Some("pca"), Some(3))
    );
    let recorded = i["achieved_error"].as_f64().unwrap();
    let (ok, stdout, _) = ltm(&["inspect", &path("p.ltm")]);
    assert!(ok && stdout.contains("pca, rank 3"), "{stdout}");
    let (ok, _, stderr) = ltm(&["export", &path("p.ltm"), "-o", &path("p.npy")]);
    assert!(ok, "{stderr}");
    let bytes = std::fs::read(dir.path().join("p.npy")).unwrap();
    let decoded: Vec<f32> = bytes[bytes.len() - 4 * p * m..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let num: f64 = decoded
        .iter()
        .zip(&values)
        .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
        .sum();
    let den: f64 = values.iter().map(|b| (*b as f64).powi(2)).sum();
    assert!(
        ((num / den).sqrt() - recorded).abs() < 1e-6 + 1e-3 * recorded,
        "{} vs {recorded}",
        (num / den).sqrt()
    );
    let env = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/interior.exr");
    let env = env.to_str().unwrap();
    let (ok, stdout, stderr) = ltm(&[
        "relight",
        &path("p.ltm"),
        "--env",
        env,
        "--terms",
        "2",
        "-o",
        &path("r.exr"),
        "--json",
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("\"lights\":2"), "{stdout}");
    let (ok, _, stderr) = ltm(&[
        "relight",
        &path("p.ltm"),
        "--env",
        env,
        "--terms",
        "4",
        "-o",
        &path("r.exr"),
    ]);
    assert!(!ok && stderr.contains("0..=3"), "{stderr}");
    for (extra, want) in [
        (&["--rank", "0"][..], "1..=12"),
        (&["--rank", "13"], "1..=12"),
        (&["--max-error", "1e-9", "--max-rank", "1"], "--max-rank"),
        (&["--max-rank", "0"], "--max-rank"),
        (&["--keep", "4"], "--rank"),
    ] {
        let mut args = vec![
            "compress",
            &path("t.raw")[..],
            "-o",
            &path("x.ltm")[..],
            "--mode",
            "pca",
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, _, stderr) = ltm(&args);
        assert!(
            !ok && stderr.contains(want) && !stderr.contains("panicked"),
            "{extra:?}: {stderr}"
        );
        assert!(!dir.path().join("x.ltm").exists());
    }
    let (ok, _, stderr) = ltm(&[
        "compress",
        &path("t.raw"),
        "-o",
        &path("x.ltm"),
        "--rank",
        "3",
    ]);
    assert!(!ok && stderr.contains("--mode pca"), "{stderr}");
}

/// `ltm relight --json` of a wavelet file: the first frame decodes the
/// columns it uses and later frames none; with `--preload` the open
/// decodes them all and no frame does; the images are the same.
#[test]
fn relight_decodes_columns_on_first_use_or_with_preload() {
    let dir = tempfile::tempdir().unwrap();
    let path = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let (p, m) = (6 * 5, 6 * 4 * 4);
    let values: Vec<f32> = (0..p * m)
        .map(|i| 0.01 + ((i * 7) % 13) as f32 * 0.01 * (1.0 + (i % m) as f32 * 0.05))
        .collect();
    import_matrix(dir.path(), 6, 5, &values);
    let (ok, _, stderr) = ltm(&["compress", &path("t.raw"), "-o", &path("t.ltm")]);
    assert!(ok, "{stderr}");
    let env = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/studio.exr");
    let relight = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "relight".to_string(),
            path("t.ltm"),
            "--env".into(),
            env.to_str().unwrap().into(),
            "--terms".into(),
            "7".into(),
            "--weighting".into(),
            "transport".into(),
            "--frames".into(),
            "3".into(),
            "--json".into(),
            "-o".into(),
            path(out),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, stdout, stderr) = ltm(&args);
        assert!(ok, "{stderr}");
        let j: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
        (j, std::fs::read(path(out)).unwrap())
    };
    let (lazy, a) = relight("a.exr", &[]);
    assert_eq!(lazy["columns_decoded"], 7, "{lazy}");
    assert!(lazy["first_frame_ms"].is_f64() && lazy["decode_ms"].is_f64());
    let (eager, b) = relight("b.exr", &["--preload"]);
    assert_eq!(eager["columns_decoded"], 0, "{eager}");
    assert!(eager["arena_bytes"].as_u64() > lazy["arena_bytes"].as_u64());
    assert_eq!(a, b);
}
