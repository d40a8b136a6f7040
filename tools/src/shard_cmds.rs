//! Sharded compression: `ltm compress --analyze --shard`, `ltm plan`,
//! `ltm compress --plan --shard` and `ltm assemble`
//! (`ltm_codec::compress::shard`).

use crate::codec_cmds::{code_options, CompressArgs};
use crate::common::shard::{parse_shard, Shard};
use crate::common::{claim_files, progress, write_atomic, Ctx};
use anyhow::{bail, Context, Result};
use clap::Args;
use ltm_codec::compress::shard::{self, AnalysisPart, PlanFile, RunIdentity, CODED_PART_MAGIC};
use ltm_codec::compress::TransposeOptions;
use ltm_codec::{default_mem_budget, Progress, RawStore, Stage};
use std::io::Read as _;
use std::path::{Path, PathBuf};

/// How a sharded run goes, for `--help`.
const SHARDED_HELP: &str = "A sharded compression runs the stages of `ltm compress` apart, each \
shard on any machine that sees the files (shared storage), and writes the file `ltm compress` \
writes on one machine, byte for byte:

  ltm compress RAW --analyze --shard I/N -o a-I.json   (coding options here; every I)
  ltm plan a-*.json -o plan-1.json                      (prints `code`)
  ltm compress RAW --plan plan-1.json --shard I/N -o c-1-I.part   (every I)
  ltm plan a-*.json c-1-*.part -o plan-2.json           (prints `code` or `assemble`)
  ...                                                   (code again while it prints `code`)
  ltm assemble c-K-*.part -o scene.ltm

`ltm plan` prints one word on standard output: `code` when it wrote a plan to code with, \
`assemble` when the coded parts it was given are the file (it then writes nothing). A target \
error usually takes one to three codings. Every shard reads every row of RAW (the row transform \
needs whole rows) and keeps its own columns. Each file names its run (the raw store's length and \
checksum, the options, the matrix's norm); parts name their plan, and every stage refuses parts \
of another run or plan, gaps, overlaps and duplicates. `--shard auto` takes I and N from a Slurm \
job array or a Kubernetes Indexed Job, as `ltm bake --shard auto` does.";

/// Arguments of `ltm plan`.
#[derive(Args)]
#[command(after_long_help = SHARDED_HELP)]
pub struct PlanArgs {
    /// Every analysis part of the run (`ltm compress --analyze --shard`),
    /// and after a coding every coded part of it (`ltm compress --plan
    /// --shard`), in any order.
    #[arg(required = true, value_name = "PART")]
    pub parts: Vec<PathBuf>,
    /// The plan to write (JSON), when another coding is needed.
    #[arg(short, long, value_name = "PLAN")]
    pub output: PathBuf,
}

/// Arguments of `ltm assemble`.
#[derive(Args)]
#[command(after_long_help = SHARDED_HELP)]
pub struct AssembleArgs {
    /// Every coded part of the last coding, in any order.
    #[arg(required = true, value_name = "PART")]
    pub parts: Vec<PathBuf>,
    /// The .ltm file to write (atomically).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// `ltm compress --analyze` or `ltm compress --plan`: one shard.
pub fn compress_shard(a: &CompressArgs, ctx: &Ctx) -> Result<()> {
    let env = |name: &str| std::env::var(name).ok();
    let shard = match a.shard.as_deref() {
        Some(spec) => parse_shard(spec, &env)?,
        None => Shard { index: 0, count: 1 },
    };
    let mut inputs = vec![("input", a.raw.as_path())];
    if let Some(plan) = &a.plan {
        inputs.push(("--plan", plan.as_path()));
    }
    let _claim = claim_files(&inputs, &[("-o", &a.output)])?;
    let raw = RawStore::open_with_limits(&a.raw, ctx.limits())
        .with_context(|| format!("opening {}", a.raw.display()))?;
    let transpose = TransposeOptions {
        row_filter: a.row_filter,
        mem_budget: a.mem_budget.unwrap_or_else(default_mem_budget),
        temp_dir: None,
    };
    let dims = raw.dims();
    let bar = progress::bar(0, "transpose", progress::Unit::of(Stage::Rows, dims));
    let show = |s| progress::show(&bar, s, dims);
    let start = std::time::Instant::now();
    match &a.plan {
        None => {
            let part = shard::analyze_shard(
                &raw,
                &transpose,
                &code_options(a),
                (shard.index, shard.count),
                Progress::new(&show),
            )
            .with_context(|| format!("analyzing shard {shard} of {}", a.raw.display()))?;
            bar.finish_and_clear();
            write_atomic(&a.output, &shard::to_json(&part)?)?;
            eprintln!(
                "wrote {}: analysis of shard {shard}, columns {:?}, {:.1} s",
                a.output.display(),
                part.columns,
                start.elapsed().as_secs_f64()
            );
        }
        Some(plan_path) => {
            let plan: PlanFile = shard::read_json(plan_path, ctx.limits())?;
            check_shard_count(&plan.run, shard, plan_path)?;
            let coded = shard::code_shard(
                &raw,
                &transpose,
                &plan,
                shard.index,
                &a.output,
                Progress::new(&show),
            )
            .with_context(|| {
                format!(
                    "coding shard {shard} of {} with {}",
                    a.raw.display(),
                    plan_path.display()
                )
            })?;
            bar.finish_and_clear();
            eprintln!(
                "wrote {}: shard {shard}, columns {:?}, coding {} at {} bits, {} bytes, {:.1} s",
                a.output.display(),
                coded.columns,
                plan.step.coding,
                plan.step.bits,
                coded.part_bytes,
                start.elapsed().as_secs_f64()
            );
        }
    }
    Ok(())
}

/// The shard count of `--shard` is the run's.
fn check_shard_count(run: &RunIdentity, shard: Shard, plan: &Path) -> Result<()> {
    if shard.count != run.shards {
        bail!(
            "--shard {shard}: {} plans a run of {} shards, not {}",
            plan.display(),
            run.shards,
            shard.count
        );
    }
    Ok(())
}

/// Whether `path` is a coded part (else an analysis part): its magic.
fn is_coded_part(path: &Path) -> Result<bool> {
    let mut magic = [0u8; 8];
    let mut f = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let n = f
        .read(&mut magic)
        .with_context(|| format!("reading {}", path.display()))?;
    Ok(n == 8 && &magic == CODED_PART_MAGIC)
}

/// `ltm plan`.
pub fn plan_cmd(a: PlanArgs, ctx: &Ctx) -> Result<()> {
    let inputs: Vec<(&str, &Path)> = a.parts.iter().map(|p| ("PART", p.as_path())).collect();
    let _claim = claim_files(&inputs, &[("-o", &a.output)])?;
    let (mut analyses, mut coded) = (Vec::new(), Vec::new());
    for path in &a.parts {
        if is_coded_part(path)? {
            coded.push(path.clone());
        } else {
            let part: AnalysisPart = shard::read_json(path, ctx.limits())?;
            analyses.push((path.clone(), part));
        }
    }
    if analyses.is_empty() {
        bail!("no analysis parts among the {} files: `ltm plan` needs every `ltm compress --analyze --shard` output of the run", a.parts.len());
    }
    let (run, analysis) = shard::merge_analyses(analyses)?;
    let next = if coded.is_empty() {
        Some(shard::plan_first(&run, analysis.as_ref())?)
    } else {
        shard::plan_next(&run, analysis.as_ref(), &coded, ctx.limits())?
    };
    match next {
        Some(plan) => {
            write_atomic(&a.output, &shard::to_json(&plan)?)?;
            eprintln!(
                "wrote {}: coding {} at {} bits of {} columns in {} shards; code every shard with it",
                a.output.display(), plan.step.coding, plan.step.bits, run.lights, run.shards
            );
            println!("code");
        }
        None => {
            eprintln!(
                "the {} coded parts are final: assemble them (nothing written to {})",
                coded.len(),
                a.output.display()
            );
            println!("assemble");
        }
    }
    Ok(())
}

/// `ltm assemble`.
pub fn assemble_cmd(a: AssembleArgs, ctx: &Ctx) -> Result<()> {
    let inputs: Vec<(&str, &Path)> = a.parts.iter().map(|p| ("PART", p.as_path())).collect();
    let _claim = claim_files(&inputs, &[("-o", &a.output)])?;
    let start = std::time::Instant::now();
    let stats = shard::assemble(&a.parts, &a.output, ctx.limits())?;
    eprintln!(
        "wrote {}: {} bytes from {} parts ({:.1}x smaller than {} raw), {} bits, {} nonzeros, relative L2 error {:.5}, coding {}, {:.1} s",
        a.output.display(), stats.file_bytes, a.parts.len(), stats.raw_bytes as f64 / stats.file_bytes as f64,
        stats.raw_bytes, stats.bits, stats.nonzeros, stats.achieved_error, stats.codings, start.elapsed().as_secs_f64()
    );
    if !stats.target_met {
        eprintln!("warning: the target error was not reached (as `ltm compress` would say on one machine)");
    }
    Ok(())
}
