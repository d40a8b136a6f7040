//! `ltm`: bake, compress, inspect and relight light-transport matrices.

mod area_light;
mod bake;
mod codec_cmds;
mod common;
mod demo;
mod merge;
mod reference;
mod relight_cmd;
mod render_cmd;
mod render_glossy;
mod report;
mod shard_cmds;
mod view;

use clap::{Parser, Subcommand};
use common::Ctx;
use ltm_codec::Limits;
use std::process::ExitCode;

/// Compressed precomputed light-transport matrices.
///
/// A typical session: `ltm bake scene.toml -o scene.raw`, then
/// `ltm compress scene.raw -o scene.ltm`, then
/// `ltm relight scene.ltm --env map.exr --terms 200 -o image.exr`.
#[derive(Parser)]
#[command(name = "ltm", version, about, long_about)]
struct Cli {
    /// Memory budget, in all, for the buffers a command sizes from its files
    /// and arguments (column tables, the relighter's arena, frames, a dense
    /// export; every file a command opens is charged to it): bytes, or with
    /// a binary suffix K, M, G, T, P or E (`1.5G`), 1M or more. Work that
    /// needs more is refused with the size it needs. Default: 75 % of the
    /// smaller of the memory available and the address-space limit
    /// (ulimit -v), or 4G where neither is known.
    #[arg(long, global = true, value_name = "SIZE", value_parser = common::size::size)]
    max_memory: Option<u64>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the whole pipeline on the default scene and the maps in assets/.
    Demo(demo::DemoArgs),
    /// Ray-trace a scene's transport matrix into a raw store.
    Bake(bake::BakeArgs),
    /// Join the parts of a sharded bake (`ltm bake --shard`) into one raw store.
    Merge(merge::MergeArgs),
    /// Convert a NumPy matrix into a raw store.
    Import(codec_cmds::ImportArgs),
    /// Compress a raw store into an .ltm file (or one shard's stage of a
    /// sharded compression: --analyze, --plan).
    Compress(codec_cmds::CompressArgs),
    /// Sharded compression: the plan of the next coding, from the analysis
    /// parts (and the coded parts of the last coding).
    Plan(shard_cmds::PlanArgs),
    /// Sharded compression: join the coded parts of the last coding into
    /// the .ltm file.
    Assemble(shard_cmds::AssembleArgs),
    /// Show an .ltm file's dimensions, size, error and depth statistics.
    Inspect(codec_cmds::InspectArgs),
    /// Decode an .ltm file to a dense NumPy matrix.
    Export(codec_cmds::ExportArgs),
    /// Relight a compressed matrix under an environment map and, for pca
    /// files, point lights (an image, or for a texture-space matrix the
    /// relit texture).
    Relight(relight_cmd::RelightArgs),
    /// Relight a texture-space matrix and draw the relit mesh from any
    /// camera (or an orbit of cameras).
    Render(render_cmd::RenderArgs),
    /// Compute the exact relit image T·L from a raw store (the ground truth).
    Reference(reference::ReferenceArgs),
    /// Measure size, speed and error over a sweep of settings; write
    /// index.md, results.json and SVG plots.
    Report(report::ReportArgs),
    /// Serve an interactive relighting page on a local port (rotate the
    /// lighting, change N, map and exposure, compare two files or the exact
    /// image).
    View(view::ViewArgs),
}

/// Restores the default action of SIGPIPE, which the Rust runtime ignores:
/// a command whose standard output is a closed pipe (`ltm inspect f.ltm |
/// head -1`) then ends quietly, as Unix tools do, instead of panicking.
#[cfg(unix)]
fn exit_quietly_on_closed_pipe() {
    // SAFETY: called first in `main`, before any other thread exists;
    // setting a signal's disposition to its default only changes what the
    // kernel does to this process on SIGPIPE, and no handler runs.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    #[cfg(unix)]
    exit_quietly_on_closed_pipe();
    let cli = Cli::parse();
    let limits = match cli.max_memory {
        Some(total) => Limits::with_max_alloc(total),
        None => Limits::for_machine(),
    };
    let ctx = Ctx::new(limits);
    let result = match cli.command {
        Command::Demo(args) => demo::run(args, &ctx),
        Command::Bake(args) => bake::run(args, &ctx),
        Command::Merge(args) => merge::run(args, &ctx),
        Command::Import(args) => codec_cmds::import(args, &ctx),
        Command::Compress(args) => codec_cmds::compress_cmd(args, &ctx),
        Command::Plan(args) => shard_cmds::plan_cmd(args, &ctx),
        Command::Assemble(args) => shard_cmds::assemble_cmd(args, &ctx),
        Command::Inspect(args) => codec_cmds::inspect_cmd(args, &ctx),
        Command::Export(args) => codec_cmds::export(args, &ctx),
        Command::Relight(args) => relight_cmd::run(args, &ctx),
        Command::Render(args) => render_cmd::run(args, &ctx),
        Command::Reference(args) => reference::run(args, &ctx),
        Command::Report(args) => report::run(args, &ctx),
        Command::View(args) => view::run(args, &ctx),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            match budget_hint(&e) {
                Some(hint) => eprintln!("error: {e:#} ({hint})"),
                None => eprintln!("error: {e:#}"),
            }
            ExitCode::FAILURE
        }
    }
}

/// The way forward for an error that ran out of the memory budget: the
/// flag that sets it.
fn budget_hint(e: &anyhow::Error) -> Option<&'static str> {
    use ltm_codec::Error::Limit;
    use ltm_relight::RelightError::Codec;
    let over = e.chain().any(|c| {
        matches!(c.downcast_ref::<ltm_codec::Error>(), Some(Limit { .. }))
            || matches!(
                c.downcast_ref::<ltm_relight::RelightError>(),
                Some(Codec(Limit { .. }))
            )
    });
    over.then_some("the budget is set with --max-memory SIZE, e.g. `ltm --max-memory 16G ...`")
}
