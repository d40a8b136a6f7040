//! Faults a tool that feeds hours of later work must survive: each test
//! injects one and checks that `ltm` exits with a message (not a signal),
//! leaves no wrong output and no temporary file behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn ltm(args: &[&str]) -> Output {
    ltm_testkit::run_output(env!("CARGO_BIN_EXE_ltm"), args)
}

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets")
}

use ltm_testkit::{assert_disk_full_error, SmallDisk};

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn full_disk_during_import_is_an_error_and_leaves_nothing() {
    let Some(disk) = SmallDisk::mount() else {
        return;
    };
    // A (64·64, 6·8²) float32 matrix: 1.5 MiB, more than the disk holds.
    let src = tempfile::tempdir().unwrap();
    let npy = src.path().join("t.npy");
    let (p, m) = (64 * 64, 6 * 8 * 8);
    let mut dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({p}, {m}), }}");
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.extend((0..p * m).flat_map(|i| ((i % 7) as f32 * 0.1).to_le_bytes()));
    std::fs::write(&npy, bytes).unwrap();
    let out = disk.path().join("t.raw");
    let run = ltm(&[
        "import",
        npy.to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "64",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_disk_full_error(&run, "import");
    assert!(
        files_in(disk.path()).is_empty(),
        "{:?}",
        files_in(disk.path())
    );
}

#[test]
fn full_disk_during_bake_is_an_error() {
    let Some(disk) = SmallDisk::mount() else {
        return;
    };
    // 48·48 pixels × 6·8² lights × 4 bytes = 3.5 MiB of rows.
    let out = disk.path().join("s.raw");
    let scene = assets().join("scenes/default.toml");
    let run = ltm(&[
        "bake",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "48",
        "--height",
        "48",
        "--face-res",
        "8",
        "--texel-samples",
        "1",
    ]);
    assert_disk_full_error(&run, "bake");
    assert!(!out.exists(), "a bake that failed left its output");
}

/// Bakes and compresses a tiny matrix of the default scene into `dir`.
fn tiny_ltm(dir: &Path) -> PathBuf {
    let raw = dir.join("t.raw");
    let ltm_path = dir.join("t.ltm");
    let scene = assets().join("scenes/default.toml");
    let out = ltm(&[
        "bake",
        scene.to_str().unwrap(),
        "-o",
        raw.to_str().unwrap(),
        "--width",
        "8",
        "--height",
        "8",
        "--face-res",
        "2",
        "--texel-samples",
        "1",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = ltm(&[
        "compress",
        raw.to_str().unwrap(),
        "-o",
        ltm_path.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    ltm_path
}

#[test]
fn a_closed_output_pipe_ends_the_command_quietly() {
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let file = tiny_ltm(dir.path());
    // The reading end of stdout is closed before ltm writes to it.
    let mut child = Command::new(env!("CARGO_BIN_EXE_ltm"))
        .args(["inspect", file.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.is_empty(), "not quiet: {stderr}");
    assert_ne!(out.status.code(), Some(101), "panicked");
}

/// Runs `ltm` expecting a refusal whose message contains `needle`, with the
/// listed files unchanged.
fn assert_refused(args: &[&str], needle: &str, unchanged: &[&Path]) {
    let before: Vec<Vec<u8>> = unchanged
        .iter()
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    let out = ltm(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{args:?} was not refused: {stderr}"
    );
    assert!(stderr.contains(needle), "{args:?}: {stderr}");
    for (p, b) in unchanged.iter().zip(before) {
        assert_eq!(
            std::fs::read(p).unwrap(),
            b,
            "{args:?} changed {}",
            p.display()
        );
    }
}

#[test]
fn an_output_that_names_an_input_or_another_output_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ltm_file = tiny_ltm(d);
    let raw = d.join("t.raw");
    let env = assets().join("envmaps/sunset.exr");
    let env_copy = d.join("env.exr");
    std::fs::copy(&env, &env_copy).unwrap();
    let hard = d.join("hard.ltm");
    std::fs::hard_link(&ltm_file, &hard).unwrap();
    let reference = d.join("ref.exr");
    let made = ltm(&[
        "reference",
        raw.to_str().unwrap(),
        "--env",
        env_copy.to_str().unwrap(),
        "-o",
        reference.to_str().unwrap(),
    ]);
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (raw_s, ltm_s, env_s, ref_s) = (s(&raw), s(&ltm_file), s(&env_copy), s(&reference));
    let dotted = format!("{}/./sub/../t.ltm", d.display());
    std::fs::create_dir(d.join("sub")).unwrap();
    let input = "refusing to overwrite an input";
    assert_refused(&["compress", &raw_s, "-o", &raw_s], input, &[&raw]);
    assert_refused(&["export", &ltm_s, "-o", &ltm_s], input, &[&ltm_file]);
    assert_refused(&["export", &ltm_s, "-o", &s(&hard)], input, &[&ltm_file]);
    assert_refused(&["export", &ltm_s, "-o", &dotted], input, &[&ltm_file]);
    let relight = |o: &str, extra: &[&str]| {
        let mut v = vec!["relight", &ltm_s, "--env", &env_s, "-o", o];
        v.extend_from_slice(extra);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let run = |args: Vec<String>, needle: &str, unchanged: &[&Path]| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_refused(&a, needle, unchanged);
    };
    run(relight(&env_s, &[]), input, &[&env_copy]);
    run(
        relight(&ref_s, &["--reference", &ref_s]),
        input,
        &[&reference],
    );
    // A name without an image extension passes both flags' name checks.
    let x = s(&d.join("x.out"));
    run(relight(&x, &["--png", &x]), "name the same file", &[]);
    assert!(!d.join("x.out").exists());
    run(
        vec!["reference", &raw_s, "--env", &env_s, "-o", &env_s]
            .into_iter()
            .map(String::from)
            .collect(),
        input,
        &[&env_copy],
    );
    assert_refused(&["compress", &raw_s, "-o", &s(d)], "is a folder", &[]);
    assert_refused(
        &["compress", &raw_s, "-o", &s(&d.join("missing/t.ltm"))],
        "does not exist",
        &[],
    );
}

#[test]
fn two_runs_writing_one_output_do_not_collide() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    tiny_ltm(d);
    let (raw, out) = (d.join("t.raw"), d.join("same.ltm"));
    let spawn = |bits: &str| {
        Command::new(env!("CARGO_BIN_EXE_ltm"))
            .args([
                "compress",
                raw.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ])
            .args(["--bits", bits])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    for _ in 0..4 {
        let (a, b) = (spawn("8"), spawn("12"));
        // Each run succeeds, or finds the other holding the output's lock.
        let mut ok = 0;
        for child in [a, b] {
            let o = child.wait_with_output().unwrap();
            let e = String::from_utf8_lossy(&o.stderr);
            assert!(
                o.status.success() || e.contains("another ltm run is writing"),
                "{e}"
            );
            ok += usize::from(o.status.success());
        }
        assert!(ok >= 1);
        // The output is one run's whole file, and nothing else is left.
        let inspect = ltm(&["inspect", out.to_str().unwrap()]);
        assert!(
            inspect.status.success(),
            "{}",
            String::from_utf8_lossy(&inspect.stderr)
        );
        let left: Vec<String> = files_in(d)
            .into_iter()
            .filter(|f| f.ends_with(".tmp") || f.ends_with(".lock"))
            .collect();
        assert!(left.is_empty(), "{left:?}");
    }
}

#[test]
fn a_folder_given_as_a_file_is_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_str().unwrap();
    let out_dir = tempfile::tempdir().unwrap();
    let npy = out_dir.path().join("x.npy");
    let ltm_out = out_dir.path().join("x.ltm");
    for args in [
        vec!["inspect", d],
        vec!["export", d, "-o", npy.to_str().unwrap()],
    ] {
        let out = ltm(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains("folder") && !stderr.contains("No such device"),
            "{args:?}: {stderr}"
        );
    }
    let raw = ltm(&["compress", d, "-o", ltm_out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&raw.stderr);
    assert!(stderr.contains("folder"), "{stderr}");
}

/// A tiny, valid `.ltm` that claims 8192×8192 pixels and 6·2² lights, with
/// every column empty: a few hundred bytes that would decode to 6.4 GB.
fn huge_claim(dir: &Path) -> PathBuf {
    use ltm_codec::column::{EncodedColumn, SparseColumn};
    use ltm_codec::compress::Mode;
    use ltm_codec::container::{LtmWriter, Meta};
    use ltm_codec::{Dims, Filter};
    let meta = Meta {
        dims: Dims::image(8192, 8192, 2, 1),
        mode: Mode::TwoD,
        row_filter: Filter::Haar,
        col_filter: Filter::LeGall53,
        bits: 10,
        seed: 0,
        target_error: 0.01,
        achieved_error: 0.0,
        terms: 0,
        norm: 1.0,
    };
    let path = dir.join("huge.ltm");
    let mut w = LtmWriter::create(&path, meta, None).unwrap();
    for _ in 0..24 {
        w.push_column(EncodedColumn::new(&SparseColumn::default(), 1, 3))
            .unwrap();
    }
    w.finish(0.0).unwrap();
    assert!(std::fs::metadata(&path).unwrap().len() < 2000);
    path
}

#[test]
fn allocations_sized_by_a_file_are_bounded_by_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    let huge = huge_claim(dir.path());
    let h = huge.to_str().unwrap();
    let npy = dir.path().join("x.npy");
    let exr = dir.path().join("x.exr");
    let env = assets().join("envmaps/sunset.exr");
    // Exit code 1 for a refused file, 2 for a bad command line.
    let check = |args: &[&str], needle: &str| {
        let out = ltm(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        let code = if needle == "out of range" { 2 } else { 1 };
        assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    };
    // 8192²·24·4 bytes = 6 GiB: over a budget of 4 GiB.
    check(
        &[
            "export",
            h,
            "-o",
            npy.to_str().unwrap(),
            "--max-memory",
            "4G",
        ],
        "needs 6442450944 bytes",
    );
    check(
        &[
            "relight",
            h,
            "--env",
            env.to_str().unwrap(),
            "-o",
            exr.to_str().unwrap(),
            "--max-memory",
            "64M",
        ],
        "left of the memory budget of 67108864 bytes",
    );
    check(&["inspect", h, "--max-memory", "12"], "out of range");
    assert!(!npy.exists() && !exr.exists());
    // Within the limit the same file opens.
    let out = ltm(&["inspect", h]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn long_commands_check_their_settings_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = out.to_str().unwrap();
    let a = assets();
    let a = a.to_str().unwrap();
    let bad_map = dir.path().join("bad.exr");
    std::fs::write(&bad_map, b"not an exr").unwrap();
    let m = bad_map.to_str().unwrap();
    for (args, needle) in [
        (vec!["demo", "-o", o, "--assets", a, "--bits", "40"], "bits"),
        (
            vec!["demo", "-o", o, "--assets", a, "--max-error", "2"],
            "error",
        ),
        (vec!["report", "-o", o, "--quick", "--env", m], "bad.exr"),
        (vec!["report", "-o", o, "--quick", "--bits", "1"], "bits"),
    ] {
        let run = ltm(&args);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} started work before failing");
    }
}
