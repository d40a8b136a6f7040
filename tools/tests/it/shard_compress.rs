//! Sharded compression through the `ltm` binary: `ltm compress --analyze
//! --shard`, `ltm plan`, `ltm compress --plan --shard` and `ltm assemble`
//! give the file of a one-machine `ltm compress`, byte for byte, for N = 1,
//! 2, 4 and 7 shards (7 does not divide the columns), on an RGB image
//! matrix and on a texture matrix with its surface data and mesh, under
//! several options; every stage refuses parts of another run, plan or
//! shard count, gaps, duplicates and damaged parts with a message naming
//! the file and the problem, and leaves no output.

use ltm_testkit::{blob_obj, scene_toml, TEXTURE_SPHERE_16};
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_ltm");

/// Runs `ltm` with `args` and `env` (scheduler variables cleared); returns
/// (success, stdout, stderr).
fn ltm_env(args: &[&str], env: &[(&str, &str)]) -> (bool, String, String) {
    let mut cmd = Command::new(BIN);
    cmd.args(args);
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_STEP",
    ]
    .into_iter()
    .chain([
        "SLURM_ARRAY_TASK_COUNT",
        "JOB_COMPLETION_INDEX",
        "LTM_SHARD_COUNT",
    ]) {
        cmd.env_remove(var);
    }
    cmd.envs(env.iter().copied());
    let out = cmd.output().expect("run ltm");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    (out.status.success(), stdout, stderr)
}

/// Runs `ltm` with `args`, which must succeed; returns its stdout.
fn ok(args: &[&str]) -> String {
    let (ok, stdout, stderr) = ltm_env(args, &[]);
    assert!(ok, "ltm {args:?} failed: {stderr}");
    stdout
}

/// `ltm args` fails with a message containing every one of `expect`, and
/// leaves no `out`.
fn fails(args: &[&str], out: &Path, expect: &[&str]) {
    let (ok, _, stderr) = ltm_env(args, &[]);
    assert!(!ok, "{args:?} succeeded");
    for e in expect {
        assert!(stderr.contains(e), "{args:?}: expected {e:?} in: {stderr}");
    }
    assert!(!out.exists(), "a failed {args:?} left {}", out.display());
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Bakes the blob scene (plus `extra` TOML) at `width`×`height`, n = 4,
/// into `dir/scene.raw`.
fn bake(dir: &Path, width: u32, height: u32, extra: &str) -> PathBuf {
    std::fs::write(dir.join("blob.obj"), blob_obj(3)).unwrap();
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, scene_toml("blob.obj", width, height, 4) + extra).unwrap();
    let raw = dir.join("scene.raw");
    ok(&["bake", s(&scene), "-o", s(&raw)]);
    raw
}

/// The files of a sharded run of `raw` in `n` shards with the coding
/// options `opts`, in `dir`: the analysis parts, and per coding its plan
/// and coded parts.
struct Run {
    dir: PathBuf,
    raw: PathBuf,
    n: usize,
    analyses: Vec<PathBuf>,
}

impl Run {
    /// Stage 1 on every shard.
    fn analyze(dir: &Path, raw: &Path, n: usize, opts: &[&str]) -> Run {
        let dir = dir.join(format!("run-{n}"));
        std::fs::create_dir_all(&dir).unwrap();
        let analyses = (0..n)
            .map(|i| {
                let out = dir.join(format!("a-{i}.json"));
                let spec = format!("{i}/{n}");
                let mut args = vec![
                    "compress",
                    s(raw),
                    "--analyze",
                    "--shard",
                    &spec,
                    "-o",
                    s(&out),
                ];
                args.extend(opts);
                ok(&args);
                out
            })
            .collect();
        Run {
            dir,
            raw: raw.into(),
            n,
            analyses,
        }
    }

    /// `ltm plan` over the analyses and `coded`: the word it printed.
    fn plan(&self, coded: &[PathBuf], out: &Path) -> String {
        let mut args = vec!["plan"];
        args.extend(self.analyses.iter().chain(coded).map(|p| s(p)));
        args.extend(["-o", s(out)]);
        ok(&args).trim().to_string()
    }

    /// Codes every shard with `plan`: the coded parts of coding `k`.
    fn code(&self, plan: &Path, k: usize) -> Vec<PathBuf> {
        (0..self.n)
            .map(|i| {
                let out = self.dir.join(format!("c-{k}-{i}.part"));
                let spec = format!("{i}/{}", self.n);
                ok(&[
                    "compress",
                    s(&self.raw),
                    "--plan",
                    s(plan),
                    "--shard",
                    &spec,
                    "-o",
                    s(&out),
                ]);
                out
            })
            .collect()
    }

    /// The whole loop, as a scheduler runs it: plan, code, plan again
    /// while `ltm plan` says `code`, then assemble. Returns the file and
    /// every coding's parts.
    fn finish(&self) -> (PathBuf, Vec<Vec<PathBuf>>) {
        let mut codings: Vec<Vec<PathBuf>> = Vec::new();
        loop {
            let plan = self.dir.join(format!("plan-{}.json", codings.len() + 1));
            let word = self.plan(codings.last().map_or(&[][..], |c| &c[..]), &plan);
            match word.as_str() {
                "code" => codings.push(self.code(&plan, codings.len() + 1)),
                "assemble" => break,
                w => panic!("ltm plan printed {w:?}"),
            }
            assert!(codings.len() <= 16, "no end to the codings");
        }
        let out = self.dir.join("sharded.ltm");
        let mut args = vec!["assemble"];
        args.extend(codings.last().unwrap().iter().map(|p| s(p)));
        args.extend(["-o", s(&out)]);
        ok(&args);
        (out, codings)
    }
}

/// The quantization bits of the plan file `path`.
fn plan_bits(path: &Path) -> u64 {
    let plan: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    plan["step"]["bits"].as_u64().unwrap()
}

/// The one-machine file of `raw` with `opts`.
fn one_machine(dir: &Path, raw: &Path, opts: &[&str]) -> Vec<u8> {
    let out = dir.join("one.ltm");
    let mut args = vec!["compress", s(raw), "-o", s(&out)];
    args.extend(opts);
    ok(&args);
    std::fs::read(out).unwrap()
}

/// Sharded runs of `raw` with `opts` in every count of `counts` give the
/// one-machine file; returns how many codings each took.
fn check_identical(dir: &Path, raw: &Path, opts: &[&str], counts: &[usize]) -> Vec<usize> {
    let whole = one_machine(dir, raw, opts);
    counts
        .iter()
        .map(|&n| {
            let run = Run::analyze(dir, raw, n, opts);
            let (file, codings) = run.finish();
            let sharded = std::fs::read(&file).unwrap();
            let first = sharded.iter().zip(&whole).position(|(a, b)| a != b);
            assert!(
                sharded == whole,
                "{n} shards, {opts:?}: the file differs from one machine's ({} and {} bytes, first difference at {first:?}) {:?} {:?}",
                sharded.len(),
                whole.len(), &sharded[96..140], &whole[96..140]
            );
            codings.len()
        })
        .collect()
}

#[test]
fn image_rows_sharded_equal_one_machine() {
    let dir = tempfile::tempdir().unwrap();
    let raw = bake(dir.path(), 24, 18, "");
    let codings = check_identical(dir.path(), &raw, &[], &[1, 2, 4, 7]);
    // The default target error needed the feedback loop here: the test
    // covers plans made from coded parts.
    assert!(codings.iter().all(|&c| c >= 2), "codings {codings:?}");
    let sub = dir.path().join("keep");
    std::fs::create_dir(&sub).unwrap();
    check_identical(
        &sub,
        &raw,
        &["--keep", "12", "--mode", "2d", "--entropy", "zstd"],
        &[3],
    );
}

#[test]
fn texture_rows_sharded_equal_one_machine() {
    let dir = tempfile::tempdir().unwrap();
    let raw = bake(dir.path(), 8, 6, TEXTURE_SPHERE_16);
    let opts = [
        "--max-error",
        "0.003",
        "--bits",
        "6",
        "--col-filter",
        "cdf97",
    ];
    check_identical(dir.path(), &raw, &opts, &[1, 2, 4, 7]);
    let sub = dir.path().join("raised");
    std::fs::create_dir(&sub).unwrap();
    // Without --bits, the peak quantizer's too few bits are raised: a
    // coding at more bits.
    let opts = [
        "--max-error",
        "0.0003",
        "--mode",
        "4d",
        "--quantizer",
        "peak",
    ];
    check_identical(&sub, &raw, &opts, &[2]);
    let bits: Vec<u64> = (1..)
        .map(|k| sub.join(format!("run-2/plan-{k}.json")))
        .take_while(|p| p.exists())
        .map(|p| plan_bits(&p))
        .collect();
    assert!(bits.iter().any(|&b| b > 10), "plans at {bits:?} bits");
}

/// `--shard auto` takes the shard from a Slurm job array's variables.
#[test]
fn shard_auto_reads_the_slurm_array() {
    let dir = tempfile::tempdir().unwrap();
    let raw = bake(dir.path(), 16, 12, "");
    let explicit = dir.path().join("explicit.json");
    ok(&[
        "compress",
        s(&raw),
        "--analyze",
        "--shard",
        "1/3",
        "-o",
        s(&explicit),
    ]);
    let auto = dir.path().join("auto.json");
    let env = [
        ("SLURM_ARRAY_TASK_ID", "2"),
        ("SLURM_ARRAY_TASK_MIN", "1"),
        ("SLURM_ARRAY_TASK_COUNT", "3"),
    ];
    let (ok, _, stderr) = ltm_env(
        &[
            "compress",
            s(&raw),
            "--analyze",
            "--shard",
            "auto",
            "-o",
            s(&auto),
        ],
        &env,
    );
    assert!(ok, "{stderr}");
    assert_eq!(
        std::fs::read(explicit).unwrap(),
        std::fs::read(auto).unwrap()
    );
}

/// `ltm assemble PARTS -o OUT`'s arguments.
fn assemble_args<'a>(out: &'a Path, parts: &[&'a Path]) -> Vec<&'a str> {
    let mut v = vec!["assemble"];
    v.extend(parts.iter().map(|p| s(p)));
    v.extend(["-o", s(out)]);
    v
}

/// `ltm plan PARTS -o PLAN`'s arguments.
fn plan_args<'a>(parts: &[&'a Path], plan: &'a Path) -> Vec<&'a str> {
    let mut v = vec!["plan"];
    v.extend(parts.iter().map(|p| s(p)));
    v.extend(["-o", s(plan)]);
    v
}

#[test]
fn bad_sets_of_analysis_parts_and_plans_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = bake(d, 16, 12, "");
    let run = Run::analyze(d, &raw, 3, &[]);
    let a = &run.analyses;
    let plan = d.join("plan.json");
    // A missing analysis part, and a duplicate one under another name.
    fails(
        &plan_args(&[&a[0], &a[2]], &plan),
        &plan,
        &["shard 2/3", "shard 1 is missing"],
    );
    let copy = d.join("copy.json");
    std::fs::copy(&a[1], &copy).unwrap();
    fails(
        &plan_args(&[&a[0], &a[1], &copy, &a[2]], &plan),
        &plan,
        &["duplicate"],
    );
    // A part of a run with other options, or another shard count.
    let other = d.join("other.json");
    ok(&[
        "compress",
        s(&raw),
        "--analyze",
        "--shard",
        "1/3",
        "--max-error",
        "0.02",
        "-o",
        s(&other),
    ]);
    fails(
        &plan_args(&[&a[0], &other, &a[2]], &plan),
        &plan,
        &["other.json", "another run", "coding options"],
    );
    let two = d.join("two.json");
    ok(&[
        "compress",
        s(&raw),
        "--analyze",
        "--shard",
        "1/2",
        "-o",
        s(&two),
    ]);
    fails(
        &plan_args(&[&a[0], &two, &a[2]], &plan),
        &plan,
        &["two.json", "shard count"],
    );
    // Not an analysis part at all.
    fails(
        &plan_args(&[&a[0], &raw, &a[2]], &plan),
        &plan,
        &["scene.raw", "not a valid"],
    );
    // A plan used with another shard count, another raw store, or with
    // coding options of its own.
    assert_eq!(run.plan(&[], &plan), "code");
    let part = d.join("c.part");
    fails(
        &[
            "compress",
            s(&raw),
            "--plan",
            s(&plan),
            "--shard",
            "0/2",
            "-o",
            s(&part),
        ],
        &part,
        &["3 shards"],
    );
    let other_dir = d.join("other");
    std::fs::create_dir(&other_dir).unwrap();
    let other_raw = bake(&other_dir, 20, 12, "");
    fails(
        &[
            "compress",
            s(&other_raw),
            "--plan",
            s(&plan),
            "--shard",
            "0/3",
            "-o",
            s(&part),
        ],
        &part,
        &["another raw store"],
    );
    fails(
        &[
            "compress",
            s(&raw),
            "--plan",
            s(&plan),
            "--mode",
            "4d",
            "-o",
            s(&part),
        ],
        &part,
        &["--mode"],
    );
    fails(
        &["compress", s(&raw), "--shard", "0/2", "-o", s(&part)],
        &part,
        &["--analyze"],
    );
    fails(
        &[
            "compress",
            s(&raw),
            "--analyze",
            "--shard",
            "3/3",
            "-o",
            s(&part),
        ],
        &part,
        &["out of range"],
    );
}

#[test]
fn bad_sets_of_coded_parts_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = bake(d, 16, 12, "");
    let run = Run::analyze(d, &raw, 3, &[]);
    let plan1 = d.join("plan-1.json");
    assert_eq!(run.plan(&[], &plan1), "code");
    let c1 = run.code(&plan1, 1);
    let plan2 = d.join("plan-2.json");
    // The default target takes a second coding on this matrix.
    assert_eq!(run.plan(&c1, &plan2), "code");
    let c2 = run.code(&plan2, 2);
    let out = d.join("out.ltm");
    fails(
        &assemble_args(&out, &[&c2[0], &c2[2]]),
        &out,
        &["shard 1 is missing"],
    );
    fails(
        &assemble_args(&out, &[&c2[0], &c1[1], &c2[2]]),
        &out,
        &["different codings"],
    );
    // A truncated part (as a task killed while writing would leave, were
    // parts not written atomically) and a damaged payload.
    let bytes = std::fs::read(&c2[1]).unwrap();
    let cut = d.join("cut.part");
    std::fs::write(&cut, &bytes[..bytes.len() - 9]).unwrap();
    fails(
        &assemble_args(&out, &[&c2[0], &cut, &c2[2]]),
        &out,
        &["cut.part", "magic"],
    );
    let mut flipped = bytes.clone();
    flipped[40] ^= 0x10;
    let bad = d.join("bad.part");
    std::fs::write(&bad, &flipped).unwrap();
    fails(
        &assemble_args(&out, &[&c2[0], &bad, &c2[2]]),
        &out,
        &["bad.part", "checksum mismatch"],
    );
    // Coded parts of another run beside these analyses.
    let other = Run::analyze(&d.join("o"), &raw, 3, &["--max-error", "0.02"]);
    let other_plan = d.join("other-plan.json");
    assert_eq!(other.plan(&[], &other_plan), "code");
    let oc = other.code(&other_plan, 1);
    let next = d.join("next.json");
    let mut parts: Vec<&Path> = run.analyses.iter().map(PathBuf::as_path).collect();
    parts.extend(oc.iter().map(PathBuf::as_path));
    fails(
        &plan_args(&parts, &next),
        &next,
        &["another run", "coding options"],
    );
    // The good set still assembles.
    ok(&assemble_args(&out, &[&c2[2], &c2[0], &c2[1]]));
}
