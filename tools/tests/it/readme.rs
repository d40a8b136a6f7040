//! The README's command blocks, run as written.
//!
//! Every ```sh block of README.md that uses `$ltm` runs in bash (`set -e`)
//! in a temporary folder that holds what the blocks reference:
//! `assets/envmaps` (linked), `assets/meshes` (linked) and
//! `assets/scenes/*.toml`, copied small ([`SMALL_SCENES`], [`SUBSTITUTED`]). The blocks run
//! in README order in that one folder, so that a later block finds the
//! files an earlier one wrote. Substitutions, all listed here:
//!
//! - lines that build or install ([`SKIPPED`]) are not run;
//! - `target/release/ltm` is a link to the binary under test;
//! - [`SUBSTITUTED`] replaces a few settings whose full size would take
//!   minutes;
//! - `$ltm view ...` runs in the background on a free port until it prints
//!   its URL, and is then stopped.
//!
//! A failing command fails the test with the README line it is on.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_ltm");

/// Lines that start with these words are not run: they build or install.
const SKIPPED: &[&str] = &["cargo", "pip"];

/// A setting of a copied scene: `(table, key, value)`.
type Setting = (&'static str, &'static str, &'static str);

/// Settings of the copied scenes, by file. Every scene file must be
/// listed, and every key must be in its file.
const SMALL_SCENES: &[(&str, &[Setting])] = &[
    (
        "default.toml",
        &[
            ("camera", "width", "32"),
            ("camera", "height", "32"),
            // 6·8² = 384 lights: room for the README's PCA rank 256.
            ("lighting", "face_res", "8"),
            ("lighting", "texel_samples", "1"),
        ],
    ),
    (
        "atlas.toml",
        &[
            ("lighting", "face_res", "4"),
            // The smallest square the charts of the three parts fit in.
            ("texture", "size", "64"),
            ("texture", "spp", "1"),
        ],
    ),
    (
        "area_light.toml",
        &[
            ("camera", "width", "32"),
            ("camera", "height", "24"),
            ("lighting", "face_res", "4"),
            ("light_plane", "order", "16"),
        ],
    ),
    (
        "bunny_texture.toml",
        &[
            ("lighting", "face_res", "4"),
            ("texture", "size", "32"),
            ("texture", "spp", "1"),
        ],
    ),
];

/// Text replaced in the copied scenes and in the commands: the 75k-triangle
/// bunny scan takes about a minute of xatlas charting or spherical
/// parameterization, its 3.7k-triangle version seconds ([`fitted_bunny`]
/// puts it where the scan is); a 256² texture of the bunny is 64× the rows
/// of a 32² one; glossy rotation matrices at n = 64 take seconds to build.
const SUBSTITUTED: &[(&str, &str)] = &[
    ("../meshes/bunny.ply", "../bunny_small_fitted.obj"),
    ("--texture-size 256", "--texture-size 32"),
    // 323 MB of rotation matrices at n = 64 (about 6 s); a few MB at 16.
    ("--glossy-n 64", "--glossy-n 16"),
];

/// Writes `assets/bunny_small_fitted.obj`: `meshes/bunny_small.obj` moved
/// and scaled onto the box of `meshes/bunny.ply` (centred on the origin,
/// 0.987 high), so that the scenes' transforms place it as they place the
/// scan.
fn fitted_bunny(assets: &Path, out: &Path) {
    let text = fs::read_to_string(assets.join("meshes/bunny_small.obj")).unwrap();
    let vertex = |l: &str| -> Option<[f64; 3]> {
        let mut w = l.strip_prefix("v ")?.split_whitespace();
        let mut c = || w.next()?.parse::<f64>().ok();
        Some([c()?, c()?, c()?])
    };
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for v in text.lines().filter_map(vertex) {
        for (k, x) in v.into_iter().enumerate() {
            lo[k] = lo[k].min(x);
            hi[k] = hi[k].max(x);
        }
    }
    let scale = 0.987 / (hi[1] - lo[1]);
    let fit = |l: &str| match vertex(l) {
        Some(v) => {
            let c: Vec<String> = (0..3)
                .map(|k| ((v[k] - (lo[k] + hi[k]) / 2.0) * scale).to_string())
                .collect();
            format!("v {}", c.join(" "))
        }
        None => l.to_string(),
    };
    let lines: Vec<String> = text.lines().map(fit).collect();
    fs::write(out, lines.join("\n") + "\n").unwrap();
}

/// A ```sh block of the README: the line number (1-based) of its first
/// line and its lines.
struct Block {
    first_line: usize,
    lines: Vec<String>,
}

/// The ```sh blocks of `readme` that use `$ltm`.
fn ltm_blocks(readme: &str) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut open: Option<Block> = None;
    for (i, line) in readme.lines().enumerate() {
        match open.as_mut() {
            None if line.trim_end() == "```sh" => {
                open = Some(Block {
                    first_line: i + 2,
                    lines: Vec::new(),
                })
            }
            Some(_) if line.trim_end() == "```" => blocks.extend(open.take()),
            Some(b) => b.lines.push(line.to_string()),
            None => {}
        }
    }
    assert!(open.is_none(), "README.md: a ```sh block is not closed");
    blocks.retain(|b| b.lines.iter().any(|l| l.contains("$ltm")));
    blocks
}

/// A block's line as bash runs it: skipped lines become `:` (so line
/// numbers stay), `$ltm view` runs briefly, substitutions apply.
fn runnable(line: &str) -> String {
    let first = line.split_whitespace().next().unwrap_or("");
    if SKIPPED.contains(&first) {
        return format!(": skipped: {line}");
    }
    let mut line = line.to_string();
    for (from, to) in SUBSTITUTED {
        line = line.replace(from, to);
    }
    match line.trim_start().strip_prefix("$ltm view ") {
        Some(args) => {
            let args = args.split(" #").next().unwrap_or(args).trim_end();
            let port = if args.contains("--port") {
                ""
            } else {
                " --port 0"
            };
            format!("serve_briefly \"$ltm\" view {args}{port}")
        }
        None => line,
    }
}

/// Bash run before each block: `$ltm`, the report of a failing line, and
/// `serve_briefly CMD...`, which starts a server in the background, waits
/// (at most 60 s) for the URL it prints and stops it.
fn prelude() -> String {
    format!(
        r#"set -e
trap 'echo "FAILED at script line $LINENO: $BASH_COMMAND" >&2' ERR
ltm='{BIN}'
serve_briefly() {{
  "$@" > view.log 2>&1 &
  local pid=$! i
  for i in $(seq 600); do
    if grep -q 'http://127.0.0.1:[0-9]*/' view.log; then
      kill "$pid" 2>/dev/null || true
      wait "$pid" 2>/dev/null || true
      return 0
    fi
    if ! kill -0 "$pid" 2>/dev/null; then
      cat view.log >&2; echo "the server exited without printing its URL" >&2
      return 1
    fi
    sleep 0.1
  done
  kill "$pid" 2>/dev/null || true
  cat view.log >&2; echo "no URL within 60 s" >&2
  return 1
}}
"#
    )
}

/// Runs one block in `dir`; on failure, the message names the README line
/// of the failing command.
fn run_block(dir: &Path, block: &Block) -> Result<(), String> {
    let prelude = prelude();
    let body: Vec<String> = block.lines.iter().map(|l| runnable(l)).collect();
    let script = format!("{prelude}{}\n", body.join("\n"));
    let path = dir.join("block.sh");
    fs::write(&path, script).unwrap();
    let out = Command::new("bash")
        .arg(&path)
        .current_dir(dir)
        .output()
        .expect("run bash");
    if out.status.success() {
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    let at = stderr
        .lines()
        .filter_map(|l| l.strip_prefix("FAILED at script line "))
        .filter_map(|l| l.split(':').next()?.parse::<usize>().ok())
        .next_back()
        .and_then(|n| n.checked_sub(prelude.lines().count() + 1))
        .map_or("a line of its prelude".to_string(), |k| {
            format!("README.md line {}", block.first_line + k)
        });
    Err(format!(
        "the README block at line {} failed at {at} ({}):\n{stderr}",
        block.first_line, out.status
    ))
}

/// Output files a block's comments name with a view number
/// (`atlas-000.exr … atlas-002.exr`): each must exist after the block.
fn named_outputs(block: &Block) -> Vec<String> {
    let words = block
        .lines
        .iter()
        .filter_map(|l| l.split_once('#').map(|(_, c)| c))
        .flat_map(str::split_whitespace);
    words
        .map(|w| w.trim_matches(|c: char| ",()".contains(c)))
        .filter(|w| {
            let stem = w.rsplit_once('.').map_or("", |(s, _)| s);
            let digits = stem.rsplit_once('-').map_or("", |(_, d)| d);
            digits.len() == 3 && digits.bytes().all(|b| b.is_ascii_digit())
        })
        .map(str::to_string)
        .collect()
}

/// Rewrites `key = value` lines of a scene file's tables to `small`;
/// panics when a key is not in its table.
fn shrink_scene(text: &str, small: &[Setting]) -> String {
    let mut used = vec![false; small.len()];
    let mut table = String::new();
    let mut out = Vec::new();
    for line in text.lines() {
        if let Some(name) = line.trim().strip_prefix('[') {
            table = name.trim_matches(|c| c == '[' || c == ']').to_string();
        }
        let key = line.split('=').next().unwrap_or("").trim();
        match small.iter().position(|(t, k, _)| *t == table && *k == key) {
            Some(i) => {
                used[i] = true;
                out.push(format!("{key} = {}", small[i].2));
            }
            None => out.push(line.to_string()),
        }
    }
    for ((t, k, _), used) in small.iter().zip(used) {
        assert!(used, "no key {k} in [{t}] of a scene file");
    }
    let mut text = out.join("\n") + "\n";
    for (from, to) in SUBSTITUTED {
        text = text.replace(from, to);
    }
    text
}

/// A folder with `assets/` as the README's commands need it: maps and
/// meshes linked, every scene copied small, and `target/release/ltm`.
fn workspace(dir: &Path) {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let scenes = dir.join("assets/scenes");
    fs::create_dir_all(&scenes).unwrap();
    fs::create_dir_all(dir.join("target/release")).unwrap();
    std::os::unix::fs::symlink(BIN, dir.join("target/release/ltm")).unwrap();
    for sub in ["envmaps", "meshes"] {
        std::os::unix::fs::symlink(assets.join(sub), dir.join("assets").join(sub)).unwrap();
    }
    fitted_bunny(&assets, &dir.join("assets/bunny_small_fitted.obj"));
    for entry in fs::read_dir(assets.join("scenes")).unwrap() {
        let path: PathBuf = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        if !name.ends_with(".toml") {
            continue;
        }
        let small = SMALL_SCENES
            .iter()
            .find(|(n, _)| *n == name)
            .unwrap_or_else(|| panic!("no small settings for assets/scenes/{name}"));
        let text = fs::read_to_string(&path).unwrap();
        fs::write(scenes.join(&name), shrink_scene(&text, small.1)).unwrap();
    }
}

/// Every `$ltm` block of README.md runs without an error, in README order,
/// and writes the numbered views its comments name.
#[test]
fn readme_command_blocks_run() {
    let readme = fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md"))
        .expect("README.md");
    let blocks = ltm_blocks(&readme);
    assert!(blocks.len() >= 6, "only {} $ltm blocks", blocks.len());
    let dir = tempfile::tempdir().unwrap();
    workspace(dir.path());
    for block in &blocks {
        let start = std::time::Instant::now();
        if let Err(e) = run_block(dir.path(), block) {
            panic!("{e}");
        }
        for name in named_outputs(block) {
            assert!(
                dir.path().join(&name).is_file(),
                "the README block at line {} names {name}, which it did not write",
                block.first_line
            );
        }
        eprintln!(
            "README block at line {}: {:.1?}",
            block.first_line,
            start.elapsed()
        );
    }
}

/// A broken command in a block fails its run, naming the README line of the
/// command; a `cargo` line is skipped, and a line after the failure does
/// not run.
#[test]
fn a_broken_command_names_its_readme_line() {
    let dir = tempfile::tempdir().unwrap();
    let block = Block {
        first_line: 10,
        lines: vec![
            "cargo build --release".to_string(),
            "$ltm --help > /dev/null   # fine".to_string(),
            "$ltm compress missing.raw \\".to_string(),
            "    -o out.ltm".to_string(),
            "touch after".to_string(),
        ],
    };
    let e = run_block(dir.path(), &block).unwrap_err();
    assert!(
        e.contains("README.md line 12") || e.contains("README.md line 13"),
        "{e}"
    );
    assert!(e.contains("compress"), "{e}");
    assert!(!dir.path().join("after").exists());
    let renamed = Block {
        first_line: 1,
        lines: vec!["$ltm inspect --no-such-flag x.ltm".to_string()],
    };
    let e = run_block(dir.path(), &renamed).unwrap_err();
    assert!(e.contains("README.md line 1"), "{e}");
}

/// The view line runs in the background until its URL; a server that
/// cannot start (a file that is not there) fails the block.
#[test]
fn view_lines_run_until_their_url() {
    assert_eq!(
        runnable("$ltm view scene.ltm      # prints http://127.0.0.1:8080/"),
        "serve_briefly \"$ltm\" view scene.ltm --port 0"
    );
    let dir = tempfile::tempdir().unwrap();
    let block = Block {
        first_line: 1,
        lines: vec!["$ltm view missing.ltm".to_string()],
    };
    let e = run_block(dir.path(), &block).unwrap_err();
    assert!(e.contains("README.md line 1"), "{e}");
}
