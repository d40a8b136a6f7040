//! `ltm bake`.

use crate::common::shard::{parse_shard, Shard};
use crate::common::{claim_files, progress, Ctx};
use anyhow::{bail, Context};
use clap::Args;
use ltm_bake::{bake_part, BakeOptions, Overrides, ResumeState, Scene, SceneDesc};
use ltm_codec::{Progress, RowSpan, Stage};
use std::path::PathBuf;
use std::sync::Once;
use std::time::Instant;

/// Arguments of `ltm bake`.
#[derive(Args)]
#[command(
    after_long_help = "Each row is a pixel of the camera image (row p = y·width + x, y from the top), or with a \
[texture] section in the scene a texel of an S×S texture over one mesh (row k = y·S + x); each column \
is a texel of a 6·n² cubemap of distant lighting (OpenGL face order, world Y up). Entry \
T[p][j] is the light reflected to the camera through pixel p from texel j per unit radiance, \
so that the pixel's radiance is Σ_j T[p][j]·L[j]. Scenes whose materials are all Lambertian \
are stored as one grey channel plus an RGB albedo image; scenes with glossy materials as 3 \
channels.\n\n\
The store is written to RAW.partial and renamed to RAW when complete. Re-running the same \
command after an interruption resumes: completed blocks whose checksums verify are kept. \
RAW.partial is resumed only when it was baked from the same inputs: its header holds a \
SHA-256 of the resolved scene description (after these options), every mesh file's bytes and \
the ltm version; after any change the bake starts over and says why.\n\n\
More than one machine: `--shard I/N` bakes only shard I (numbered from 0) of N contiguous row \
ranges, as even as possible (the first rows mod N shards hold one row more), into a part file \
whose header records the whole scene's input identity and the part's rows; each row is computed \
exactly as in a whole bake. `ltm merge part-*.raw -o RAW` then joins the parts into a store \
byte-identical to a one-machine bake. A part resumes like a whole store, and only from a \
RAW.partial of the same scene and the same rows. `--shard auto` takes I and N from a Slurm job \
array (SLURM_ARRAY_TASK_ID minus SLURM_ARRAY_TASK_MIN, in steps of SLURM_ARRAY_TASK_STEP, of \
SLURM_ARRAY_TASK_COUNT) or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX, with N from \
`--shard auto/N` or LTM_SHARD_COUNT).\n\n\
The scene file format is described in the ltm-bake crate (module `scene`); \
assets/scenes/default.toml is an example."
)]
pub struct BakeArgs {
    /// Scene description (TOML); mesh paths in it are relative to its directory.
    pub scene: PathBuf,
    /// Output raw store.
    #[arg(short, long, value_name = "RAW")]
    pub output: PathBuf,
    /// Image size in pixels: WxH, or N for N×N (overrides camera.width and
    /// camera.height; the same grammar as `ltm demo --size` and `ltm
    /// render --size`).
    #[arg(long, value_name = "WxH", conflicts_with_all = ["width", "height"], value_parser = bake_size)]
    pub size: Option<(u32, u32)>,
    /// Image width in pixels (overrides camera.width).
    #[arg(long, value_name = "W")]
    pub width: Option<u32>,
    /// Image height in pixels (overrides camera.height).
    #[arg(long, value_name = "H")]
    pub height: Option<u32>,
    /// Cubemap face resolution n, a power of two: 6·n² lights (overrides lighting.face_res).
    #[arg(long, value_name = "N")]
    pub face_res: Option<u32>,
    /// Direction samples per cubemap texel (overrides lighting.texel_samples).
    #[arg(long, value_name = "S")]
    pub texel_samples: Option<u32>,
    /// Pixel sub-samples, averaged with a box filter (overrides camera.spp).
    #[arg(long, value_name = "K")]
    pub spp: Option<u32>,
    /// Texture side S of a `[texture]` bake: S² rows (overrides texture.size).
    #[arg(long, value_name = "S")]
    pub texture_size: Option<u32>,
    /// Texel density of an atlas, texels per world unit of length (overrides
    /// texture.texels_per_unit); without --texture-size the texture is as
    /// large as the atlas needs. Every part gets texels in proportion to its area.
    #[arg(long, value_name = "D")]
    pub texels_per_unit: Option<f64>,
    /// Bake a texture over these surfaces instead of camera pixels: a mesh
    /// index into the scene's `[[meshes]]` (0, 1, ...) or `all` (every mesh
    /// and quad, atlas only). Adds a `[texture]` section to a scene without
    /// one (then --texture-size or --texels-per-unit is needed; its other
    /// keys take their defaults), or overrides texture.mesh.
    #[arg(long, value_name = "MESH")]
    pub texture: Option<ltm_bake::Receivers>,
    /// The texture's layout: atlas, uv or sphere (overrides
    /// texture.parameterization; default atlas).
    #[arg(long, value_name = "P")]
    pub parameterization: Option<ltm_codec::Parameterization>,
    /// Bake only shard I (0-based) of N row ranges into a part for `ltm
    /// merge`: `I/N`, `auto` (Slurm array or Kubernetes Indexed Job
    /// variables) or `auto/N`; see the long help.
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<String>,
}

/// `--size`: WxH or N, sides 1..=[`ltm_codec::MAX_SIDE`].
fn bake_size(s: &str) -> std::result::Result<(u32, u32), String> {
    crate::common::ranges::image_size(s, ltm_codec::MAX_SIDE)
}

/// The rows of `shard` among the scene's `rows`, announced on stderr.
fn shard_rows(shard: Shard, rows: usize) -> anyhow::Result<RowSpan> {
    if shard.count > rows as u64 {
        bail!(
            "--shard {shard}: {} shards is more than the scene's {rows} rows (valid: 1..={rows})",
            shard.count
        );
    }
    let span = RowSpan::shard(rows as u64, shard.index, shard.count);
    eprintln!("shard {shard}: {span} of {rows}");
    Ok(span)
}

/// What became of an existing `RAW.partial`, for the user; `None` when
/// there was none.
fn resume_message(state: &ResumeState, partial: &str) -> Option<String> {
    match state {
        ResumeState::New => None,
        ResumeState::Resumed { kept, total } => Some(format!(
            "resuming {partial}: kept {kept} of {total} blocks baked from the same inputs"
        )),
        ResumeState::Restarted(why) => Some(format!(
            "not resuming {partial}: {why}; baking from scratch"
        )),
        _ => Some(format!("{partial}: {state}")),
    }
}

/// Prints what is about to be baked: skipped triangles, the texture's
/// parameterization, and the matrix's size.
fn describe(scene: &Scene, desc: &SceneDesc) {
    let dims = scene.dims();
    for m in &scene.stats().meshes {
        if m.degenerate_skipped > 0 {
            eprintln!(
                "warning: {}: skipped {} degenerate (zero-area) triangles of {}",
                m.path.display(),
                m.degenerate_skipped,
                m.triangles + m.degenerate_skipped
            );
        }
    }
    let [lo, hi] = scene.bounding_box();
    let corner = |c: [f64; 3]| {
        format!(
            "{}, {}, {}",
            fmt_coord(c[0]),
            fmt_coord(c[1]),
            fmt_coord(c[2])
        )
    };
    eprintln!(
        "scene bounding box: ({}) to ({}), centre ({})",
        corner(lo),
        corner(hi),
        corner([0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k])))
    );
    if let Some(map) = scene.texel_map() {
        describe_texture(map);
    }
    eprintln!(
        "baking {} × {} {} × {} lights ({}×{} faces) × {} channel{}{}: {:.2} GB, {} triangles, {} texel samples, {} samples per row",
        dims.width(),
        dims.height(),
        if dims.rows.is_texture() { "texels" } else { "pixels" },
        dims.lights(),
        dims.face_res(),
        dims.face_res(),
        dims.channels,
        if dims.channels == 1 { "" } else { "s" },
        if dims.channels == 1 { " + albedo image" } else { "" },
        dims.raw_bytes() as f64 / 1e9,
        scene.stats().triangles,
        desc.lighting.texel_samples,
        scene.rows().samples_per_row(),
    );
    // At most one shadow ray per light sample of each row's sub-samples;
    // rows off the surface trace none. The progress line shows the rate.
    let rows = scene
        .texel_map()
        .map_or(dims.pixels(), |m| m.stats().valid_texels) as f64;
    let per_light =
        rows * scene.rows().samples_per_row() as f64 * desc.lighting.texel_samples as f64;
    let mut rays = per_light * dims.lights() as f64;
    let mut bytes = dims.raw_bytes() as f64;
    if let Some((_, face)) = scene.light_plane() {
        let texels = face.texels() as f64;
        rays += per_light * texels;
        bytes += 4.0 * dims.pixels() as f64 * texels * dims.channels as f64;
        eprintln!(
            "and every row over the light plane's face: {0} × {0} texels of side {1} (near-field rows)",
            face.order, face.side
        );
    }
    eprintln!(
        "estimate: {:.2} GB on disk, {} MiB of row blocks in memory (three in flight), at most {:.3e} shadow rays",
        bytes / 1e9,
        3 * (ltm_bake::DEFAULT_BLOCK_BYTES >> 20),
        rays
    );
}

/// A coordinate for a message: four significant digits, plain where that
/// reads well, in exponent notation beyond.
fn fmt_coord(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.3e}");
    }
    let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    let s = format!("{v:.digits$}");
    match s.contains('.') {
        true => s.trim_end_matches('0').trim_end_matches('.').to_string(),
        false => s,
    }
}

/// The texture's layout: texel use, stretch and, for an atlas, its charts
/// and each part's texel density.
fn describe_texture(map: &ltm_bake::TexelMap) {
    let st = map.stats();
    let stretch = match (st.stretch_mean, st.stretch_max) {
        (Some(m), Some(x)) => format!(
            ", L2 stretch mean {m:.3} max {x:.3}, {} flipped triangles",
            st.flipped_triangles
        ),
        _ => String::new(),
    };
    eprintln!(
        "texture {}² ({}): {} valid texels ({:.1} %), {:.4e} valid texels per unit area, {} zero-area triangles skipped{stretch}; parameterized in {:.2} s",
        st.size,
        map.parameterization().name(),
        st.valid_texels,
        100.0 * st.valid_texels as f64 / (st.size as f64 * st.size as f64),
        st.texels_per_area,
        st.skipped_triangles,
        st.seconds
    );
    if let Some(a) = &st.atlas {
        eprintln!(
            "atlas: {} charts, {:.4} texels per unit length",
            a.charts, a.texels_per_unit
        );
        // Per part only where there are parts to compare: each part's
        // charts' own area, where the line above counts whole texels.
        if a.part_density.len() > 1 {
            for (part, density) in &a.part_density {
                eprintln!("  {part}: its charts cover {density:.4e} texels per unit area");
            }
        }
    }
}

pub fn run(args: BakeArgs, _ctx: &Ctx) -> anyhow::Result<()> {
    let mut desc = SceneDesc::load(&args.scene)?;
    desc.apply(&Overrides {
        width: args.width.or(args.size.map(|s| s.0)),
        height: args.height.or(args.size.map(|s| s.1)),
        face_res: args.face_res,
        texel_samples: args.texel_samples,
        spp: args.spp,
        texture_size: args.texture_size,
        texels_per_unit: args.texels_per_unit,
        texture: args.texture,
        parameterization: args.parameterization,
    })?;
    let meshes: Vec<PathBuf> = desc.meshes.iter().map(|m| desc.resolve(&m.path)).collect();
    let mut inputs = vec![("SCENE", args.scene.as_path())];
    inputs.extend(meshes.iter().map(|m| ("mesh", m.as_path())));
    let _claim = claim_files(&inputs, &[("-o", &args.output)])?;
    let env = |name: &str| std::env::var(name).ok();
    let shard = args
        .shard
        .as_deref()
        .map(|s| parse_shard(s, &env))
        .transpose()?;
    if shard.is_none() {
        ltm_codec::output::check_space(&args.output, desc.transport_bytes())?;
    }
    let scene = Scene::build(&desc)?;
    describe(&scene, &desc);
    let dims = scene.dims();
    let part = shard.map(|s| shard_rows(s, dims.pixels())).transpose()?;
    // An atlas sized by its density is known only now.
    let rows = part.map_or(dims.pixels() as u64, |s| s.len());
    ltm_codec::output::check_space(&args.output, rows.saturating_mul(dims.row_len() as u64 * 4))?;
    let bar = progress::bar(rows, "bake", progress::Unit::rows(dims));
    let options = BakeOptions::default();
    let partial = format!("{}.partial", args.output.display());
    let start = Instant::now();
    let first = Once::new();
    let result = bake_part(
        &scene,
        &args.output,
        &options,
        part,
        Progress::new(&|s| {
            // The bar counts all rows; resumed ones are complete already.
            bar.set_position(s.done);
            let Stage::Bake { resume } = s.stage else {
                return;
            };
            first.call_once(|| {
                bar.reset_eta();
                if let Some(line) = resume_message(&resume, &partial) {
                    // Printed even when the bar is hidden (stderr not a terminal).
                    bar.suspend(|| eprintln!("{line}"));
                }
            });
            let secs = start.elapsed().as_secs_f64().max(1e-9);
            bar.set_message(format!("{:.1} Mray/s", s.work as f64 / secs / 1e6));
        }),
    );
    bar.finish_and_clear();
    let report = result.with_context(|| format!("baking {}", args.scene.display()))?;
    let secs = report.elapsed.as_secs_f64().max(1e-9);
    if report.rows_baked == 0 {
        // No row was baked, so no progress report printed this.
        if let Some(line) = resume_message(&report.resume, &partial) {
            eprintln!("{line}");
        }
    }
    eprintln!(
        "baked {} rows in {:.1} s: {:.0} rows/s, {:.2} M shadow rays/s ({} shadow rays) -> {}",
        report.rows_baked,
        secs,
        report.rows_baked as f64 / secs,
        report.rays.shadow_rays as f64 / secs / 1e6,
        report.rays.shadow_rays,
        report.path.display()
    );
    Ok(())
}
