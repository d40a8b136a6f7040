//! The Slurm pipeline of `tools/cluster/slurm` on a real Slurm: a tiny
//! scene baked and compressed as 4-task job arrays gives a raw store and an
//! `.ltm` file byte-identical to a one-machine `ltm bake` and
//! `ltm compress` (with two codings: the check job submits the second); a
//! killed shard fails the pipeline without an `.ltm` file, and running the
//! pipeline again completes it.
//!
//! Needs a Slurm whose node is up (`sinfo`) and sees this machine's
//! temporary directory, as the single-node Slurm of
//! `tools/cluster/slurm/start-local-slurm.sh` does; without it the
//! tests are skipped with a message, unless `LTM_SLURM=1` (set by
//! `.ci/run`), where they fail. They wait on the jobs' state (`wait.sh`
//! polls `squeue`) with a timeout, never for a fixed time.

#![cfg(unix)]

use ltm_testkit::{blob_obj, scene_toml};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_ltm");
const SHARDS: &str = "4";
/// Bake options given to the pipeline and to the one-machine bake (the
/// scene file says 32×32).
const BAKE: &[&str] = &["--size", "24x16", "--face-res", "4"];
/// Compress options, likewise.
const COMPRESS: &[&str] = &["--max-error", "0.05"];
/// The longest a pipeline may take, in seconds (wait.sh --timeout).
const TIMEOUT_S: &str = "600";

fn scripts() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("cluster/slurm")
}

/// Whether a Slurm node is up to run jobs; panics when it is not and
/// `LTM_SLURM=1`.
fn slurm_available() -> bool {
    let why = match Command::new("sinfo")
        .args(["-h", "-N", "-o", "%T"])
        .output()
    {
        Err(e) => format!("sinfo: {e}"),
        Ok(out) if !out.status.success() => {
            format!("sinfo: {}", String::from_utf8_lossy(&out.stderr).trim())
        }
        Ok(out) => {
            let states = String::from_utf8_lossy(&out.stdout).into_owned();
            let up = states
                .lines()
                .any(|s| matches!(s.trim(), "idle" | "mixed" | "allocated" | "completing"));
            if up {
                return true;
            }
            format!("no Slurm node is up (sinfo: {:?})", states.trim())
        }
    };
    if std::env::var("LTM_SLURM").as_deref() == Ok("1") {
        panic!("LTM_SLURM=1 but Slurm cannot run jobs: {why}; start it with tools/cluster/slurm/start-local-slurm.sh");
    }
    eprintln!(
        "skipped: {why} (tools/cluster/slurm/start-local-slurm.sh starts a single-node Slurm; LTM_SLURM=1 makes this a failure)"
    );
    false
}

/// Runs `program` with `args`; returns (success, stdout + stderr).
fn run(program: &Path, args: &[&str]) -> (bool, String) {
    let out = Command::new(program)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", program.display()));
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

fn ltm(args: &[&str]) {
    let (ok, text) = run(Path::new(BIN), args);
    assert!(ok, "ltm {args:?} failed: {text}");
}

/// The scene (blob mesh, 32×32 pixels, n = 4) in `dir`.
fn scene(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("blob.obj"), blob_obj(3)).unwrap();
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene_toml("blob.obj", 32, 32, 4)).unwrap();
    path
}

/// One machine: `ltm bake` and `ltm compress` of `scene` into `dir`;
/// returns the raw store's and the .ltm file's bytes.
fn one_machine(scene: &Path, dir: &Path) -> (Vec<u8>, Vec<u8>) {
    let raw = dir.join("one.raw");
    let out = dir.join("one.ltm");
    let mut bake = vec!["bake", scene.to_str().unwrap(), "-o", raw.to_str().unwrap()];
    bake.extend(BAKE);
    ltm(&bake);
    let mut compress = vec![
        "compress",
        raw.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    compress.extend(COMPRESS);
    ltm(&compress);
    (std::fs::read(raw).unwrap(), std::fs::read(out).unwrap())
}

/// Submits the pipeline of `scene` into `work` with the binary `ltm_bin`
/// and waits for its end; returns (success, wait.sh's output and the
/// pipeline's logs).
fn pipeline(scene: &Path, work: &Path, ltm_bin: &Path) -> (bool, String) {
    let (bake, compress) = (BAKE.join(" "), COMPRESS.join(" "));
    let args = [
        "--work",
        work.to_str().unwrap(),
        "--shards",
        SHARDS,
        "--ltm",
        ltm_bin.to_str().unwrap(),
        "--bake",
        &bake,
        "--compress",
        &compress,
        scene.to_str().unwrap(),
    ];
    let (ok, text) = run(&scripts().join("pipeline.sh"), &args);
    assert!(ok, "pipeline.sh {args:?} failed: {text}");
    let (ok, mut text) = run(
        &scripts().join("wait.sh"),
        &["--timeout", TIMEOUT_S, work.to_str().unwrap()],
    );
    assert!(!text.contains("timed out"), "{text}");
    let mut logs: Vec<_> = std::fs::read_dir(work.join("logs"))
        .map(|d| d.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default();
    logs.sort();
    for log in logs {
        let body = std::fs::read_to_string(&log).unwrap_or_default();
        text += &format!("\n--- {}\n{body}", log.display());
    }
    (ok, text)
}

fn read(path: &Path, what: &str) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{what} {}: {e}", path.display()))
}

#[test]
fn pipeline_is_byte_identical_to_one_machine() {
    if !slurm_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let (raw, ltm_file) = one_machine(&scene, dir.path());
    let work = dir.path().join("work");
    let (ok, log) = pipeline(&scene, &work, Path::new(BIN));
    let merged = work.join("scene.raw");
    assert!(merged.exists(), "the pipeline merged no store:\n{log}");
    assert!(
        read(&merged, "merged store") == raw,
        "the merged store differs from a one-machine bake:\n{log}"
    );
    assert!(ok, "the pipeline failed after the merge:\n{log}");
    // COMPRESS makes the first coding miss the error window, so that the
    // check job's second coding (submitted from inside the pipeline) runs.
    assert!(
        log.lines().any(|l| l.starts_with("ltm-check-2 ")),
        "the pipeline coded once: pick COMPRESS options that code twice:\n{log}"
    );
    assert!(
        read(&work.join("scene.ltm"), "assembled file") == ltm_file,
        "the assembled .ltm differs from a one-machine compress:\n{log}"
    );
}

#[test]
fn killed_shard_is_never_assembled_and_a_rerun_completes() {
    if !slurm_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let (_, ltm_file) = one_machine(&scene, dir.path());
    // ltm, except that task 2 of the first coding is killed (SIGKILL, as a
    // scheduler or the OOM killer kills) while the file `kill` exists.
    let kill = dir.path().join("kill");
    std::fs::write(&kill, "").unwrap();
    let wrapper = dir.path().join("ltm-killed");
    std::fs::write(
        &wrapper,
        format!(
            "#!/usr/bin/env bash\n\
             if [ -e '{kill}' ] && [ \"$1\" = compress ] && [[ \" $* \" == *' --plan '* ]] \
             && [ \"${{SLURM_ARRAY_TASK_ID:-}}\" = 2 ]; then\n  \
             echo 'killed on purpose' >&2\n  kill -9 $$\nfi\n\
             exec '{BIN}' \"$@\"\n",
            kill = kill.display()
        ),
    )
    .unwrap();
    std::fs::set_permissions(&wrapper, std::fs::Permissions::from_mode(0o755)).unwrap();

    let work = dir.path().join("work");
    let (ok, log) = pipeline(&scene, &work, &wrapper);
    assert!(!ok, "the pipeline succeeded with a killed task:\n{log}");
    assert!(
        log.lines()
            .any(|l| l.starts_with("ltm-code-1 ") && l.contains("_2 FAILED")),
        "the killed task is not reported FAILED:\n{log}"
    );
    assert!(
        log.lines()
            .any(|l| l.starts_with("ltm-check-1 ") && l.contains(" CANCELLED")),
        "the check after the killed task is not CANCELLED:\n{log}"
    );
    assert!(
        !work.join("scene.ltm").exists(),
        "a pipeline with a killed task left scene.ltm:\n{log}"
    );
    let left: Vec<String> = std::fs::read_dir(work.join("code"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with("c-1-2"))
        .collect();
    assert!(left.is_empty(), "the killed task left {left:?}:\n{log}");

    // The same command again: the finished shards are skipped, the killed
    // one runs, and the result is the one-machine file.
    std::fs::remove_file(&kill).unwrap();
    let (ok, log) = pipeline(&scene, &work, &wrapper);
    assert!(ok, "the rerun failed:\n{log}");
    assert!(
        log.contains("exists (a complete output of an earlier run): skipped"),
        "the rerun did not skip finished shards:\n{log}"
    );
    assert!(
        read(&work.join("scene.ltm"), "assembled file") == ltm_file,
        "the rerun's .ltm differs from a one-machine compress:\n{log}"
    );
}
