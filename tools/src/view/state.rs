//! What the server holds: the opened files and maps, the cache of rotated
//! lights and of exact images, the frame slots that bound concurrent work,
//! and each client's latest sequence number.

use super::glossy::{GlossyTimes, Materials};
use super::params::{AreaParams, Client, FrameParams, GlossyParams, Lighting, Resampling};
use super::preview::Preview;
use anyhow::{bail, Context, Result};
use glam::DVec3;
use ltm_codec::container::LtmFile;
use ltm_codec::{Charge, ImageCamera, Limits, RawStore, RowLayout, SurfacePoint};
use ltm_relight::nearfield::{AreaLight, LightTexture, NearField, NearFieldMethod, Placement};
use ltm_relight::{
    reference, relative_l2, EnvMap, Frame, FrameStats, Image, PrefilteredMap, Relight, Request,
    TexturedMesh,
};
use serde::Serialize;
use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Rotated lights kept (per face resolution, map and rotation).
const LIGHT_CACHE: usize = 16;
/// Exact images kept (per map and rotation).
const EXACT_CACHE: usize = 8;
/// Maps prepared for draft resampling kept (per map and face resolution).
const PREFILTERED_KEPT: usize = 4;
/// Draft lights kept.
const DRAFTS_KEPT: usize = 4;
/// Clients whose latest sequence number is remembered.
const MAX_CLIENTS: usize = 256;

/// One opened `.ltm` file.
pub struct ViewFile {
    /// Path as given.
    pub path: PathBuf,
    /// The relighter (wavelet, pca or sh).
    pub relighter: Box<dyn Relight + Send + Sync>,
    /// Facts shown on the page.
    pub info: FileInfo,
    /// What `ltm render` draws for a texture-space file: its stored mesh
    /// or the grid of its geometry image, and the texels' records.
    pub mesh: Option<TexturedMesh>,
    /// Frames to reuse (each holds a relighter's scratch buffers).
    frames: Mutex<Vec<Frame>>,
    /// The file's near-field rows (a scene's `[light_plane]`), if any.
    near: Option<NearField>,
    /// A texture-space file's surface points (what glossy materials shade),
    /// or, with `--brdf`, an image-space file's whose eye is known, charged
    /// to the budget while they live.
    points: (Vec<SurfacePoint>, Charge),
}

/// A file's light plane, as `/api/info` gives it.
#[derive(Serialize, Clone)]
pub struct NearInfo {
    /// Face texels per side.
    pub order: u32,
    /// Face side in tangent units.
    pub side: f64,
}

/// A file's facts, as `/api/info` gives them.
#[derive(Serialize, Clone)]
pub struct FileInfo {
    /// File name (no folders).
    pub name: String,
    /// Bytes on disk.
    pub bytes: u64,
    /// Coding mode (adaptive, 2d, 4d, pca, ...).
    pub mode: String,
    /// Measured relative L2 error of the decoded matrix.
    pub matrix_error: f64,
    /// Relit image (or texture) width and height.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Cubemap lights (columns).
    pub lights: usize,
    /// The largest N.
    pub max_terms: usize,
    /// `image` (a fixed camera's pixels) or `texture` (a mesh's texels).
    pub layout: &'static str,
    /// A texture's parameterization (`uv` or `sphere`, whose square folds
    /// onto itself along its border).
    pub parameterization: Option<&'static str>,
    /// The light plane of a file with near-field rows (area lights), or
    /// null.
    pub near_field: Option<NearInfo>,
    /// With `--brdf`, the eye an image-space file's pixels were seen from
    /// (recovered from its surface records; glossy materials shade from
    /// it); null for texture files and where the records do not fix it.
    pub eye: Option<[f64; 3]>,
}

/// A listed environment map.
#[derive(Serialize)]
pub struct MapInfo {
    /// File name (no folders).
    pub name: String,
    /// Lat-long width and height.
    pub width: usize,
    /// Height.
    pub height: usize,
}

/// A finished frame.
pub struct FrameOut {
    /// The image.
    pub image: Image,
    /// Relighter statistics.
    pub stats: FrameStats,
    /// Wall time of the relight.
    pub frame_time: Duration,
    /// Time spent resampling the map (zero when the rotated light was cached).
    pub resample_time: Duration,
    /// Whether the light was the draft resampling (not the exact one).
    pub draft: bool,
    /// Relative L2 error against the exact image, when it is cached (and
    /// no area light is added: the exact image is the map's).
    pub error: Option<f64>,
    /// Time of the area light's near-field rows, when one was asked for.
    pub area_time: Option<Duration>,
    /// What the glossy material cost, when one was asked for.
    pub glossy: Option<GlossyTimes>,
}

/// Why a frame was not made.
pub enum FrameError {
    /// A newer request from the same client arrived (HTTP 204).
    Stale,
    /// All frame slots are busy (HTTP 503).
    Busy,
    /// Bad parameters for this file (HTTP 400).
    Bad(String),
    /// A failure of ours (HTTP 500).
    Internal(String),
}

type LightKey = (usize, usize, [u64; 3]);
/// A cubemap light: one RGB value per texel.
type Light = Arc<Vec<[f32; 3]>>;
type ExactKey = (usize, [u64; 3]);
/// Map index and face resolution.
type PrefilteredKey = (usize, usize);

/// The server's state, shared by all worker threads.
pub struct Viewer {
    /// Files, in command-line order.
    pub files: Vec<ViewFile>,
    maps: Vec<(MapInfo, EnvMap)>,
    previews: Vec<Preview>,
    raw: Option<(PathBuf, RawStore)>,
    lights: Mutex<VecDeque<(LightKey, Light)>>,
    /// Maps prepared for draft resampling, per map and face resolution.
    prefiltered: Mutex<Vec<(PrefilteredKey, Arc<PrefilteredMap>)>>,
    /// The latest draft lights (two files turned together share one).
    drafts: Mutex<VecDeque<(LightKey, Light)>>,
    exact: Mutex<VecDeque<(ExactKey, Arc<Image>)>>,
    /// Area-light textures: `uniform`, then each `--area-light`.
    textures: Vec<(String, LightTexture)>,
    /// The glossy materials of `--brdf`, if any.
    materials: Option<Materials>,
    slots: Slots,
    clients: Mutex<HashMap<String, (u64, Instant)>>,
    /// Set once [`Viewer::preload`] has decoded every file's columns.
    preloaded: AtomicBool,
}

fn key_of(l: &Lighting) -> [u64; 3] {
    let r = l.rotation;
    [r.yaw.to_bits(), r.pitch.to_bits(), r.roll.to_bits()]
}

/// The eye of an image-space file's pixels, recovered from its surface
/// records; a warning names the file and the reason where they do not fix
/// it (its frames then take no glossy material).
fn image_eye(file: &LtmFile, path: &Path) -> Option<[f64; 3]> {
    let width = file.meta().dims.width() as usize;
    let camera = match file.surface() {
        Some(surface) => ImageCamera::recover(surface, width).map_err(|e| e.to_string()),
        None => Err("it stores no surface records".into()),
    };
    match camera {
        Ok(c) => Some(c.eye()),
        Err(e) => {
            eprintln!(
                "warning: {}: glossy materials need the eye its pixels were seen from: {e}",
                path.display()
            );
            None
        }
    }
}

pub fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

impl ViewFile {
    /// Opens `path`; with `glossy` (materials were given), an image-space
    /// file's eye is recovered and its surface points kept.
    fn open(path: &Path, glossy: bool, limits: &Limits) -> Result<ViewFile> {
        // One read of the file, whose relighter is made last (it takes it).
        let mut file = LtmFile::open_with_limits(path, limits)
            .with_context(|| format!("opening {}", path.display()))?;
        let near = match file.near_field() {
            Some(_) => Some(
                NearField::take(&mut file, limits)
                    .with_context(|| format!("opening {}", path.display()))?,
            ),
            None => None,
        };
        let meta = file.meta().clone();
        let (width, height) = (meta.dims.width() as usize, meta.dims.height() as usize);
        let texture = meta.dims.rows.is_texture();
        let mesh = match texture {
            true => Some(
                TexturedMesh::from_file(&file, limits)
                    .with_context(|| format!("opening {}", path.display()))?,
            ),
            false => None,
        };
        let bytes = file.file_bytes();
        let eye = match glossy && !texture {
            true => image_eye(&file, path),
            false => None,
        };
        let points = match file.surface().filter(|_| texture || eye.is_some()) {
            Some(surface) => {
                let size = std::mem::size_of::<SurfacePoint>() as u64;
                let charge = limits.check_alloc("surface points", surface.len() as u64, size)?;
                (surface.points().to_vec(), charge)
            }
            None => (Vec::new(), Charge::default()),
        };
        let relighter = ltm_relight::open_file(file, limits)
            .with_context(|| format!("opening {}", path.display()))?;
        let info = FileInfo {
            name: file_name(path),
            bytes,
            mode: meta.mode.name().into(),
            matrix_error: f64::from(meta.achieved_error),
            width,
            height,
            lights: relighter.lights(),
            max_terms: relighter.max_terms(),
            layout: if texture { "texture" } else { "image" },
            parameterization: match meta.dims.rows {
                RowLayout::Texture {
                    parameterization, ..
                } => Some(parameterization.name()),
                _ => None,
            },
            near_field: near.as_ref().map(|n| NearInfo {
                order: n.basis().order,
                side: n.basis().side,
            }),
            eye,
        };
        Ok(ViewFile {
            path: path.to_path_buf(),
            relighter,
            info,
            mesh,
            frames: Mutex::new(Vec::new()),
            near,
            points,
        })
    }

    /// Cubemap face resolution n (lights = 6·n²).
    fn face_res(&self) -> usize {
        self.relighter.face_res()
    }
}

impl Viewer {
    /// Decodes every file's columns not decoded yet (frames decode the
    /// ones they need first themselves); a file that fails here says so and
    /// fails again in the frame that needs the column.
    pub fn preload(&self) {
        for f in &self.files {
            if let Err(e) = f.relighter.preload() {
                eprintln!("warning: {}: {e}", f.path.display());
            }
        }
        self.preloaded.store(true, Ordering::Release);
    }

    /// Whether [`Viewer::preload`] has run to its end: until then a frame
    /// may decode the columns it needs first (`preloaded` in `/api/info`).
    pub fn preloaded(&self) -> bool {
        self.preloaded.load(Ordering::Acquire)
    }

    /// Opens the files, maps and raw store; `slots` frames may run at once.
    pub fn open(
        files: &[PathBuf],
        maps: &[PathBuf],
        (raw, textures, materials): (
            Option<&Path>,
            Vec<(String, LightTexture)>,
            Option<Materials>,
        ),
        slots: usize,
        limits: &Limits,
    ) -> Result<Viewer> {
        let files = files
            .iter()
            .map(|p| ViewFile::open(p, materials.is_some(), limits))
            .collect::<Result<Vec<_>>>()?;
        let maps = maps
            .iter()
            .map(|p| {
                let env = EnvMap::load(p).with_context(|| format!("loading {}", p.display()))?;
                let info = MapInfo {
                    name: file_name(p),
                    width: env.width(),
                    height: env.height(),
                };
                Ok((info, env))
            })
            .collect::<Result<Vec<_>>>()?;
        if maps.is_empty() {
            bail!("no environment map: give --env MAP (or run from the repository, where assets/envmaps has some)");
        }
        let raw = match raw {
            Some(p) => Some((p.to_path_buf(), open_raw(p, &files, limits)?)),
            None => None,
        };
        let previews = maps.iter().map(|(_, env)| Preview::new(env)).collect();
        Ok(Viewer {
            files,
            maps,
            previews,
            prefiltered: Mutex::new(Vec::new()),
            drafts: Mutex::new(VecDeque::new()),
            raw,
            lights: Mutex::new(VecDeque::new()),
            exact: Mutex::new(VecDeque::new()),
            textures,
            materials,
            slots: Slots::new(slots),
            clients: Mutex::new(HashMap::new()),
            preloaded: AtomicBool::new(false),
        })
    }

    /// The names of the area-light textures offered.
    pub fn area_textures(&self) -> impl Iterator<Item = &str> {
        self.textures.iter().map(|(n, _)| n.as_str())
    }

    /// The near-field image of area light `a` on file `f`, added to
    /// `image`, and its time.
    fn add_area(
        &self,
        f: &ViewFile,
        a: &AreaParams,
        image: &mut Image,
    ) -> Result<Duration, FrameError> {
        let near = f.near.as_ref().ok_or_else(|| {
            FrameError::Bad(format!(
                "{} has no near-field rows (its scene has no [light_plane]): it takes no area light",
                f.info.name
            ))
        })?;
        let t = Instant::now();
        let texture = self.textures[a.texture].1.clone();
        let (texture, size) = crate::area_light::turned(texture, a.size, a.degrees)
            .map_err(|e| FrameError::Bad(format!("{e:#}")))?;
        let light = AreaLight {
            texture,
            placement: Placement {
                center: a.center,
                size,
                intensity: a.intensity,
            },
        };
        let lit = near
            .render(&[light], NearFieldMethod::Exact)
            .map_err(|e| FrameError::Bad(e.to_string()))?;
        for (o, v) in image.data.iter_mut().zip(&lit) {
            for c in 0..3 {
                o[c] += v[c];
            }
        }
        Ok(t.elapsed())
    }

    /// The glossy materials of `--brdf`, if any.
    pub fn materials(&self) -> Option<&Materials> {
        self.materials.as_ref()
    }

    /// Glossy material `g` seen from its eye, added to file `f`'s relit
    /// texture `image` under lighting `p`.
    fn add_glossy(
        &self,
        f: (usize, &ViewFile),
        g: &GlossyParams,
        p: &FrameParams,
        image: &mut Image,
    ) -> Result<GlossyTimes, FrameError> {
        let (index, file) = f;
        if file.points.0.is_empty() {
            return Err(FrameError::Bad(format!(
                "{} is an image-space file whose surface records do not fix the eye its pixels were seen from: it takes no glossy material",
                file.info.name
            )));
        }
        let materials = self.materials.as_ref().ok_or_else(|| {
            FrameError::Bad("no glossy materials: start ltm view with --brdf SPEC".into())
        })?;
        // The transport's lighting at the glossy side (a draft while the
        // lighting moves, as the transport's); kept in the light cache.
        let (cubemap, _, draft) = self.light(materials.side(), &p.lighting, p.resampling);
        let lit = (p.lighting.map, key_of(&p.lighting), draft);
        // An image-space file's pixels are seen from its camera's eye.
        let eye = DVec3::from(file.info.eye.unwrap_or(g.eye));
        materials
            .add(
                (index, &file.points.0),
                g.material,
                (lit, cubemap.as_slice()),
                eye,
                image,
            )
            .map_err(|e| FrameError::Internal(format!("{e:#}")))
    }

    /// The listed maps.
    pub fn maps(&self) -> impl Iterator<Item = &MapInfo> {
        self.maps.iter().map(|(i, _)| i)
    }

    /// Number of maps.
    pub fn map_count(&self) -> usize {
        self.maps.len()
    }

    /// The preview of the lighting's map, rotated (`/api/map`).
    pub fn map_preview(&self, l: &Lighting) -> Image {
        self.previews[l.map].rotated(&l.rotation)
    }

    /// Whether `--reference` was given.
    pub fn has_reference(&self) -> bool {
        self.raw.is_some()
    }

    /// The reference store's file name.
    pub fn reference_name(&self) -> Option<String> {
        self.raw.as_ref().map(|(p, _)| file_name(p))
    }

    /// The rotated cubemap light at face resolution `n`, and the time spent
    /// resampling it (zero when cached): the exact one when it is cached or
    /// `how` asks for it, else the draft (flagged `true`).
    pub fn light(&self, n: usize, l: &Lighting, how: Resampling) -> (Light, Duration, bool) {
        let key = (n, l.map, key_of(l));
        if let Some(v) = lock(&self.lights).iter().find(|(k, _)| *k == key) {
            return (v.1.clone(), Duration::ZERO, false);
        }
        if how == Resampling::Draft {
            if let Some(v) = lock(&self.drafts).iter().find(|(k, _)| *k == key) {
                return (v.1.clone(), Duration::ZERO, true);
            }
            let t = Instant::now();
            let light = Arc::new(self.prefiltered(n, l.map).to_cubemap(&l.rotation));
            let took = t.elapsed();
            let mut drafts = lock(&self.drafts);
            drafts.push_back((key, light.clone()));
            if drafts.len() > DRAFTS_KEPT {
                drafts.pop_front();
            }
            return (light, took, true);
        }
        let t = Instant::now();
        let light = Arc::new(self.maps[l.map].1.to_cubemap(n, &l.rotation));
        let took = t.elapsed();
        let mut cache = lock(&self.lights);
        cache.push_back((key, light.clone()));
        if cache.len() > LIGHT_CACHE {
            cache.pop_front();
        }
        (light, took, false)
    }

    /// Map `map` prepared for draft resampling at face resolution `n`
    /// (made on first use, about one exact resampling at `2n`).
    fn prefiltered(&self, n: usize, map: usize) -> Arc<PrefilteredMap> {
        let mut kept = lock(&self.prefiltered);
        if let Some((_, p)) = kept.iter().find(|(k, _)| *k == (map, n)) {
            return p.clone();
        }
        let p = Arc::new(PrefilteredMap::new(&self.maps[map].1, n));
        kept.push(((map, n), p.clone()));
        if kept.len() > PREFILTERED_KEPT {
            kept.remove(0);
        }
        p
    }

    /// Records `c` as its client's latest request; false when a newer one
    /// was already seen.
    pub fn note_client(&self, c: &Client) -> bool {
        let mut m = lock(&self.clients);
        if m.len() >= MAX_CLIENTS && !m.contains_key(&c.id) {
            // Forget the client heard from longest ago.
            if let Some(old) = m.iter().min_by_key(|(_, v)| v.1).map(|(k, _)| k.clone()) {
                m.remove(&old);
            }
        }
        let e = m.entry(c.id.clone()).or_insert((c.seq, Instant::now()));
        if c.seq < e.0 {
            return false;
        }
        *e = (c.seq, Instant::now());
        true
    }

    /// Whether a newer request from the same client has arrived.
    fn is_stale(&self, c: &Option<Client>) -> bool {
        c.as_ref()
            .is_some_and(|c| lock(&self.clients).get(&c.id).is_some_and(|v| v.0 > c.seq))
    }

    /// Makes a frame: waits for nothing (a busy server answers Busy), and
    /// drops the request when a newer one from the same client arrived.
    pub fn frame(&self, p: &FrameParams) -> Result<FrameOut, FrameError> {
        if let Some(c) = &p.client {
            if !self.note_client(c) {
                return Err(FrameError::Stale);
            }
        }
        let _slot = self.slots.try_acquire().ok_or(FrameError::Busy)?;
        if self.is_stale(&p.client) {
            return Err(FrameError::Stale);
        }
        let f = &self.files[p.file];
        let (light, resample_time, draft) = self.light(f.face_res(), &p.lighting, p.resampling);
        let kept = lock(&f.frames).pop();
        let mut frame = match kept {
            Some(frame) => frame,
            None => f
                .relighter
                .frame()
                .map_err(|e| FrameError::Bad(e.to_string()))?,
        };
        let request = Request {
            terms: p.terms,
            weighting: p.weighting,
        };
        let t = Instant::now();
        let result = f.relighter.relight(&light, &request, &mut frame);
        let frame_time = t.elapsed();
        let out = match result {
            Ok(stats) => {
                let mut image = frame.image.clone();
                let (error, area_time) = match &p.area {
                    None => (
                        self.cached_exact(&p.lighting)
                            .and_then(|e| relative_l2(&image, &e).ok()),
                        None,
                    ),
                    Some(a) => match self.add_area(f, a, &mut image) {
                        Ok(t) => (None, Some(t)),
                        Err(e) => {
                            lock(&f.frames).push(frame);
                            return Err(e);
                        }
                    },
                };
                // The exact image is the transport's: a glossy frame has no
                // error against it.
                let (error, glossy) = match &p.glossy {
                    None => (error, None),
                    Some(g) => match self.add_glossy((p.file, f), g, p, &mut image) {
                        Ok(t) => (None, Some(t)),
                        Err(e) => {
                            lock(&f.frames).push(frame);
                            return Err(e);
                        }
                    },
                };
                // A glossy part lit by a draft makes a draft frame.
                let draft = draft || glossy.as_ref().is_some_and(|g| g.draft);
                Ok(FrameOut {
                    image,
                    stats,
                    frame_time,
                    resample_time,
                    draft,
                    error,
                    area_time,
                    glossy,
                })
            }
            Err(e) => Err(FrameError::Bad(e.to_string())),
        };
        lock(&f.frames).push(frame);
        if self.is_stale(&p.client) {
            return Err(FrameError::Stale);
        }
        out
    }

    fn cached_exact(&self, l: &Lighting) -> Option<Arc<Image>> {
        let key = (l.map, key_of(l));
        lock(&self.exact)
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v.clone())
    }

    /// The exact image T·L from the raw store (cached per map and rotation)
    /// and the time it took (zero when cached).
    pub fn exact(&self, l: &Lighting) -> Result<(Arc<Image>, Duration), FrameError> {
        let Some((_, raw)) = &self.raw else {
            return Err(FrameError::Bad(
                "no reference: start ltm view with --reference RAW".into(),
            ));
        };
        if let Some(img) = self.cached_exact(l) {
            return Ok((img, Duration::ZERO));
        }
        let _slot = self.slots.try_acquire().ok_or(FrameError::Busy)?;
        let n = raw.dims().face_res() as usize;
        let (light, _, _) = self.light(n, l, Resampling::Exact);
        let t = Instant::now();
        let img =
            Arc::new(reference(raw, &light).map_err(|e| FrameError::Internal(e.to_string()))?);
        let took = t.elapsed();
        let mut cache = lock(&self.exact);
        cache.push_back(((l.map, key_of(l)), img.clone()));
        if cache.len() > EXACT_CACHE {
            cache.pop_front();
        }
        Ok((img, took))
    }
}

/// Opens the raw store and checks that it is the matrix of the files.
fn open_raw(p: &Path, files: &[ViewFile], limits: &Limits) -> Result<RawStore> {
    let raw = RawStore::open_with_limits(p, limits)
        .with_context(|| format!("opening raw store {}", p.display()))?;
    let d = raw.dims();
    let size = (d.width() as usize, d.height() as usize);
    for f in files {
        let i = &f.info;
        if (i.width, i.height, i.lights) != (size.0, size.1, d.lights()) {
            bail!(
                "--reference {}: {}×{} rows and {} lights, but {} has {}×{} and {}",
                p.display(),
                size.0,
                size.1,
                d.lights(),
                f.path.display(),
                i.width,
                i.height,
                i.lights
            );
        }
    }
    Ok(raw)
}

/// Locks a mutex, recovering the data if a panicking thread poisoned it.
pub(super) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A counting semaphore that never waits: at most `n` holders.
struct Slots {
    free: Mutex<usize>,
}

/// A held slot, given back when dropped (also when its request's client
/// went away or a frame failed).
struct Slot<'a>(&'a Slots);

impl Slots {
    fn new(n: usize) -> Slots {
        Slots {
            free: Mutex::new(n.max(1)),
        }
    }

    fn try_acquire(&self) -> Option<Slot<'_>> {
        let mut f = lock(&self.free);
        if *f == 0 {
            return None;
        }
        *f -= 1;
        Some(Slot(self))
    }
}

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        *lock(&self.0.free) += 1;
    }
}
