//! `--shard I/N` and `--shard auto`: which part of a sharded run this is.
//!
//! Shards are numbered from 0: `--shard 0/4` to `--shard 3/4`. `auto` takes
//! the index from the scheduler:
//!
//! - Slurm job arrays: `SLURM_ARRAY_TASK_ID`, counted from
//!   `SLURM_ARRAY_TASK_MIN` in steps of `SLURM_ARRAY_TASK_STEP` (1 when
//!   unset), so `--array=0-3`, `--array=1-4` and `--array=0-6:2` all give
//!   shards 0 to 3; the count is `SLURM_ARRAY_TASK_COUNT`.
//! - Kubernetes Indexed Jobs: `JOB_COMPLETION_INDEX` (0-based); the count
//!   is not in the environment, so it comes from `--shard auto/N` or
//!   `LTM_SHARD_COUNT` (set it to the Job's `completions`).
//!
//! `auto/N` also checks a Slurm array's count against N.

use anyhow::{anyhow, bail, Context, Result};

/// Which shard this is: `index` (0-based) of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// 0-based index.
    pub index: u64,
    /// Number of shards.
    pub count: u64,
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Parses `--shard SPEC` (`I/N`, `auto` or `auto/N`), reading scheduler
/// variables through `env`.
pub fn parse_shard(spec: &str, env: &dyn Fn(&str) -> Option<String>) -> Result<Shard> {
    let (index, count) = spec.split_once('/').unwrap_or((spec, ""));
    let count = match count {
        "" if index == "auto" => None,
        "" => bail!("--shard {spec}: expected I/N (0 <= I < N), auto or auto/N"),
        n => Some(number("--shard N", n)?),
    };
    let shard = if index == "auto" {
        from_env(count, env)?
    } else {
        Shard {
            index: number("--shard I", index)?,
            count: count.unwrap_or(0),
        }
    };
    if shard.count == 0 || shard.index >= shard.count {
        bail!(
            "--shard {spec}: shard index {} of {} shards is out of range (valid: N >= 1 and 0 <= I < N; shards are numbered from 0)",
            shard.index,
            shard.count
        );
    }
    Ok(shard)
}

/// A whole number from `text`, named `what` in the error.
fn number(what: &str, text: &str) -> Result<u64> {
    text.trim()
        .parse()
        .map_err(|_| anyhow!("{what} = {text:?} is not a whole number >= 0"))
}

/// A variable's number, or `None` when it is unset.
fn var(env: &dyn Fn(&str) -> Option<String>, name: &str) -> Result<Option<u64>> {
    env(name)
        .map(|v| number(name, &v))
        .transpose()
        .with_context(|| format!("--shard auto: reading {name}"))
}

/// The shard of `--shard auto[/count]` from the scheduler's variables.
fn from_env(count: Option<u64>, env: &dyn Fn(&str) -> Option<String>) -> Result<Shard> {
    if let Some(id) = var(env, "SLURM_ARRAY_TASK_ID")? {
        let min = var(env, "SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
        let step = var(env, "SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
        let total = var(env, "SLURM_ARRAY_TASK_COUNT")?;
        let n = match (total, count) {
            (Some(t), Some(c)) if t != c => bail!(
                "--shard auto/{c}: SLURM_ARRAY_TASK_COUNT = {t} is another count; give --shard auto or the array's size"
            ),
            (Some(t), _) => t,
            (None, Some(c)) => c,
            (None, None) => bail!(
                "--shard auto: SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not; give --shard auto/N"
            ),
        };
        if id < min || !(id - min).is_multiple_of(step) {
            bail!(
                "--shard auto: SLURM_ARRAY_TASK_ID = {id} is not SLURM_ARRAY_TASK_MIN = {min} plus a multiple of SLURM_ARRAY_TASK_STEP = {step}; use an array of consecutive ids (--array=0-{})",
                n.saturating_sub(1)
            );
        }
        return Ok(Shard {
            index: (id - min) / step,
            count: n,
        });
    }
    if let Some(index) = var(env, "JOB_COMPLETION_INDEX")? {
        let n = match (count, var(env, "LTM_SHARD_COUNT")?) {
            (Some(c), _) | (None, Some(c)) => c,
            (None, None) => bail!(
                "--shard auto: JOB_COMPLETION_INDEX = {index} is set but no count: give --shard auto/N or set LTM_SHARD_COUNT to the Job's completions"
            ),
        };
        return Ok(Shard { index, count: n });
    }
    bail!(
        "--shard auto: neither SLURM_ARRAY_TASK_ID (Slurm job arrays) nor JOB_COMPLETION_INDEX (Kubernetes Indexed Jobs) is set; give --shard I/N"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| {
            vars.iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn explicit_and_auto() {
        let none = with(&[]);
        assert_eq!(
            parse_shard("2/7", &none).unwrap(),
            Shard { index: 2, count: 7 }
        );
        for bad in ["7/7", "0/0", "x/3", "3", "-1/3", "1/"] {
            assert!(parse_shard(bad, &none).is_err(), "{bad}");
        }
        let msg = parse_shard("auto", &none).unwrap_err().to_string();
        assert!(msg.contains("SLURM_ARRAY_TASK_ID") && msg.contains("JOB_COMPLETION_INDEX"));
        let slurm = with(&[
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(
            parse_shard("auto", &slurm).unwrap(),
            Shard { index: 2, count: 4 }
        );
        assert!(parse_shard("auto/3", &slurm).is_err());
        let out = with(&[
            ("SLURM_ARRAY_TASK_ID", "9"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert!(parse_shard("auto", &out)
            .unwrap_err()
            .to_string()
            .contains("out of range"));
        let k8s = with(&[("JOB_COMPLETION_INDEX", "3")]);
        assert!(parse_shard("auto", &k8s)
            .unwrap_err()
            .to_string()
            .contains("LTM_SHARD_COUNT"));
        assert_eq!(
            parse_shard("auto/4", &k8s).unwrap(),
            Shard { index: 3, count: 4 }
        );
        let k8s = with(&[("JOB_COMPLETION_INDEX", "3"), ("LTM_SHARD_COUNT", "3")]);
        assert!(parse_shard("auto", &k8s).is_err());
    }
}
