//! The memory budget, against the binary: a few hundred bytes claiming an
//! 8192² image get a clear error naming the budget (or succeed), never a
//! signal, under a 3 GB address-space limit (`ulimit -v 3000000`, where the
//! default budget follows the limit) and with the default settings, in every
//! command that reads an `.ltm` file; and `ltm view` makes the first frame
//! of a small pca file.

use ltm_codec::{compress_pca, Dims, PcaOptions, RawHeader, RawStore, RawWriter};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Duration;

/// The address-space limit of the limited runs, in KiB (about 2.9 GiB).
const ADDRESS_SPACE_KIB: &str = "3000000";

fn envmap() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/interior.exr")
}

/// `ltm ARGS`, under `ulimit -v` when `limited`.
fn ltm(limited: bool, args: &[&str]) -> Command {
    let bin = env!("CARGO_BIN_EXE_ltm");
    let mut c = Command::new("sh");
    let script = if limited {
        format!("ulimit -v {ADDRESS_SPACE_KIB}; exec \"$0\" \"$@\"")
    } else {
        "exec \"$0\" \"$@\"".to_string()
    };
    c.arg("-c").arg(script).arg(bin).args(args);
    c
}

/// A small valid pca file (12×10 pixels, 6·2² lights, rank 4).
fn small_pca(dir: &Path) -> PathBuf {
    let dims = Dims::image(12, 10, 2, 3);
    let t: Vec<f32> = (0..dims.pixels() * dims.row_len())
        .map(|i| ((i % 37) as f32 * 0.11).sin().abs() * 1e-2)
        .collect();
    let header = RawHeader::new(dims, false, 1 << 16);
    let raw = RawWriter::write_dense(&dir.join("small.raw"), header, &t, None).unwrap();
    let raw = RawStore::open(&raw).unwrap();
    let path = dir.join("small-pca.ltm");
    let opts = PcaOptions {
        rank: Some(4),
        ..Default::default()
    };
    compress_pca(&raw, &path, &opts, ltm_codec::Progress::NONE).unwrap();
    path
}

/// Checks that a run ended by an exit code (0, or 1 with a message that
/// names the memory budget), not by a signal. `ltm render` of an
/// image-space file may instead say that it needs a texture-space one.
fn assert_clean(out: &Output, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("{what}: {:?}: {}", out.status, stderr.trim());
    let other = what.contains("render") && stderr.contains("image-space file");
    match out.status.code() {
        Some(0) => {}
        Some(1) => assert!(
            stderr.contains("memory budget") || other,
            "{what}: the message does not name the budget: {stderr}"
        ),
        _ => panic!(
            "{what}: ended by {:?} (a signal?), not by exit code 0 or 1: {stderr}",
            out.status
        ),
    }
}

/// Runs every file-reading command on `file` (but `view`).
fn run_commands(limited: bool, file: &Path, out: &Path) -> Vec<(String, Output)> {
    let f = file.to_str().unwrap();
    let env = envmap();
    let env = env.to_str().unwrap();
    let o = |name: &str| out.join(name).to_str().unwrap().to_string();
    let runs: Vec<Vec<String>> = vec![
        vec!["inspect".into(), f.into()],
        vec![
            "relight".into(),
            f.into(),
            "--env".into(),
            env.into(),
            "-o".into(),
            o("relit.exr"),
        ],
        vec![
            "render".into(),
            f.into(),
            "--env".into(),
            env.into(),
            "--camera".into(),
            "0,0,3".into(),
            "--target".into(),
            "0,0,0".into(),
            "-o".into(),
            o("view.exr"),
        ],
        vec!["export".into(), f.into(), "-o".into(), o("dense.npy")],
    ];
    runs.into_iter()
        .map(|args| {
            let a: Vec<&str> = args.iter().map(String::as_str).collect();
            let output = ltm(limited, &a).output().expect("run ltm");
            for name in ["relit.exr", "view.exr", "dense.npy"] {
                let _ = std::fs::remove_file(out.join(name));
            }
            (format!("ltm {} (limited: {limited})", args[0]), output)
        })
        .collect()
}

/// `ltm view FILE` (under `ulimit -v` when `limited`): starts it, asks for
/// its first frame and returns the HTTP status and body, or the exit
/// status and stderr of a server that refused to start.
fn view_first_frame(limited: bool, file: &Path) -> Result<(u16, String), Output> {
    let env = envmap();
    let mut child = ltm(
        limited,
        &[
            "view",
            file.to_str().unwrap(),
            "--env",
            env.to_str().unwrap(),
            "--port",
            "0",
        ],
    )
    .stdout(Stdio::piped())
    .stderr(Stdio::piped())
    .spawn()
    .expect("start ltm view");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let Some(addr) = line
        .trim()
        .strip_prefix("http://")
        .and_then(|s| s.strip_suffix('/'))
    else {
        return Err(child.wait_with_output().unwrap());
    };
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(600))).unwrap();
    let target = "/api/frame?file=0&map=0&yaw=0&pitch=0&roll=0&n=4&weighting=transport";
    write!(
        s,
        "GET {target} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut answer = Vec::new();
    let _ = s.read_to_end(&mut answer);
    let alive = child.try_wait().unwrap().is_none();
    let _ = child.kill();
    let ended = child.wait().unwrap();
    assert!(alive, "ltm view died on its first frame: {ended:?}");
    let text = String::from_utf8_lossy(&answer).into_owned();
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no HTTP answer: {text:?}"));
    Ok((status, text))
}

/// Checks a view's first frame: served (200, unless `refused`), or refused
/// with a message naming the budget (HTTP 400, or a server that exits 1 at
/// start).
fn assert_view_clean(result: Result<(u16, String), Output>, what: &str, refused: bool) {
    match result {
        Ok((200, _)) => assert!(!refused, "{what}: the first frame was served"),
        Ok((status, text)) => assert!(
            status == 400 && text.contains("memory budget"),
            "{what}: first frame answered {status}: {text}"
        ),
        Err(out) => {
            assert_clean(&out, what);
            if refused {
                assert_eq!(out.status.code(), Some(1), "{what}");
            }
        }
    }
}

/// Runs every command on the crafted file, under the address-space limit
/// or with the default settings.
fn claims_8192_everywhere(limited: bool) {
    let dir = tempfile::tempdir().unwrap();
    let file = ltm_testkit::ltm_claiming_8192(dir.path());
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    for (what, output) in run_commands(limited, &file, &out) {
        assert_clean(&output, &what);
        if limited && !what.contains("inspect") {
            // Under 3 GB, every command that decodes runs out of budget
            // (render first says that an image-space file has no mesh) and
            // says how to raise it.
            assert_eq!(output.status.code(), Some(1), "{what}");
            let stderr = String::from_utf8_lossy(&output.stderr);
            assert!(
                stderr.contains("--max-memory") || what.contains("render"),
                "{what}: {stderr}"
            );
        }
    }
    assert_view_clean(
        view_first_frame(limited, &file),
        &format!("ltm view (limited: {limited})"),
        limited,
    );
    if limited {
        // The message names what, how many bytes, and the budget.
        let env = envmap();
        let f = file.to_str().unwrap();
        let a = ["relight", f, "--env", env.to_str().unwrap(), "-o", "x.exr"];
        let output = ltm(true, &a).current_dir(&out).output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            stderr.contains("needs") && stderr.contains("bytes left of the memory budget of"),
            "{stderr}"
        );
    }
}

#[test]
fn a_small_file_claiming_8192_squared_pixels_gets_a_message_under_3_gb() {
    claims_8192_everywhere(true);
}

#[test]
fn a_small_file_claiming_8192_squared_pixels_gets_a_message_or_an_image_by_default() {
    claims_8192_everywhere(false);
}

#[test]
fn view_serves_the_first_frame_of_a_small_pca_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = small_pca(dir.path());
    for limited in [true, false] {
        match view_first_frame(limited, &file) {
            Ok((status, text)) => assert_eq!(status, 200, "limited: {limited}: {text}"),
            Err(out) => panic!(
                "ltm view did not start (limited: {limited}): {}",
                String::from_utf8_lossy(&out.stderr)
            ),
        }
    }
}

#[test]
fn max_memory_overrides_the_default_budget() {
    let dir = tempfile::tempdir().unwrap();
    let file = small_pca(dir.path());
    let f = file.to_str().unwrap();
    let args = ["export", f, "-o", "x.npy"];
    let ok = ltm(false, &args).current_dir(dir.path()).output().unwrap();
    assert_eq!(ok.status.code(), Some(0), "{ok:?}");
    let big = ltm_testkit::ltm_claiming_8192(dir.path());
    let args = [
        "--max-memory",
        "1M",
        "export",
        big.to_str().unwrap(),
        "-o",
        "y.npy",
    ];
    let refused = ltm(false, &args).current_dir(dir.path()).output().unwrap();
    assert_clean(&refused, "export under 1M");
    assert_eq!(refused.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("memory budget of 1048576 bytes"),
        "{stderr}"
    );
}
