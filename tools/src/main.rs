//! `ltm`: bake, compress, inspect and relight light-transport matrices.

mod bake;
mod codec_cmds;
mod demo;
mod output;
mod paths;
mod progress;
mod ranges;
mod reference;
mod relight_cmd;
mod render_cmd;
mod report;
mod view;

use clap::{Parser, Subcommand};
use ltm_codec::Limits;
use std::process::ExitCode;
use std::sync::OnceLock;

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
    /// a binary suffix K, M, G or T. Work that needs more is refused with
    /// the size it needs. Default: 75 % of the smaller of the memory
    /// available and the address-space limit (ulimit -v), or 4G where
    /// neither is known.
    #[arg(long, global = true, value_name = "SIZE", value_parser = parse_size)]
    max_memory: Option<u64>,
    #[command(subcommand)]
    command: Command,
}

/// The decoding limits of this run (`--max-memory`).
static LIMITS: OnceLock<Limits> = OnceLock::new();

/// The decoding limits every command passes to the libraries.
pub fn limits() -> &'static Limits {
    LIMITS.get_or_init(Limits::default)
}

/// Parses a byte count with an optional binary suffix (K, M, G, T).
fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (digits, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => return Err(format!("unknown size suffix '{c}' (valid: K, M, G, T)")),
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    let n: u64 = digits
        .parse()
        .map_err(|_| format!("'{s}' is not a size (e.g. 512M, 16G or 1000000)"))?;
    match n.checked_mul(1 << shift) {
        Some(v) if v >= 1 << 20 => Ok(v),
        _ => Err(format!("'{s}' is out of range (valid: 1M to 16E bytes)")),
    }
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
    let _ = LIMITS.set(limits);
    let result = match cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Bake(args) => bake::run(args),
        Command::Import(args) => codec_cmds::import(args),
        Command::Compress(args) => codec_cmds::compress_cmd(args),
        Command::Inspect(args) => codec_cmds::inspect_cmd(args),
        Command::Export(args) => codec_cmds::export(args),
        Command::Relight(args) => relight_cmd::run(args),
        Command::Render(args) => render_cmd::run(args),
        Command::Reference(args) => reference::run(args),
        Command::Report(args) => report::run(args),
        Command::View(args) => view::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
