//! The `ltm` binary end to end: the demo on a tiny setting, and bad input
//! that must exit non-zero with a clear message.

use std::path::Path;
use std::process::Command;

fn ltm(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_ltm"))
        .args(args)
        .output()
        .expect("run ltm");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
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

#[test]
fn bad_input_exits_non_zero_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.ltm");
    std::fs::write(&junk, b"definitely not an ltm file").unwrap();
    let missing = dir.path().join("missing.raw");
    let out = dir.path().join("o.ltm");
    let cases: Vec<(Vec<&str>, &str)> = vec![
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
    ];
    for (args, expect) in cases {
        let (ok, _, stderr) = ltm(&args);
        assert!(!ok, "{args:?} succeeded");
        assert!(stderr.contains(expect), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
    assert!(!out.exists());
}
