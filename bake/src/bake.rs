//! The bake driver: rows in blocks, computed in parallel, streamed to the raw
//! store.
//!
//! Rows are grouped in the raw store's blocks (about
//! [`BakeOptions::block_bytes`] of row data each). The blocks still pending
//! in `PATH.partial` are computed one after the other, the rows of a block in
//! parallel (rayon); a writer thread copies each finished block into the
//! memory-mapped file while the next one is computed. At most three blocks
//! are in memory at once (one being computed, one queued, one being
//! written), so memory stays bounded whatever the matrix size.
//!
//! Resuming: the raw store's header carries the scene's input identity
//! ([`crate::identity`]: a SHA-256 of the resolved scene description, every
//! mesh file's bytes and every setting). [`ltm_codec::RawWriter::create`]
//! reopens a `PATH.partial` only when its identity and layout equal the
//! new header's, and keeps its blocks whose checksums verify; only the
//! others are baked. Every row is a pure function of those inputs and the
//! row index, so a resumed bake is byte-identical to an uninterrupted one. A
//! partial file from other inputs (or without an identity) is started over,
//! and [`BakeReport::resume`] and the progress reports ([`Stage::Bake`]) say why. The file
//! is renamed to `PATH` only when every block is complete.

use crate::error::{BakeError, Result};
use crate::transport::{Grid, RowStats, Scratch, Tables};
use crate::world::Scene;
use ltm_codec::raw::ResumeState;
use ltm_codec::{Progress, RawHeader, RawWriter, RowSpan, Stage, Surface, SurfacePoint};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::sync_channel;
use std::time::{Duration, Instant};

/// Default bytes of row data per block.
pub const DEFAULT_BLOCK_BYTES: u64 = 32 << 20;

/// Options of [`bake`].
#[derive(Clone, Copy, Debug)]
pub struct BakeOptions {
    /// Bytes of row data per block (the unit of writing and resuming). A
    /// `.partial` file resumes only with the same value.
    pub block_bytes: u64,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            block_bytes: DEFAULT_BLOCK_BYTES,
        }
    }
}

/// Summary of a finished bake.
#[derive(Clone, Debug)]
pub struct BakeReport {
    /// The complete raw store.
    pub path: PathBuf,
    /// Its header.
    pub header: RawHeader,
    /// Blocks in the store.
    pub blocks_total: usize,
    /// Blocks found complete in a `.partial` file and kept.
    pub blocks_resumed: usize,
    /// What was done with an existing `PATH.partial`: resumed, or started
    /// over and why ([`ResumeState`]'s `Display` says it in words).
    pub resume: ResumeState,
    /// Rows computed in this run (resumed ones excluded).
    pub rows_baked: u64,
    /// Rays traced in this run.
    pub rays: RowStats,
    /// Wall-clock time of this run.
    pub elapsed: Duration,
}

/// The raw store header for a scene: grey transport with an albedo image,
/// or 3 channels, per-row surface data, the receiver mesh of an `atlas` or
/// `uv` texture, the face of its light plane, and the scene's input
/// identity.
pub fn raw_header(scene: &Scene, block_bytes: u64) -> RawHeader {
    let header = RawHeader::new(scene.dims(), scene.channels() == 1, block_bytes)
        .with_input_id(scene.input_id())
        .with_surface();
    let header = match scene.light_plane() {
        Some((_, basis)) => header.with_plane(*basis),
        None => header,
    };
    match receiver_mesh(scene) {
        Some(mesh) => header.with_mesh(&mesh),
        None => header,
    }
}

/// The receiver as drawn (triangles with texel-unit coordinates) of a
/// texture-space scene laid out by `atlas` or `uv`; `None` otherwise.
pub fn receiver_mesh(scene: &Scene) -> Option<ltm_codec::ReceiverMesh> {
    scene.texel_map()?.receiver_mesh()
}

/// The surface data of every row of `scene` (see
/// [`ltm_codec::Surface`]): for image rows each pixel centre's first hit,
/// for texture rows each texel's point on the mesh.
pub fn row_surface(scene: &Scene) -> Result<Surface> {
    let rows = scene.dims().pixels();
    let points: Vec<SurfacePoint> = (0..rows)
        .into_par_iter()
        .map(|p| scene.rows().surface_point(scene, p))
        .collect();
    Surface::new(points).map_err(BakeError::Store)
}

/// Computes whole blocks of rows.
pub struct BlockBaker<'a> {
    scene: &'a Scene,
    tables: Tables,
    header: RawHeader,
    /// The light plane's face, when rows are also baked over it.
    plane: Option<Grid>,
}

impl<'a> BlockBaker<'a> {
    /// A baker for `scene` writing blocks of `header` (from [`raw_header`]).
    pub fn new(scene: &'a Scene, header: RawHeader) -> Result<BlockBaker<'a>> {
        if header.dims != scene.dims() || header.has_albedo != (scene.channels() == 1) {
            return Err(BakeError::Store(ltm_codec::Error::Invalid(format!(
                "raw store header {:?} (albedo image: {}) does not match the scene's dimensions {:?}",
                header.dims,
                header.has_albedo,
                scene.dims()
            ))));
        }
        if header.input_id.is_some_and(|id| id != scene.input_id()) {
            return Err(BakeError::Store(ltm_codec::Error::Invalid(
                "raw store header carries the input identity of another scene".into(),
            )));
        }
        let plane = scene.light_plane().map(|(plane, basis)| {
            let (order, side) = (basis.order as usize, basis.side);
            Grid::face(order, side, plane.x_axis(), plane.y_axis(), -plane.normal())
        });
        if header.plane.as_ref() != scene.light_plane().map(|(_, b)| b) {
            return Err(BakeError::Store(ltm_codec::Error::Invalid(
                "raw store header and scene disagree about the light plane".into(),
            )));
        }
        Ok(BlockBaker {
            scene,
            tables: Tables::new(scene),
            header,
            plane,
        })
    }

    /// Computes block `b`'s rows over the light plane's face into `plane`
    /// (resized to its rows × `order²·C`, [`RawHeader::plane_row_len`]), as
    /// [`Scene::plane_row`] computes each; empty without a light plane.
    pub fn compute_plane(&self, b: usize, plane: &mut Vec<f32>) -> RowStats {
        plane.clear();
        let (Some(grid), Some((light_plane, _))) = (&self.plane, self.scene.light_plane()) else {
            return RowStats::default();
        };
        let range = self.header.block_range(b);
        let len = self.header.plane_row_len();
        plane.resize(range.len() * len, 0.0);
        let start = self.header.first_row() + range.start;
        let texels = len / self.scene.channels() as usize;
        plane
            .par_chunks_mut(len)
            .enumerate()
            .map_init(
                || Scratch::with_texels(self.scene, texels),
                |scratch, (i, row)| {
                    let mut albedo = [0.0f32; 3];
                    let p = start + i;
                    self.scene.row_on(
                        &self.tables,
                        grid,
                        Some(light_plane),
                        scratch,
                        p,
                        row,
                        &mut albedo,
                    )
                },
            )
            .reduce(RowStats::default, |mut a, b| {
                a += b;
                a
            })
    }

    /// The header blocks are computed for.
    pub fn header(&self) -> &RawHeader {
        &self.header
    }

    /// Computes block `b` into `rows` (resized to its rows × M·C) and
    /// `albedo` (3 values per row; zeros for 3-channel transport), calling
    /// `on_row` after each row.
    pub fn compute(
        &self,
        b: usize,
        rows: &mut Vec<f32>,
        albedo: &mut Vec<f32>,
        on_row: &(dyn Fn(RowStats) + Sync),
    ) -> RowStats {
        let range = self.header.block_range(b);
        let row_len = self.header.dims.row_len();
        rows.clear();
        rows.resize(range.len() * row_len, 0.0);
        albedo.clear();
        albedo.resize(range.len() * 3, 0.0);
        // Rows are numbered in the whole matrix, so that a part of a sharded
        // bake computes the very rows a whole bake does.
        let start = self.header.first_row() + range.start;
        rows.par_chunks_mut(row_len)
            .zip(albedo.par_chunks_mut(3))
            .enumerate()
            .map_init(
                || Scratch::new(self.scene),
                |scratch, (i, (row, alb))| {
                    let mut a = [0.0f32; 3];
                    let s = self
                        .scene
                        .row_into(&self.tables, scratch, start + i, row, &mut a);
                    alb.copy_from_slice(&a);
                    on_row(s);
                    s
                },
            )
            .reduce(RowStats::default, |mut a, b| {
                a += b;
                a
            })
    }
}

/// Bakes `scene` into the raw store `out` (through `out.partial`, resuming
/// it when it was baked from the same inputs, else starting it over),
/// reporting progress after every row.
pub fn bake(
    scene: &Scene,
    out: &Path,
    options: &BakeOptions,
    progress: Progress<'_>,
) -> Result<BakeReport> {
    bake_part(scene, out, options, None, progress)
}

/// [`bake`] of the rows `part` only (all rows when `None`): a part of a
/// sharded bake (raw store version 5, [`RawHeader::with_part`]) whose
/// header carries the whole scene's input identity and the part's rows.
/// Every row is a function of the inputs and its index in the whole
/// matrix, so `ltm merge` of the parts equals a whole bake byte for byte.
/// A `.partial` file of another part (or a whole store) is started over
/// ([`ltm_codec::raw::RestartReason::DifferentRows`]).
pub fn bake_part(
    scene: &Scene,
    out: &Path,
    options: &BakeOptions,
    part: Option<RowSpan>,
    progress: Progress<'_>,
) -> Result<BakeReport> {
    let start = Instant::now();
    let whole = raw_header(scene, options.block_bytes);
    let header = match part {
        Some(span) => check_part(span, &whole)?,
        None => whole,
    };
    let baker = BlockBaker::new(scene, header)?;
    let mesh = receiver_mesh(scene);
    let mut writer =
        RawWriter::create_with_geometry(out, header, Some(&row_surface(scene)?), mesh.as_ref())?;
    let resume = writer.resume_state();
    let pending = writer.pending_blocks();
    let blocks_total = header.block_count();
    let rows_total: u64 = pending
        .iter()
        .map(|&b| header.block_range(b).len() as u64)
        .sum();
    let all_rows = header.stored_rows() as u64;
    let rows_done = AtomicU64::new(all_rows - rows_total);
    let shadow = AtomicU64::new(0);
    let on_row = |s: RowStats| {
        let done = rows_done.fetch_add(1, Ordering::Relaxed) + 1;
        let rays = shadow.fetch_add(s.shadow_rays, Ordering::Relaxed) + s.shadow_rays;
        progress.report_work(Stage::Bake { resume }, done, all_rows, rays);
    };
    let rays = bake_blocks(&baker, &mut writer, &pending, &on_row)?;
    let path = writer.finish()?;
    Ok(BakeReport {
        path,
        header,
        blocks_total,
        blocks_resumed: blocks_total - pending.len(),
        resume,
        rows_baked: rows_total,
        rays,
        elapsed: start.elapsed(),
    })
}

/// The header of part `span` of a bake of `whole`: the span must hold at
/// least one row and lie within the matrix.
fn check_part(span: RowSpan, whole: &RawHeader) -> Result<RawHeader> {
    let rows = whole.dims.pixels() as u64;
    if span.is_empty() || span.end > rows {
        return Err(BakeError::Store(ltm_codec::Error::OutOfRange {
            what: "shard rows",
            value: span.to_string(),
            valid: format!("a non-empty range within rows 0..{rows}"),
        }));
    }
    Ok(whole.with_part(span))
}

/// Computes the `pending` blocks one after the other while a writer thread
/// copies each finished one into `writer` (at most one queued).
fn bake_blocks(
    baker: &BlockBaker,
    writer: &mut RawWriter,
    pending: &[usize],
    on_row: &(dyn Fn(RowStats) + Sync),
) -> Result<RowStats> {
    let has_albedo = baker.header().has_albedo;
    let has_plane = baker.header().plane.is_some();
    let mut rays = RowStats::default();
    let written: Result<()> = std::thread::scope(|s| {
        let (tx, rx) = sync_channel::<(usize, Vec<f32>, Vec<f32>, Vec<f32>)>(1);
        let handle = s.spawn(move || -> Result<()> {
            for (b, rows, albedo, plane) in rx {
                let albedo = has_albedo.then_some(albedo.as_slice());
                let plane = has_plane.then_some(plane.as_slice());
                writer.write_block_with_plane(b, &rows, albedo, plane)?;
            }
            Ok(())
        });
        for &b in pending {
            let (mut rows, mut albedo, mut plane) = (Vec::new(), Vec::new(), Vec::new());
            rays += baker.compute(b, &mut rows, &mut albedo, on_row);
            rays += baker.compute_plane(b, &mut plane);
            if tx.send((b, rows, albedo, plane)).is_err() {
                break; // the writer failed; its error is returned below
            }
        }
        drop(tx);
        match handle.join() {
            Ok(r) => r,
            Err(panic) => std::panic::resume_unwind(panic),
        }
    });
    written.map(|()| rays)
}
