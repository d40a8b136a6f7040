//! `ltm merge`: the parts of a sharded bake joined into one raw store.

use crate::common::{claim_files, Ctx};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `ltm merge`.
#[derive(Args)]
#[command(
    after_long_help = "The parts are the outputs of `ltm bake SCENE --shard I/N -o PART` for every I \
from 0 to N-1, in any order. Before writing anything, merge checks that every file is a complete \
part (a RAW.partial file or a truncated part is refused), that all come from the same scene (equal \
input identity, dimensions, block size, surface data and mesh) and that together they hold every \
row exactly once (no gap, overlap or duplicate). It then streams the rows in order into RAW, \
verifying every block checksum of every part as it goes, one block in memory at a time. RAW is \
written to RAW.partial and renamed when complete (removed on failure), and equals the raw store \
of `ltm bake SCENE -o RAW` on one machine byte for byte. Every error names the part and the \
problem."
)]
pub struct MergeArgs {
    /// The part files (`ltm bake --shard`), in any order.
    #[arg(required = true, value_name = "PART")]
    pub parts: Vec<PathBuf>,
    /// Output raw store.
    #[arg(short, long, value_name = "RAW")]
    pub output: PathBuf,
}

pub fn run(args: MergeArgs, ctx: &Ctx) -> anyhow::Result<()> {
    let inputs: Vec<(&str, &std::path::Path)> =
        args.parts.iter().map(|p| ("PART", p.as_path())).collect();
    let _claim = claim_files(&inputs, &[("-o", &args.output)])?;
    let start = Instant::now();
    let report = ltm_codec::raw::merge_parts(&args.parts, &args.output, &ctx.limits)?;
    eprintln!(
        "merged {} parts ({} rows) in {:.1} s -> {}",
        report.parts.len(),
        report.header.dims.pixels(),
        start.elapsed().as_secs_f64(),
        report.path.display()
    );
    Ok(())
}
