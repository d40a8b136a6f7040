//! `ltm`: bake, compress, inspect and relight light-transport matrices.

mod bake;
mod codec_cmds;
mod demo;
mod output;
mod progress;
mod reference;
mod relight_cmd;
mod report;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Compressed precomputed light-transport matrices.
///
/// A typical session: `ltm bake scene.toml -o scene.raw`, then
/// `ltm compress scene.raw -o scene.ltm`, then
/// `ltm relight scene.ltm --env map.exr --terms 200 -o image.exr`.
#[derive(Parser)]
#[command(name = "ltm", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the whole pipeline on the default scene and the maps in assets/.
    Demo(demo::DemoArgs),
    /// Ray-trace a scene's transport matrix into a raw store.
    Bake(bake::BakeArgs),
    /// Convert a NumPy matrix into a raw store.
    Import(codec_cmds::ImportArgs),
    /// Compress a raw store into an .ltm file.
    Compress(codec_cmds::CompressArgs),
    /// Show an .ltm file's dimensions, size, error and depth statistics.
    Inspect(codec_cmds::InspectArgs),
    /// Decode an .ltm file to a dense NumPy matrix.
    Export(codec_cmds::ExportArgs),
    /// Relight a compressed matrix under an environment map.
    Relight(relight_cmd::RelightArgs),
    /// Compute the exact relit image T·L from a raw store (the ground truth).
    Reference(reference::ReferenceArgs),
    /// Measure size, speed and error over a sweep of settings; write
    /// index.md, results.json and SVG plots.
    Report(report::ReportArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Bake(args) => bake::run(args),
        Command::Import(args) => codec_cmds::import(args),
        Command::Compress(args) => codec_cmds::compress_cmd(args),
        Command::Inspect(args) => codec_cmds::inspect_cmd(args),
        Command::Export(args) => codec_cmds::export(args),
        Command::Relight(args) => relight_cmd::run(args),
        Command::Reference(args) => reference::run(args),
        Command::Report(args) => report::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
