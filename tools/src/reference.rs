//! `ltm reference`: the exact relit image T·L from a raw store.

use crate::common::{claim_files, progress, Ctx, ImageOutput};
use anyhow::Context;
use clap::Args;
use ltm_codec::{Progress, RawStore};
use ltm_relight::{reference_with_progress, EnvMap, Rotation};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `ltm reference`.
#[derive(Args)]
#[command(
    after_long_help = "The environment map is resampled to the store's cubemap by exact \
area-weighted integration (the mean radiance over each texel, power conserved), rotated by \
--rotate, and multiplied with every column of the uncompressed matrix, accumulating in double \
precision: B[p] = Σ_j T[p][j]·L[j]. With a grey transport and an albedo image the result is \
multiplied by the albedo. This is the ground truth that images relit from compressed .ltm files \
are measured against.\n\n\
Every block checksum of the store is verified. Outputs are written under a unique temporary name and renamed \
when complete."
)]
pub struct ReferenceArgs {
    /// Raw transport store (from `ltm bake` or `ltm import`).
    pub raw: PathBuf,
    /// Environment map: lat-long OpenEXR (.exr) or Radiance HDR (.hdr),
    /// width = 2·height; negative values are clamped to 0.
    #[arg(long, value_name = "MAP")]
    pub env: PathBuf,
    /// Rotate the lighting by YAW,PITCH,ROLL degrees: yaw about +Y (positive
    /// turns the light from +Z toward +X), then pitch about +X (+Y toward
    /// +Z), then roll about +Z (+X toward +Y).
    #[arg(
        long,
        value_name = "YAW,PITCH,ROLL",
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    pub rotate: Rotation,
    #[command(flatten)]
    pub out: ImageOutput,
}

pub fn run(args: ReferenceArgs, ctx: &Ctx) -> anyhow::Result<()> {
    let out = &args.out;
    let _claim = claim_files(&[("input", &args.raw), ("--env", &args.env)], &out.roles())?;
    let start = Instant::now();
    let raw = RawStore::open_with_limits(&args.raw, ctx.limits())
        .with_context(|| format!("opening raw store {}", args.raw.display()))?;
    let dims = raw.dims();
    let env = EnvMap::load(&args.env)
        .with_context(|| format!("loading environment map {}", args.env.display()))?;
    let n = dims.face_res() as usize;
    let light = env.to_cubemap(n, &args.rotate);

    let bar = progress::bar(
        dims.pixels() as u64,
        "reference",
        progress::Unit::rows(dims),
    );
    let image = reference_with_progress(&raw, &light, Progress::new(&|s| bar.set_position(s.done)))
        .with_context(|| format!("computing T·L from {}", args.raw.display()))?;
    bar.finish_and_clear();

    out.write(&image)?;
    eprintln!(
        "wrote {}: {}×{} pixels, {} lights (n = {}), {} channel(s){}, lighting {} rotated {}, {:.2} s",
        out.output.display(),
        dims.width(),
        dims.height(),
        dims.lights(),
        n,
        dims.channels,
        if raw.albedo().is_some() {
            " × albedo"
        } else {
            ""
        },
        args.env.display(),
        args.rotate,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
