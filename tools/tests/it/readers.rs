//! Readers against the binary, under inputs that change or hold extreme
//! values: an `.ltm` file, a raw store or an `.npy` array truncated and
//! rewritten while `export`, `relight --terms all`, `view`, `reference`,
//! `compress` and `import` read it ends the run with exit 1 and a message, or with the output of the
//! unchanged input, never with a signal (no reader maps a file); a
//! `--reference` image with a NaN or infinite pixel, or all zero, is
//! refused; lighting near the `f32` limit relights to a finite image, as
//! `reference` computes it.

use ltm_codec::Dims;
use ltm_testkit::{block_bytes, run, run_ok, run_output, write_raw};
use std::fs::OpenOptions;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::os::unix::fs::FileExt;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

const BIN: &str = env!("CARGO_BIN_EXE_ltm");

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 48×40 RGB store of 96 lights (about 2 MB) and its compressed file.
fn fixture(dir: &Path) -> (PathBuf, PathBuf) {
    let dims = Dims::image(48, 40, 4, 3);
    let t: Vec<f32> = (0..dims.pixels() * dims.row_len())
        .map(|i| ((i % 97) as f32 * 0.13).sin().abs() * 1e-2)
        .collect();
    let raw = write_raw(&dir.join("s.raw"), dims, &t, None, block_bytes(dims, 64));
    let ltm = dir.join("s.ltm");
    run_ok(BIN, &["compress", s(&raw), "-o", s(&ltm)]);
    (raw, ltm)
}

fn envmap() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/interior.exr")
}

/// Truncates `victim` in place to a fraction of its length and writes it
/// back, over and over, until `stop`; leaves it whole.
fn hammer(victim: &Path, original: &[u8], stop: &AtomicBool) {
    let f = OpenOptions::new().write(true).open(victim).unwrap();
    let mut k = 0u64;
    while !stop.load(Ordering::Relaxed) {
        f.set_len(original.len() as u64 * (k % 4) / 4).unwrap();
        std::thread::sleep(Duration::from_micros(200 + 300 * (k % 5)));
        f.write_all_at(original, 0).unwrap();
        std::thread::sleep(Duration::from_micros(400));
        k += 1;
    }
    f.write_all_at(original, 0).unwrap();
    f.set_len(original.len() as u64).unwrap();
}

/// `ltm args` while another thread truncates and rewrites `victim`.
fn run_while_truncating(args: &[&str], victim: &Path) -> Output {
    let original = std::fs::read(victim).unwrap();
    let stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let h = scope.spawn(|| hammer(victim, &original, &stop));
        let out = run_output(BIN, args);
        stop.store(true, Ordering::Relaxed);
        h.join().unwrap();
        out
    })
}

/// The run ended by exit 0 with `output` holding `want`, or by exit 1 with
/// a message; never by a signal.
fn assert_clean(out: &Output, what: &str, output: &Path, want: &[u8]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.signal(),
        None,
        "{what}: killed by a signal: {stderr}"
    );
    match out.status.code() {
        Some(0) => assert!(
            std::fs::read(output).unwrap() == want,
            "{what}: succeeded with another output"
        ),
        Some(1) => assert!(
            stderr.starts_with("error: ") && !output.exists(),
            "{what}: {stderr}"
        ),
        c => panic!("{what}: exit code {c:?}: {stderr}"),
    }
    let _ = std::fs::remove_file(output);
}

#[test]
fn inputs_truncated_while_read_give_an_error_or_the_right_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (raw, ltm) = fixture(d);
    let env = envmap();
    let out = |name: &str| d.join(name);
    // An array to import: the export of the compressed file.
    let npy = out("a.npy");
    run_ok(BIN, &["export", s(&ltm), "-o", s(&npy)]);
    let mut cases: Vec<(Vec<String>, &Path, PathBuf)> = vec![
        (
            vec![
                "export".into(),
                s(&ltm).into(),
                "-o".into(),
                s(&out("e.npy")).into(),
            ],
            &ltm,
            out("e.npy"),
        ),
        (
            ["relight", s(&ltm), "--env", s(&env), "--terms", "all", "-o"]
                .map(String::from)
                .into_iter()
                .chain([s(&out("r.exr")).to_string()])
                .collect(),
            &ltm,
            out("r.exr"),
        ),
        (
            ["reference", s(&raw), "--env", s(&env), "-o"]
                .map(String::from)
                .into_iter()
                .chain([s(&out("x.exr")).to_string()])
                .collect(),
            &raw,
            out("x.exr"),
        ),
        (
            vec![
                "compress".into(),
                s(&raw).into(),
                "-o".into(),
                s(&out("c.ltm")).into(),
            ],
            &raw,
            out("c.ltm"),
        ),
    ];
    cases.push((
        ["import", s(&npy), "--width", "48", "--height", "40", "-o"]
            .map(String::from)
            .into_iter()
            .chain([s(&out("i.raw")).to_string()])
            .collect(),
        &npy,
        out("i.raw"),
    ));
    for (args, victim, output) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        // The output of the unchanged input.
        run_ok(BIN, &args);
        let want = std::fs::read(output).unwrap();
        std::fs::remove_file(output).unwrap();
        for round in 0..4 {
            let what = format!("{} (round {round})", args[0]);
            let result = run_while_truncating(&args, victim);
            assert_clean(&result, &what, output, &want);
        }
        // Truncated before the run: an error that says so.
        let original = std::fs::read(victim).unwrap();
        let f = OpenOptions::new().write(true).open(victim).unwrap();
        f.set_len(original.len() as u64 / 2).unwrap();
        let r = run(BIN, &args);
        assert!(!r.ok && r.stderr.starts_with("error: "), "{}", r.stderr);
        f.write_all_at(&original, 0).unwrap();
    }
}

/// `ltm view` reads its files whole at start: truncating the `.ltm` while
/// its columns are still being decoded in the background changes nothing.
#[test]
fn view_serves_frames_of_a_file_truncated_after_start() {
    let dir = tempfile::tempdir().unwrap();
    let (_, ltm) = fixture(dir.path());
    let original = std::fs::read(&ltm).unwrap();
    let mut child = Command::new(BIN)
        .args(["view", s(&ltm), "--env", s(&envmap()), "--port", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("http://")
        .and_then(|s| s.strip_suffix('/'))
        .unwrap_or_else(|| panic!("no URL: {line}"))
        .to_string();
    let f = OpenOptions::new().write(true).open(&ltm).unwrap();
    f.set_len(0).unwrap();
    for n in [1, 96] {
        let mut c = TcpStream::connect(&addr).unwrap();
        c.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        let target = format!("/api/frame?file=0&map=0&yaw=0&pitch=0&roll=0&n={n}");
        write!(
            c,
            "GET {target} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut answer = Vec::new();
        let _ = c.read_to_end(&mut answer);
        let head = String::from_utf8_lossy(&answer[..answer.len().min(40)]).into_owned();
        assert!(head.starts_with("HTTP/1.1 200"), "N = {n}: {head}");
    }
    // Give the background preload time to run into the truncated range.
    std::thread::sleep(Duration::from_millis(500));
    let alive = child.try_wait().unwrap().is_none();
    let _ = child.kill();
    let status = child.wait().unwrap();
    f.write_all_at(&original, 0).unwrap();
    assert!(alive, "ltm view died: {status:?}");
}

/// An OpenEXR file of `w × h` pixels, any values (the library's writer
/// refuses non-finite ones).
fn write_exr(path: &Path, w: usize, h: usize, px: impl Fn(usize, usize) -> f32 + Sync) {
    exr::prelude::write_rgb_file(path, w, h, |x, y| (px(x, y), px(x, y), px(x, y))).unwrap();
}

#[test]
fn references_that_are_not_finite_or_all_zero_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, ltm) = fixture(d);
    let env = envmap();
    let cases: [(&str, f32, &str); 3] = [
        ("nan.exr", f32::NAN, "reference pixel (3, 2)"),
        ("inf.exr", f32::INFINITY, "reference pixel (3, 2)"),
        ("zero.exr", 0.0, "all zero"),
    ];
    for (name, bad, expect) in cases {
        let reference = d.join(name);
        write_exr(&reference, 48, 40, |x, y| {
            if (x, y) == (3, 2) || bad == 0.0 {
                bad
            } else {
                0.25
            }
        });
        let o = d.join("o.exr");
        let r = run(
            BIN,
            &[
                "relight",
                s(&ltm),
                "--env",
                s(&env),
                "-o",
                s(&o),
                "--reference",
                s(&reference),
            ],
        );
        assert!(!r.ok, "{name}: {}", r.stderr);
        assert!(
            r.stderr.contains(expect) && r.stderr.lines().count() == 1,
            "{name}: {}",
            r.stderr
        );
    }
}

/// A map of 3e38 everywhere: `reference` and `relight` both give finite
/// images, and they agree.
#[test]
fn lighting_near_the_f32_limit_relights_as_reference_computes_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (raw, ltm) = fixture(d);
    let map = d.join("huge.exr");
    write_exr(&map, 32, 16, |_, _| 3e38);
    let exact = d.join("exact.exr");
    run_ok(
        BIN,
        &["reference", s(&raw), "--env", s(&map), "-o", s(&exact)],
    );
    let relit = d.join("relit.exr");
    let r = run(
        BIN,
        &[
            "relight",
            s(&ltm),
            "--env",
            s(&map),
            "--terms",
            "all",
            "-o",
            s(&relit),
            "--reference",
            s(&exact),
        ],
    );
    assert!(r.ok, "{}", r.stderr);
    let error: f64 = r
        .stderr
        .lines()
        .find_map(|l| l.strip_prefix("relative L2 error against the reference: "))
        .unwrap_or_else(|| panic!("no error line: {}", r.stderr))
        .trim()
        .parse()
        .unwrap();
    assert!(error.is_finite() && error < 0.05, "{error}");
}
