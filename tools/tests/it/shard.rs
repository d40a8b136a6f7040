//! Sharded bakes through the `ltm` binary: `ltm bake --shard I/N` and
//! `ltm merge` give a store byte-identical to a one-machine bake (image
//! and texture rows, N = 1, 2, 4 and 7); merge refuses every bad set of
//! parts with a message naming the part and the problem; `--shard auto`
//! reads the scheduler's variables; a damaged part is baked again.

use ltm_testkit::{blob_obj, scene_toml};
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_ltm");

/// Runs `ltm` with `args` and `env`; returns (success, stderr).
fn ltm_env(args: &[&str], env: &[(&str, &str)]) -> (bool, String) {
    let mut cmd = Command::new(BIN);
    cmd.args(args);
    for var in SCHEDULER_VARS {
        cmd.env_remove(var);
    }
    cmd.envs(env.iter().copied());
    let out = cmd.output().expect("run ltm");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    (out.status.success(), stderr)
}

const SCHEDULER_VARS: [&str; 6] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_STEP",
    "SLURM_ARRAY_TASK_COUNT",
    "JOB_COMPLETION_INDEX",
    "LTM_SHARD_COUNT",
];

fn ok(args: &[&str]) -> String {
    let (ok, stderr) = ltm_env(args, &[]);
    assert!(ok, "ltm {args:?} failed: {stderr}");
    stderr
}

/// `ltm merge` fails with a message containing every one of `expect`.
fn merge_fails(parts: &[&Path], out: &Path, expect: &[&str]) {
    let mut args: Vec<&str> = vec!["merge"];
    args.extend(parts.iter().map(|p| p.to_str().unwrap()));
    args.extend(["-o", out.to_str().unwrap()]);
    let (ok, stderr) = ltm_env(&args, &[]);
    assert!(!ok, "{args:?} succeeded");
    for e in expect {
        assert!(stderr.contains(e), "{args:?}: expected {e:?} in: {stderr}");
    }
    assert!(!out.exists(), "a failed merge left {}", out.display());
}

/// A scene directory: the blob mesh and `scene.toml` of `width`×`height`
/// pixels with `extra` appended (e.g. a `[texture]` section).
fn scene(dir: &Path, width: u32, height: u32, extra: &str) -> PathBuf {
    std::fs::write(dir.join("blob.obj"), blob_obj(3)).unwrap();
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene_toml("blob.obj", width, height, 2) + extra).unwrap();
    path
}

/// Bakes shard `i` of `n` of `scene` (plus `flags`) into `dir/part-i-of-n.raw`.
fn bake_shard(scene: &Path, dir: &Path, i: usize, n: usize, flags: &[&str]) -> PathBuf {
    let part = dir.join(format!("part-{i}-of-{n}.raw"));
    let spec = format!("{i}/{n}");
    let mut args = vec![
        "bake",
        scene.to_str().unwrap(),
        "--shard",
        &spec,
        "-o",
        part.to_str().unwrap(),
    ];
    args.extend(flags);
    ok(&args);
    part
}

fn merge(parts: &[PathBuf], out: &Path) {
    let mut args: Vec<&str> = vec!["merge"];
    // In reverse: merge sorts the parts by their rows.
    args.extend(parts.iter().rev().map(|p| p.to_str().unwrap()));
    args.extend(["-o", out.to_str().unwrap()]);
    ok(&args);
}

/// Sharded bakes of `scene` for N = 1, 2, 4, 7 equal the whole bake.
fn sharded_equals_whole(scene: &Path, dir: &Path) {
    let whole = dir.join("whole.raw");
    ok(&[
        "bake",
        scene.to_str().unwrap(),
        "-o",
        whole.to_str().unwrap(),
    ]);
    let want = std::fs::read(&whole).unwrap();
    for n in [1, 2, 4, 7] {
        let parts: Vec<PathBuf> = (0..n).map(|i| bake_shard(scene, dir, i, n, &[])).collect();
        let out = dir.join(format!("merged-{n}.raw"));
        merge(&parts, &out);
        assert!(
            std::fs::read(&out).unwrap() == want,
            "{n} shards: merged store differs from the whole bake"
        );
    }
}

#[test]
fn image_shards_merge_to_the_whole_bake() {
    let dir = tempfile::tempdir().unwrap();
    // 24 × 18 = 432 rows: 7 does not divide them.
    let scene = scene(dir.path(), 24, 18, "");
    sharded_equals_whole(&scene, dir.path());
}

#[test]
fn texture_shards_merge_to_the_whole_bake() {
    let dir = tempfile::tempdir().unwrap();
    // A 16² atlas (receiver mesh stored): 256 rows, 7 does not divide them.
    let scene = scene(
        dir.path(),
        8,
        8,
        "\n[texture]\nmesh = 0\nsize = 16\nspp = 1\n",
    );
    sharded_equals_whole(&scene, dir.path());
}

#[test]
fn merge_refuses_bad_parts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = scene(d, 12, 10, "");
    let other = d.join("other.raw");
    std::fs::rename(bake_shard(&scene, d, 1, 3, &["--spp", "2"]), &other).unwrap();
    let p: Vec<PathBuf> = (0..3).map(|i| bake_shard(&scene, d, i, 3, &[])).collect();
    let half = bake_shard(&scene, d, 0, 2, &[]);
    let out = d.join("out.raw");
    let name = |p: &PathBuf| p.file_name().unwrap().to_str().unwrap().to_string();
    merge_fails(
        &[&p[0], &other, &p[2]],
        &out,
        &[&name(&other), "another scene"],
    );
    merge_fails(&[&p[0], &p[2]], &out, &[&name(&p[2]), "gap", "rows 40..80"]);
    merge_fails(
        &[&p[0], &p[1]],
        &out,
        &[&name(&p[1]), "gap", "rows 80..120"],
    );
    merge_fails(&[&p[1], &p[2]], &out, &[&name(&p[1]), "gap", "rows 0..40"]);
    merge_fails(&[&half, &p[1], &p[2]], &out, &[&name(&p[1]), "overlap"]);
    merge_fails(
        &[&p[0], &p[1], &p[1], &p[2]],
        &out,
        &[&name(&p[1]), "duplicate"],
    );
    let whole = d.join("whole.raw");
    ok(&[
        "bake",
        scene.to_str().unwrap(),
        "-o",
        whole.to_str().unwrap(),
    ]);
    merge_fails(&[&whole], &out, &["whole.raw", "not a part"]);
    // A truncated part, and one with a flipped byte in its last row.
    let bytes = std::fs::read(&p[2]).unwrap();
    let cut = d.join("cut.raw");
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    merge_fails(&[&p[0], &p[1], &cut], &out, &["cut.raw", "truncated"]);
    let mut flipped = bytes.clone();
    let at = flipped.len() - 5;
    flipped[at] ^= 0x40;
    let bad = d.join("bad.raw");
    std::fs::write(&bad, &flipped).unwrap();
    merge_fails(&[&p[0], &p[1], &bad], &out, &["bad.raw", "CRC"]);
    // An unfinished part (its blocks never completed) is refused too.
    let mut pending = bytes;
    let table = 144; // the version-5 header's length: the block table follows
    pending[table..table + 4].copy_from_slice(&0u32.to_le_bytes());
    let unfinished = d.join("unfinished.raw");
    std::fs::write(&unfinished, &pending).unwrap();
    merge_fails(
        &[&p[0], &p[1], &unfinished],
        &out,
        &["unfinished.raw", "never completed"],
    );
    // The good parts still merge; a part is not a store compress accepts.
    merge(&p, &out);
    let (ok, stderr) = ltm_env(
        &[
            "compress",
            p[0].to_str().unwrap(),
            "-o",
            d.join("x.ltm").to_str().unwrap(),
        ],
        &[],
    );
    assert!(!ok && stderr.contains("ltm merge"), "{stderr}");
}

#[test]
fn shard_auto_reads_the_scheduler() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = scene(d, 12, 10, "");
    let s = scene.to_str().unwrap();
    let part = d.join("part.raw");
    let o = part.to_str().unwrap();
    let run =
        |spec: &str, env: &[(&str, &str)]| ltm_env(&["bake", s, "--shard", spec, "-o", o], env);
    // Slurm: --array=1-4, task 3 is shard 2 of 4 (rows 60..90 of 120).
    let slurm = [
        ("SLURM_ARRAY_TASK_ID", "3"),
        ("SLURM_ARRAY_TASK_MIN", "1"),
        ("SLURM_ARRAY_TASK_COUNT", "4"),
    ];
    let (ok, stderr) = run("auto", &slurm);
    assert!(
        ok && stderr.contains("shard 2/4: rows 60..90 of 120"),
        "{stderr}"
    );
    let explicit = bake_shard(&scene, d, 2, 4, &[]);
    assert!(std::fs::read(&part).unwrap() == std::fs::read(&explicit).unwrap());
    // Kubernetes: the index from JOB_COMPLETION_INDEX, the count from
    // auto/N or LTM_SHARD_COUNT.
    let (ok, stderr) = run("auto/4", &[("JOB_COMPLETION_INDEX", "0")]);
    assert!(ok && stderr.contains("shard 0/4: rows 0..30"), "{stderr}");
    let (ok, stderr) = run(
        "auto",
        &[("JOB_COMPLETION_INDEX", "1"), ("LTM_SHARD_COUNT", "4")],
    );
    assert!(ok && stderr.contains("shard 1/4: rows 30..60"), "{stderr}");
    for (spec, env, expect) in [
        ("auto", &[][..], "neither SLURM_ARRAY_TASK_ID"),
        (
            "auto",
            &[("JOB_COMPLETION_INDEX", "1")][..],
            "LTM_SHARD_COUNT",
        ),
        (
            "auto/4",
            &[("JOB_COMPLETION_INDEX", "4")][..],
            "out of range",
        ),
        (
            "auto",
            &[("SLURM_ARRAY_TASK_ID", "0")][..],
            "SLURM_ARRAY_TASK_COUNT",
        ),
        (
            "auto",
            &[
                ("SLURM_ARRAY_TASK_ID", "x"),
                ("SLURM_ARRAY_TASK_COUNT", "2"),
            ][..],
            "SLURM_ARRAY_TASK_ID",
        ),
        ("4/4", &[][..], "out of range"),
        ("0/121", &[][..], "more than the scene's 120 rows"),
    ] {
        let (ok, stderr) = run(spec, env);
        assert!(
            !ok && stderr.contains(expect),
            "--shard {spec} {env:?}: {stderr}"
        );
    }
}

#[test]
fn a_damaged_shard_is_baked_again() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = scene(d, 12, 10, "");
    let good = bake_shard(&scene, d, 1, 3, &[]);
    let want = std::fs::read(&good).unwrap();
    // A killed run leaves PART.partial: a truncated one is started over.
    let part = d.join("again.raw");
    let partial = d.join("again.raw.partial");
    std::fs::write(&partial, &want[..want.len() / 2]).unwrap();
    let spec = [
        "bake",
        scene.to_str().unwrap(),
        "--shard",
        "1/3",
        "-o",
        part.to_str().unwrap(),
    ];
    let stderr = ok(&spec);
    assert!(stderr.contains("not resuming"), "{stderr}");
    assert!(std::fs::read(&part).unwrap() == want);
    // A complete partial file of the same shard is resumed; one of another
    // shard is not.
    std::fs::remove_file(&part).unwrap();
    std::fs::write(&partial, &want).unwrap();
    let stderr = ok(&spec);
    assert!(
        stderr.contains("resuming") && stderr.contains("kept 1 of 1"),
        "{stderr}"
    );
    assert!(std::fs::read(&part).unwrap() == want);
    std::fs::remove_file(&part).unwrap();
    std::fs::write(
        &partial,
        std::fs::read(bake_shard(&scene, d, 0, 3, &[])).unwrap(),
    )
    .unwrap();
    let stderr = ok(&spec);
    assert!(stderr.contains("other rows"), "{stderr}");
    assert!(std::fs::read(&part).unwrap() == want);
}
