//! Every command × every class of file hazard, against the binary.
//!
//! The command list comes from `ltm help`: a command this table does not
//! cover fails [`every_command_is_covered`]. Each class is one test that
//! runs over every command it applies to:
//! - an output that is an input, another output, or a link to an input;
//! - an output that is a device, a FIFO or `/proc/self/fd/1`;
//! - a second run to an output that a first run holds (its lock);
//! - a full disk;
//! - an input rewritten or truncated while the command reads it: the run
//!   fails with a message, or its output is exactly the output of the old
//!   or of the new input;
//! - a few hundred bytes that claim a huge matrix, under `ulimit -v`.
//!
//! Plus the regressions of issue 29's silent corruptions (two imports to
//! one output, bake outputs that are its inputs, partial files through
//! links) and the determinism of bakes.

use ltm_codec::OutputLock;
use ltm_testkit::{assert_disk_full_error, SmallDisk};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

const BIN: &str = env!("CARGO_BIN_EXE_ltm");

/// The inputs every case starts from, made once.
struct Corpus {
    dir: PathBuf,
    scene: PathBuf,
    mesh: PathBuf,
    tex_scene: PathBuf,
    raw: PathBuf,
    /// `scene`'s bake in two parts (`ltm bake --shard`).
    parts: [PathBuf; 2],
    /// `raw`'s analysis parts of a sharded compression in two shards.
    analyses: [PathBuf; 2],
    /// The coded parts of that run's last coding.
    coded: Vec<PathBuf>,
    ltm: PathBuf,
    tex_ltm: PathBuf,
    npy: PathBuf,
    env: PathBuf,
}

/// How the outputs of a command are named.
#[derive(Clone, Copy, PartialEq)]
enum Outs {
    /// None (`inspect`, `view`).
    None,
    /// `-o FILE`.
    One,
    /// `-o FILE --png FILE2`.
    Two,
    /// `-o DIR`, a folder of files.
    Folder,
}

/// The input a command reads during its run, and a copy of it with other
/// contents.
type Streamed = fn(&Corpus) -> (PathBuf, PathBuf);

/// One command of the table: its arguments for given outputs, the inputs
/// it names, and the input it reads during its run (if any).
struct Cmd {
    name: &'static str,
    outs: Outs,
    args: fn(&Corpus, &Path, &Path) -> Vec<String>,
    inputs: fn(&Corpus) -> Vec<PathBuf>,
    /// The file read while the command works (for the changed-input
    /// classes), and a copy of it with other contents of the same length.
    streamed: Option<Streamed>,
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

fn strs(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// The command table: every subcommand of `ltm help`, in its order.
fn commands() -> Vec<Cmd> {
    vec![
        Cmd {
            name: "demo",
            outs: Outs::Folder,
            args: |_, o, _| {
                let mut a = strs(&["demo", "--size", "16", "--face-res", "2", "-o"]);
                a.push(s(o));
                a
            },
            inputs: |_| vec![],
            streamed: None,
        },
        Cmd {
            name: "bake",
            outs: Outs::One,
            args: |c, o, _| vec!["bake".into(), s(&c.scene), "-o".into(), s(o)],
            inputs: |c| vec![c.scene.clone(), c.mesh.clone()],
            streamed: None,
        },
        // Its inputs cannot be swapped for other valid ones mid-run (a part
        // of another scene is refused), so it has no streamed input; a
        // part that changes during the merge is refused by its stamp.
        Cmd {
            name: "merge",
            outs: Outs::One,
            args: |c, o, _| {
                let mut a = vec!["merge".into()];
                a.extend(c.parts.iter().map(|p| s(p)));
                a.extend(["-o".into(), s(o)]);
                a
            },
            inputs: |c| c.parts.to_vec(),
            streamed: None,
        },
        Cmd {
            name: "import",
            outs: Outs::One,
            args: |c, o, _| {
                let mut a = vec!["import".into(), s(&c.npy)];
                a.extend(strs(&["--width", "24", "--height", "16", "-o"]));
                a.push(s(o));
                a
            },
            inputs: |c| vec![c.npy.clone()],
            streamed: Some(|c| (c.npy.clone(), c.dir.join("other.npy"))),
        },
        Cmd {
            name: "compress",
            outs: Outs::One,
            args: |c, o, _| vec!["compress".into(), s(&c.raw), "-o".into(), s(o)],
            inputs: |c| vec![c.raw.clone()],
            streamed: Some(|c| (c.raw.clone(), c.dir.join("other.raw"))),
        },
        // Like merge, parts cannot be swapped for other valid ones mid-run.
        Cmd {
            name: "plan",
            outs: Outs::One,
            args: |c, o, _| {
                let mut a = vec!["plan".into()];
                a.extend(c.analyses.iter().map(|p| s(p)));
                a.extend(["-o".into(), s(o)]);
                a
            },
            inputs: |c| c.analyses.to_vec(),
            streamed: None,
        },
        Cmd {
            name: "assemble",
            outs: Outs::One,
            args: |c, o, _| {
                let mut a = vec!["assemble".into()];
                a.extend(c.coded.iter().map(|p| s(p)));
                a.extend(["-o".into(), s(o)]);
                a
            },
            inputs: |c| c.coded.clone(),
            streamed: None,
        },
        Cmd {
            name: "inspect",
            outs: Outs::None,
            args: |c, _, _| vec!["inspect".into(), s(&c.ltm)],
            inputs: |c| vec![c.ltm.clone()],
            streamed: None,
        },
        Cmd {
            name: "export",
            outs: Outs::One,
            args: |c, o, _| vec!["export".into(), s(&c.ltm), "-o".into(), s(o)],
            inputs: |c| vec![c.ltm.clone()],
            streamed: Some(|c| (c.ltm.clone(), c.dir.join("other.ltm"))),
        },
        Cmd {
            name: "relight",
            outs: Outs::Two,
            args: |c, o, o2| {
                let mut a = vec!["relight".into(), s(&c.ltm), "--env".into(), s(&c.env)];
                a.extend(["--terms".into(), "all".into(), "-o".into(), s(o)]);
                a.extend(["--png".into(), s(o2)]);
                a
            },
            inputs: |c| vec![c.ltm.clone(), c.env.clone()],
            streamed: Some(|c| (c.ltm.clone(), c.dir.join("other.ltm"))),
        },
        Cmd {
            name: "render",
            outs: Outs::Two,
            args: |c, o, o2| {
                let mut a = vec!["render".into(), s(&c.tex_ltm), "--env".into(), s(&c.env)];
                a.extend(strs(&[
                    "--camera", "0,1,3", "--target", "0,0.5,0", "--size", "32x24",
                ]));
                a.extend(["-o".into(), s(o), "--png".into(), s(o2)]);
                a
            },
            inputs: |c| vec![c.tex_ltm.clone(), c.env.clone()],
            streamed: None,
        },
        Cmd {
            name: "reference",
            outs: Outs::Two,
            args: |c, o, o2| {
                let mut a = vec!["reference".into(), s(&c.raw), "--env".into(), s(&c.env)];
                a.extend(["-o".into(), s(o), "--png".into(), s(o2)]);
                a
            },
            inputs: |c| vec![c.raw.clone(), c.env.clone()],
            streamed: Some(|c| (c.raw.clone(), c.dir.join("other.raw"))),
        },
        Cmd {
            name: "report",
            outs: Outs::Folder,
            args: |c, o, _| {
                let mut a = vec!["report".into(), "--quick".into(), "--raw".into(), s(&c.raw)];
                a.extend(["--env".into(), s(&c.env), "-o".into(), s(o)]);
                a
            },
            inputs: |c| vec![c.raw.clone(), c.env.clone()],
            streamed: None,
        },
        // `view` writes nothing; its reading of files is tested in
        // view_api.rs, view_server.rs and budget.rs.
        Cmd {
            name: "view",
            outs: Outs::None,
            args: |c, _, _| vec!["view".into(), s(&c.ltm)],
            inputs: |c| vec![c.ltm.clone()],
            streamed: None,
        },
    ]
}

fn run(args: &[String]) -> Output {
    let out = Command::new(BIN).args(args).output().expect("run ltm");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    assert!(
        out.status.code().is_some(),
        "{args:?}: killed by a signal: {stderr}"
    );
    out
}

fn run_ok(args: &[String]) {
    let out = run(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Runs `args`, which must fail with exit code 1 and a message holding
/// `expect`.
fn fails(args: &[String], expect: &str) {
    let out = run(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{args:?} did not fail: {stderr}"
    );
    assert!(
        stderr.contains(expect),
        "{args:?}: expected '{expect}' in: {stderr}"
    );
}

/// Compresses `raw` in two shards in `dir`: the analysis parts `a0.json`
/// and `a1.json`, and the coded parts of the last coding (returned).
fn sharded_compression(dir: &Path, raw: &Path) -> Vec<PathBuf> {
    let (a0, a1) = (dir.join("a0.json"), dir.join("a1.json"));
    for (spec, a) in [("0/2", &a0), ("1/2", &a1)] {
        run_ok(&strs(&[
            "compress",
            &s(raw),
            "--analyze",
            "--shard",
            spec,
            "-o",
            &s(a),
        ]));
    }
    let mut coded: Vec<PathBuf> = Vec::new();
    for k in 1.. {
        let plan = dir.join(format!("plan-{k}.json"));
        let mut args = vec!["plan".to_string(), s(&a0), s(&a1)];
        args.extend(coded.iter().map(|c| s(c)));
        args.extend(["-o".into(), s(&plan)]);
        let out = run(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        if String::from_utf8_lossy(&out.stdout).trim() == "assemble" {
            break;
        }
        coded = (0..2)
            .map(|i| {
                let part = dir.join(format!("c-{k}-{i}.part"));
                let spec = format!("{i}/2");
                run_ok(&strs(&[
                    "compress",
                    &s(raw),
                    "--plan",
                    &s(&plan),
                    "--shard",
                    &spec,
                    "-o",
                    &s(&part),
                ]));
                part
            })
            .collect();
    }
    coded
}

fn corpus() -> &'static Corpus {
    static CORPUS: OnceLock<Corpus> = OnceLock::new();
    CORPUS.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        let p = |n: &str| dir.join(n);
        std::fs::write(p("box.obj"), ltm_testkit::blob_obj(6)).unwrap();
        let scene = ltm_testkit::scene_toml("box.obj", 24, 16, 4);
        std::fs::write(p("scene.toml"), &scene).unwrap();
        std::fs::write(
            p("tex.toml"),
            scene.clone() + ltm_testkit::TEXTURE_SPHERE_16,
        )
        .unwrap();
        let other = scene.replace("[0.7, 0.6, 0.5]", "[0.2, 0.6, 0.9]");
        std::fs::write(p("other.toml"), other).unwrap();
        let env = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/studio.exr");
        for (scene, raw) in [
            ("scene.toml", "t.raw"),
            ("tex.toml", "tex.raw"),
            ("other.toml", "other.raw"),
        ] {
            run_ok(&strs(&["bake", &s(&p(scene)), "-o", &s(&p(raw))]));
        }
        for k in 0..2 {
            let (spec, part) = (format!("{k}/2"), format!("t.part{k}.raw"));
            run_ok(&strs(&[
                "bake",
                &s(&p("scene.toml")),
                "--shard",
                &spec,
                "-o",
                &s(&p(&part)),
            ]));
        }
        for (raw, ltm) in [
            ("t.raw", "t.ltm"),
            ("tex.raw", "tex.ltm"),
            ("other.raw", "other.ltm"),
        ] {
            run_ok(&strs(&["compress", &s(&p(raw)), "-o", &s(&p(ltm))]));
        }
        let coded = sharded_compression(&dir, &p("t.raw"));
        for (ltm, npy) in [("t.ltm", "t.npy"), ("other.ltm", "other.npy")] {
            run_ok(&strs(&["export", &s(&p(ltm)), "-o", &s(&p(npy))]));
        }
        Corpus {
            scene: p("scene.toml"),
            mesh: p("box.obj"),
            tex_scene: p("tex.toml"),
            raw: p("t.raw"),
            parts: [p("t.part0.raw"), p("t.part1.raw")],
            analyses: [p("a0.json"), p("a1.json")],
            coded,
            ltm: p("t.ltm"),
            tex_ltm: p("tex.ltm"),
            npy: p("t.npy"),
            env,
            dir,
        }
    })
}

/// The subcommands `ltm help` lists.
fn cli_commands() -> Vec<String> {
    let out = run(&strs(&["help"]));
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let list = text.split("Commands:").nth(1).expect("a command list");
    let list = list.split("Options:").next().unwrap();
    list.lines()
        .filter_map(|l| l.strip_prefix("  "))
        .filter(|l| !l.starts_with(' '))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect()
}

#[test]
fn every_command_is_covered() {
    let table: Vec<&str> = commands().iter().map(|c| c.name).collect();
    let cli = cli_commands();
    assert!(cli.len() >= 11, "{cli:?}");
    for c in &cli {
        assert!(
            table.contains(&c.as_str()),
            "command `{c}` has no row in the reliability matrix"
        );
    }
}

/// A fresh folder for one case's outputs.
fn scratch() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

#[test]
fn outputs_that_are_inputs_or_links_to_them_are_refused() {
    let c = corpus();
    for cmd in commands().iter().filter(|c| c.outs != Outs::None) {
        let d = scratch();
        let png = d.path().join("o.png");
        for input in (cmd.inputs)(c) {
            let before = std::fs::read(&input).unwrap();
            let link = d.path().join("link");
            let _ = std::fs::remove_file(&link);
            std::os::unix::fs::symlink(&input, &link).unwrap();
            for out in [&input, &link] {
                let args = (cmd.args)(c, out, &png);
                let expect = if cmd.outs == Outs::Folder {
                    "is not a folder"
                } else {
                    "refusing to overwrite an input"
                };
                fails(&args, expect);
                assert_eq!(
                    std::fs::read(&input).unwrap(),
                    before,
                    "{}: the input changed",
                    cmd.name
                );
            }
        }
        if cmd.outs == Outs::Two {
            let out = d.path().join("same");
            fails(&(cmd.args)(c, &out, &out), "name the same file");
        }
    }
}

#[test]
fn devices_fifos_and_stdout_as_outputs_are_refused() {
    let c = corpus();
    let d = scratch();
    let dev = d.path().join("null");
    std::os::unix::fs::symlink("/dev/null", &dev).unwrap();
    let fifo = d.path().join("fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let stdout = PathBuf::from("/proc/self/fd/1");
    for cmd in commands().iter().filter(|c| c.outs != Outs::None) {
        let png = d.path().join(format!("{}.png", cmd.name));
        for (out, word) in [(&dev, "device"), (&fifo, "FIFO"), (&stdout, "FIFO")] {
            let word = if cmd.outs == Outs::Folder {
                "is not a folder"
            } else {
                word
            };
            fails(&(cmd.args)(c, out, &png), word);
        }
        if cmd.outs == Outs::Two {
            fails(&(cmd.args)(c, &d.path().join("o.exr"), &fifo), "FIFO");
        }
    }
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
}

#[test]
fn a_second_run_to_a_locked_output_fails_and_leaves_it_alone() {
    let c = corpus();
    for cmd in commands().iter().filter(|c| c.outs != Outs::None) {
        let d = scratch();
        let out = d.path().join("out");
        let png = d.path().join("out.png");
        // What another ltm run holds while it writes `out`.
        let held = OutputLock::acquire(&out).unwrap();
        fails(&(cmd.args)(c, &out, &png), "another ltm run is writing");
        assert!(!out.exists(), "{}: wrote a locked output", cmd.name);
        assert!(!png.exists(), "{}: wrote beside a locked output", cmd.name);
        drop(held);
        assert!(!ltm_codec::output::lock_path(&out).exists());
    }
}

#[test]
fn a_full_disk_is_an_error_that_leaves_nothing() {
    let Some(disk) = SmallDisk::mount() else {
        return;
    };
    disk.fill();
    let c = corpus();
    for cmd in commands()
        .iter()
        .filter(|c| !matches!(c.outs, Outs::None | Outs::Folder))
    {
        let out = disk.path().join("out");
        let png = disk.path().join("out.png");
        let run = run(&(cmd.args)(c, &out, &png));
        assert_disk_full_error(&run, cmd.name);
        assert_eq!(disk.files(), ["filler"], "{}: left files behind", cmd.name);
    }
}

/// Runs `cmd` while `change` rewrites its streamed input after `delay`:
/// the run fails with a message, or its output equals the output of the
/// input before or after the change.
fn race(cmd: &Cmd, change: fn(&Path, &Path), delay: Duration) {
    let c = corpus();
    let (input, other) = (cmd.streamed.unwrap())(c);
    let d = scratch();
    let work = d.path().join(input.file_name().unwrap());
    let mut outputs = Vec::new();
    // The outputs of the two inputs, each run alone.
    for (k, src) in [&input, &other].into_iter().enumerate() {
        std::fs::copy(src, &work).unwrap();
        let out = d.path().join(format!("expect{k}"));
        run_ok(&swap(
            &(cmd.args)(c, &out, &d.path().join(format!("expect{k}.png"))),
            &input,
            &work,
        ));
        outputs.push(std::fs::read(&out).unwrap());
    }
    std::fs::copy(&input, &work).unwrap();
    let out = d.path().join("raced");
    let png = d.path().join("raced.png");
    let args = swap(&(cmd.args)(c, &out, &png), &input, &work);
    let child = Command::new(BIN)
        .args(&args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(delay);
    change(&work, &other);
    let result = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        result.status.code().is_some(),
        "{}: killed by a signal: {stderr}",
        cmd.name
    );
    assert!(!stderr.contains("panicked"), "{}: {stderr}", cmd.name);
    if result.status.success() {
        let got = std::fs::read(&out).unwrap();
        assert!(
            outputs.contains(&got),
            "{}: the output mixes the old and the new input",
            cmd.name
        );
    } else {
        assert!(!out.exists(), "{}: a failed run left its output", cmd.name);
        assert_eq!(result.status.code(), Some(1), "{}: {stderr}", cmd.name);
        assert!(
            stderr.lines().any(|l| l.starts_with("error")),
            "{}: no message: {stderr}",
            cmd.name
        );
    }
}

/// `args` with `from` replaced by `to`.
fn swap(args: &[String], from: &Path, to: &Path) -> Vec<String> {
    args.iter()
        .map(|a| if a == &s(from) { s(to) } else { a.clone() })
        .collect()
}

/// Rewrites `work` in place with the bytes of `other` (same length).
fn rewrite(work: &Path, other: &Path) {
    use std::io::{Seek, Write};
    let bytes = std::fs::read(other).unwrap();
    let mut f = std::fs::OpenOptions::new().write(true).open(work).unwrap();
    f.seek(std::io::SeekFrom::Start(0)).unwrap();
    f.write_all(&bytes).unwrap();
    f.set_len(bytes.len() as u64).unwrap();
}

fn truncate(work: &Path, _other: &Path) {
    let len = std::fs::metadata(work).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(work)
        .unwrap()
        .set_len(len / 2)
        .unwrap();
}

#[test]
fn inputs_changed_or_truncated_during_a_run_never_mix_into_an_output() {
    for cmd in commands().iter().filter(|c| c.streamed.is_some()) {
        for ms in [0, 20, 80] {
            race(cmd, rewrite, Duration::from_millis(ms));
            race(cmd, truncate, Duration::from_millis(ms));
        }
    }
}

#[test]
fn two_imports_to_one_output_give_one_whole_array() {
    let c = corpus();
    let d = scratch();
    let out = d.path().join("both.raw");
    let import = |npy: &Path| {
        let mut a = vec!["import".to_string(), s(npy)];
        a.extend(strs(&["--width", "24", "--height", "16", "-o", &s(&out)]));
        Command::new(BIN)
            .args(&a)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let other = c.dir.join("other.npy");
    for _ in 0..4 {
        let _ = std::fs::remove_file(&out);
        let (a, b) = (import(&c.npy), import(&other));
        let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
        for r in [&a, &b] {
            let e = String::from_utf8_lossy(&r.stderr);
            assert!(
                r.status.success() || e.contains("another ltm run is writing"),
                "{e}"
            );
        }
        assert!(a.status.success() || b.status.success());
        // The store holds one array, whole: it exports to one of the two.
        let back = d.path().join("back.npy");
        let ltm = d.path().join("back.ltm");
        run_ok(&strs(&[
            "compress",
            &s(&out),
            "-o",
            &s(&ltm),
            "--mode",
            "2d",
            "--bits",
            "16",
            "--max-error",
            "0.001",
        ]));
        run_ok(&strs(&["export", &s(&ltm), "-o", &s(&back)]));
        let got = npy_values(&back);
        let near = |npy: &Path| {
            let want = npy_values(npy);
            let err: f64 = got.iter().zip(&want).map(|(g, w)| (g - w) * (g - w)).sum();
            let norm: f64 = want.iter().map(|w| w * w).sum();
            (err / norm).sqrt() < 0.01
        };
        assert!(near(&c.npy) || near(&other), "the store mixes two arrays");
        std::fs::remove_file(&ltm).unwrap();
        std::fs::remove_file(&back).unwrap();
    }
}

/// The float32 values of an `.npy` file written by `ltm export`.
fn npy_values(path: &Path) -> Vec<f64> {
    let bytes = std::fs::read(path).unwrap();
    let header = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    bytes[10 + header..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64)
        .collect()
}

#[test]
fn partial_files_are_never_written_through_links() {
    let c = corpus();
    let d = scratch();
    let victim = d.path().join("victim");
    std::fs::write(&victim, b"keep me").unwrap();
    let out = d.path().join("o.raw");
    std::os::unix::fs::symlink(&victim, d.path().join("o.raw.partial")).unwrap();
    fails(
        &strs(&["bake", &s(&c.scene), "-o", &s(&out)]),
        "symbolic link",
    );
    let mut import = vec!["import".to_string(), s(&c.npy)];
    import.extend(strs(&["--width", "24", "--height", "16", "-o", &s(&out)]));
    fails(&import, "symbolic link");
    assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
    std::fs::remove_file(d.path().join("o.raw.partial")).unwrap();
    std::os::unix::fs::symlink(&victim, ltm_codec::output::lock_path(&out)).unwrap();
    fails(&import, "symbolic link");
    assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
}

/// Bakes `scene` to `out` with `threads` worker threads.
fn bake_with_threads(scene: &Path, out: &Path, threads: &str) {
    let args = strs(&["bake", &s(scene), "-o", &s(out)]);
    let r = Command::new(BIN)
        .args(&args)
        .env("RAYON_NUM_THREADS", threads)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

#[test]
fn bakes_are_byte_identical_across_runs_and_thread_counts() {
    let c = corpus();
    let d = scratch();
    for scene in [&c.scene, &c.tex_scene] {
        let mut stores = Vec::new();
        for (k, threads) in ["1", "2", "1", "2"].into_iter().enumerate() {
            let out = d.path().join(format!("{k}.raw"));
            bake_with_threads(scene, &out, threads);
            stores.push(std::fs::read(&out).unwrap());
        }
        for (k, st) in stores.iter().enumerate().skip(1) {
            assert!(
                st == &stores[0],
                "{}: bake {k} differs from bake 0",
                scene.display()
            );
        }
    }
}

#[test]
fn a_resumed_texture_bake_keeps_rows_only_for_the_same_surface() {
    let c = corpus();
    let d = scratch();
    let out = d.path().join("tex.raw");
    bake_with_threads(&c.tex_scene, &out, "2");
    let whole = std::fs::read(&out).unwrap();
    // An interrupted bake of the same scene resumes, and ends identical.
    std::fs::rename(&out, d.path().join("tex.raw.partial")).unwrap();
    let r = run(&strs(&["bake", &s(&c.tex_scene), "-o", &s(&out)]));
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(
        r.status.success() && stderr.contains("resuming"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&out).unwrap(), whole);
}

#[test]
fn issue_29_messages() {
    let c = corpus();
    let d = scratch();
    // bake checks its output before any work, and leaves no DIR.partial.
    let folder = d.path().join("folder");
    std::fs::create_dir(&folder).unwrap();
    fails(
        &strs(&["bake", &s(&c.scene), "-o", &s(&folder)]),
        "is a folder",
    );
    assert!(!d.path().join("folder.partial").exists());
    // A store larger than the disk is refused before the bake starts.
    let big = strs(&["bake", &s(&c.scene), "-o", &s(&d.path().join("big.raw"))]);
    let big = [
        big,
        strs(&["--width", "8192", "--height", "8192", "--face-res", "128"]),
    ]
    .concat();
    fails(&big, "bytes free");
    // report checks its SH orders before any work.
    let report = d.path().join("report");
    let args = strs(&[
        "report",
        "--quick",
        "--raw",
        &s(&c.raw),
        "--sh-orders",
        "100000",
        "-o",
        &s(&report),
    ]);
    fails(&args, "--sh-orders 100000 is out of range (valid: 1..=");
    assert!(!report.exists());
    // --max-memory takes every suffix its message names.
    run_ok(&strs(&["--max-memory", "2E", "inspect", &s(&c.ltm)]));
    // A truncated .npy says so.
    let npy = std::fs::read(&c.npy).unwrap();
    let short = d.path().join("short.npy");
    std::fs::write(&short, &npy[..60]).unwrap();
    let import = strs(&[
        "import",
        &s(&short),
        "--width",
        "24",
        "--height",
        "16",
        "-o",
        &s(&d.path().join("i.raw")),
    ]);
    fails(&import, "truncated");
    // pca compress of a matrix of full rank below the default --max-rank.
    run_ok(&strs(&[
        "compress",
        &s(&c.raw),
        "--mode",
        "pca",
        "-o",
        &s(&d.path().join("p.ltm")),
    ]));
}

#[test]
fn an_orbit_that_fails_at_a_late_view_leaves_no_view() {
    let Some(disk) = SmallDisk::mount() else {
        return;
    };
    // About 96 KiB free: the first views fit, not all sixteen.
    let keep = disk.path().join("keep");
    disk.fill();
    std::fs::remove_file(disk.path().join("filler")).unwrap();
    std::fs::write(&keep, vec![0u8; 1024 * 1024 - 96 * 1024]).unwrap();
    let c = corpus();
    let out = disk.path().join("view.exr");
    let mut args = strs(&[
        "render",
        &s(&c.tex_ltm),
        "--env",
        &s(&c.env),
        "--camera",
        "0,1,3",
        "--target",
        "0,0.5,0",
    ]);
    args.extend(strs(&["--size", "96x96", "--views", "16", "-o", &s(&out)]));
    let r = run(&args);
    assert_disk_full_error(&r, "render --views 16");
    assert_eq!(disk.files(), ["keep"], "views were left behind");
}

/// A version-1 raw store header claiming 8192² pixels × 6·128² lights
/// (26 TB) with an albedo image, followed by its block table: 72 bytes.
fn raw_bomb(path: &Path) {
    let (w, h, n) = (8192u64, 8192u64, 128u64);
    let p = w * h;
    let flags_offset = 64 + 8;
    let albedo_offset = (flags_offset + p).div_ceil(64) * 64;
    let data_offset = (albedo_offset + 12 * p).div_ceil(4096) * 4096;
    let mut b = b"LTMRAW\0\x01".to_vec();
    for v in [1u32, 1, w as u32, h as u32, n as u32, 1, p as u32, 1] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend_from_slice(&data_offset.to_le_bytes());
    b.extend_from_slice(&albedo_offset.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    let crc = crc32fast::hash(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b.extend_from_slice(&[1, 0, 0, 0, 0, 0, 0, 0]);
    std::fs::write(path, b).unwrap();
}

/// An `.npy` header claiming a (2^26, 6·128²) float32 array, and no data.
fn npy_bomb(path: &Path) {
    let mut dict =
        "{'descr': '<f4', 'fortran_order': False, 'shape': (67108864, 98304), }".to_string();
    while !(10 + dict.len() + 1).is_multiple_of(64) {
        dict.push(' ');
    }
    dict.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    b.extend_from_slice(dict.as_bytes());
    std::fs::write(path, b).unwrap();
}

/// An analysis part of a sharded compression (from `src`) claiming 2^40
/// columns with a term-count target (no analysis to check them against).
fn json_bomb(src: &Path, path: &Path) {
    let mut part: serde_json::Value = serde_json::from_slice(&std::fs::read(src).unwrap()).unwrap();
    let huge = serde_json::json!(1u64 << 40);
    part["run"]["lights"] = huge.clone();
    part["run"]["shards"] = serde_json::json!(1);
    part["run"]["options"]["target"] = serde_json::json!({"Keep": 1u64 << 40});
    part["shard"] = serde_json::json!(0);
    part["columns"] = serde_json::json!({"start": 0, "end": huge});
    part["analysis"] = serde_json::Value::Null;
    std::fs::write(path, serde_json::to_vec(&part).unwrap()).unwrap();
}

/// A coded part (from `src`) whose header claims 2^40 columns, with every
/// length and checksum of its framing valid (docs/FORMAT.md, "Coded
/// part").
fn part_bomb(src: &Path, path: &Path) {
    let b = std::fs::read(src).unwrap();
    let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap()) as usize;
    let t = b.len() - 48;
    let (payloads, measures, header) = (u64_at(t), u64_at(t + 8), u64_at(t + 16));
    let at = 16 + payloads + measures;
    let mut json: serde_json::Value = serde_json::from_slice(&b[at..at + header]).unwrap();
    json["columns"]["end"] = serde_json::json!(1u64 << 40);
    let json = serde_json::to_vec(&json).unwrap();
    let mut out = b[..at].to_vec();
    out.extend_from_slice(&json);
    let mut trailer = Vec::new();
    for v in [payloads, measures, json.len()] {
        trailer.extend_from_slice(&(v as u64).to_le_bytes());
    }
    trailer.extend_from_slice(&b[t + 24..t + 32]);
    trailer.extend_from_slice(&crc32fast::hash(&json).to_le_bytes());
    trailer.extend_from_slice(&crc32fast::hash(&trailer).to_le_bytes());
    trailer.extend_from_slice(b"LTMCPART");
    out.extend_from_slice(&trailer);
    std::fs::write(path, out).unwrap();
}

/// Runs `args` under a 3 GB address-space limit.
fn run_limited(args: &[String]) -> Output {
    let script = "ulimit -v 3000000; exec \"$0\" \"$@\"";
    let out = Command::new("sh")
        .arg("-c")
        .arg(script)
        .arg(BIN)
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    out
}

#[test]
fn files_that_claim_huge_matrices_are_refused_under_an_address_space_limit() {
    let c = corpus();
    let d = scratch();
    let bombs = d.path();
    raw_bomb(&bombs.join("bomb.raw"));
    npy_bomb(&bombs.join("bomb.npy"));
    json_bomb(&c.analyses[0], &bombs.join("bomb.json"));
    part_bomb(&c.coded[0], &bombs.join("bomb.part"));
    let scene = std::fs::read_to_string(&c.scene).unwrap();
    let scene = scene
        .replace("width = 24", "width = 8192")
        .replace("height = 16", "height = 8192");
    let scene = scene
        .replace("face_res = 4", "face_res = 128")
        .replace("box.obj", &s(&c.mesh));
    std::fs::write(bombs.join("bomb.toml"), scene).unwrap();
    let ltm_bomb = ltm_testkit::ltm_claiming_8192(bombs);
    let mut covered = Vec::new();
    for cmd in commands() {
        let inputs = (cmd.inputs)(c);
        let out = d.path().join(format!("{}.out", cmd.name));
        let mut args = (cmd.args)(c, &out, &d.path().join(format!("{}.png", cmd.name)));
        for input in &inputs {
            let ext = input.extension().and_then(|e| e.to_str()).unwrap_or("");
            let bomb = match ext {
                "raw" | "npy" | "toml" | "json" | "part" => bombs.join(format!("bomb.{ext}")),
                "ltm" => ltm_bomb.clone(),
                _ => continue,
            };
            args = swap(&args, input, &bomb);
        }
        if args == (cmd.args)(c, &out, &d.path().join(format!("{}.png", cmd.name))) {
            continue;
        }
        if cmd.name == "view" {
            // It serves until stopped: budget.rs requests a frame of the
            // same file from a running `ltm view`.
            continue;
        }
        // An error naming the problem, or success (`inspect` reads only
        // the tables); never a signal.
        let r = run_limited(&args);
        let stderr = String::from_utf8_lossy(&r.stderr);
        let code = r.status.code();
        assert!(
            code == Some(0) || code == Some(1),
            "{}: {code:?} {stderr}",
            cmd.name
        );
        assert!(
            code == Some(0) || stderr.starts_with("error"),
            "{}: {stderr}",
            cmd.name
        );
        covered.push(cmd.name);
    }
    // demo reads only the repository's assets; view is in budget.rs.
    assert_eq!(covered.len(), commands().len() - 2, "{covered:?}");
}

#[test]
fn two_bakes_to_one_output_give_one_whole_store() {
    let c = corpus();
    let d = scratch();
    let out = d.path().join("both.raw");
    let other_scene = c.dir.join("other.toml");
    let want = [
        std::fs::read(&c.raw).unwrap(),
        std::fs::read(c.dir.join("other.raw")).unwrap(),
    ];
    let bake = |scene: &Path| {
        let a = strs(&["bake", &s(scene), "-o", &s(&out)]);
        Command::new(BIN)
            .args(&a)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    for _ in 0..3 {
        let _ = std::fs::remove_file(&out);
        let (a, b) = (bake(&c.scene), bake(&other_scene));
        let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
        for r in [&a, &b] {
            let e = String::from_utf8_lossy(&r.stderr);
            assert!(
                r.status.success() || e.contains("another ltm run is writing"),
                "{e}"
            );
        }
        let got = std::fs::read(&out).unwrap();
        assert!(
            want.contains(&got),
            "the store is not one scene's whole bake"
        );
        assert!(!d.path().join("both.raw.partial").exists());
    }
}
