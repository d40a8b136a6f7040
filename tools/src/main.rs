//! `ltm`: bake, compress, inspect and relight light-transport matrices.

mod bake;
mod progress;

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
    /// Ray-trace a scene's transport matrix into a raw store.
    Bake(bake::BakeArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bake(args) => bake::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
