//! Running the `ltm` binary in a test. Its path is known only to the tests
//! of the package that builds it: pass `env!("CARGO_BIN_EXE_ltm")`.

use std::process::{Command, Output};

/// A finished run: whether it succeeded, and its output as text.
#[derive(Debug)]
pub struct Run {
    pub ok: bool,
    pub stdout: String,
    pub stderr: String,
}

impl From<Run> for (bool, String, String) {
    /// `(ok, stdout, stderr)`.
    fn from(r: Run) -> Self {
        (r.ok, r.stdout, r.stderr)
    }
}

/// Runs `bin` with `args` and returns its raw output. Panics when the
/// binary cannot be started.
pub fn run_output(bin: &str, args: &[&str]) -> Output {
    Command::new(bin).args(args).output().expect("run ltm")
}

/// Runs `bin` with `args`: success, stdout and stderr.
pub fn run(bin: &str, args: &[&str]) -> Run {
    let out = run_output(bin, args);
    Run {
        ok: out.status.success(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Runs `bin` with `args`, which must succeed, and returns its stdout.
pub fn run_ok(bin: &str, args: &[&str]) -> String {
    let r = run(bin, args);
    assert!(r.ok, "ltm {args:?} failed: {}", r.stderr);
    r.stdout
}
