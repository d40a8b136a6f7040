//! `ltm view`: an interactive relighting page served on a local port.
//!
//! The page (`page.html`, `view.js`, embedded in the binary) asks the server
//! for frames and draws them on a canvas; exposure and tone mapping are
//! applied in the browser, so they need no new frame. Only the files named
//! on the command line are read: maps and files are chosen by index.
//!
//! # API (all `GET`; any other method gets 405, a bad parameter 400)
//!
//! - `/api/info`: JSON with `files` (name, bytes, mode, matrix_error, width,
//!   height, lights, max_terms, layout `image` or `texture`, `near_field`:
//!   the light plane's `order` and `side` of a file with near-field rows,
//!   else null), `maps` (name, width, height), `reference` (the raw store's
//!   name or null), `area_textures` (names; index 0 is `uniform`), `brdfs`
//!   (the `--brdf` specs: material K is `brdfs[K − 1]`) and `glossy_n`
//!   (their lighting side, or null). With `--brdf`, an image-space file's
//!   `eye` is the camera position its pixels were seen from, recovered
//!   from its surface records (`ltm_codec::ImageCamera`), or null where
//!   they do not fix it (texture files: null). `preloaded` is true once
//!   every column of every file is decoded (the server decodes them in the
//!   background from the start; until then a frame decodes the columns it
//!   needs first, and a drag that meets many new columns is slower).
//! - `/api/frame?file=F&map=M&yaw=Y&pitch=P&roll=R&n=N&weighting=W&light=L&client=C&seq=S`:
//!   one frame. `yaw`, `pitch`, `roll` (degrees, finite, |a| ≤ 36000),
//!   `weighting` (unweighted, transport, area) and `light` are optional.
//!   `light=draft` lets a rotation whose exact light is not cached be
//!   resampled approximately (`ltm_relight::PrefilteredMap`, about 1 ms
//!   instead of tens): the page asks for drafts while the lighting moves
//!   and for the exact frame once it rests. `n` is 1 to the
//!   file's `max_terms`; `client` (1–32 letters and digits) and `seq` go
//!   together: a request older than the newest seen from the same client
//!   is dropped with 204 (latest request wins). Frames run in a fixed number
//!   of slots; when all are busy the answer is 503. An area light
//!   (files with near-field rows only; a scene's `[light_plane]`) is added
//!   with `ax`, `ay` (centre in the plane), `aw`, `ah` (sides, > 0), `ai`
//!   (intensity, >= 0), all five or none (finite, |v| ≤ 10⁶), and optionally
//!   `aq` (quarter turns, 0..=3) or `ad` (degrees, any angle within
//!   ±3600), and `at` (texture index); it is lit
//!   exactly (`ltm relight --area-method exact`), `X-Area-Ms` gives its
//!   time, and such a frame carries no `X-Error` (the exact image is the
//!   map's). A glossy material (`ltm view --brdf`; texture-space files,
//!   and image-space files with an `eye`) is added with `brdf` (1 to the number of `--brdf` materials; 0, the
//!   default, is the baked material alone) and `eye` (`x,y,z` in world
//!   units, finite, |v| ≤ 10⁶; required with `brdf` ≥ 1, refused without):
//!   the frame is then what `ltm render --brdf SPEC --shading sum` draws
//!   from that eye (see `glossy.rs`; an image-space file's pixels are
//!   shaded from its own `eye` whatever the request gives, as `ltm
//!   relight --brdf SPEC` shades them), with `X-Step1-Ms` (0 when the file's
//!   lighting was kept), `X-Step2-Ms` and `X-Glossy-Setup-Ms` (rotation
//!   matrices and slices on first use, and a switch of material), and no
//!   `X-Error`.
//! - `/api/exact?…` (same parameters): the exact image `T·L` from the
//!   `--reference` store, computed on demand and cached per map and
//!   rotation; `X-Error` gives the frame's relative L2 error against it.
//!   Once cached, `/api/frame` answers also carry `X-Error`.
//! - `/api/map?map=M&yaw=Y&pitch=P&roll=R`: the map's preview, at most
//!   256 × 128 (box-filtered once at start), rotated as the frames' lighting
//!   is (pixel ω shows the map's light from `R⁻¹·ω`, nearest pixel), as a
//!   binary frame (below). The page fetches each map's unrotated preview
//!   once and turns it itself, with the same nearest pixels (a yaw drag
//!   costs no request).
//! - `/api/surface?file=F`: a texture-space file's texel records: the
//!   16-byte header below with magic `LTMS` and format 2, then x, y, z as
//!   little-endian f32 per texel (its surface point; rows top to bottom),
//!   then one valid byte per texel.
//! - `/api/mesh?file=F`: what `ltm render` draws for a texture-space file
//!   (`ltm_relight::TexturedMesh`: its stored receiver mesh, or the grid of
//!   its geometry image), so that the page triangulates nothing itself.
//!   A 16-byte header of four little-endian `u32`s: magic `LTMG` (bytes),
//!   vertex count V, triangle count T, format (1: draw every triangle; 2:
//!   cull back faces, as `ltm render` does for a stored mesh, whose open
//!   surfaces carry each side as triangles of their own); then, all
//!   little-endian:
//!   V × (x, y, z) f32 vertex positions; V × (u, v) f32 texture coordinates
//!   in texel units (u rightwards, v downwards, texel (x, y) covering
//!   [x, x+1] × [y, y+1]); T × 3 u32 vertex indices (counter-clockwise);
//!   T f32 reaches (the chart rule: a texel is read for a shaded point
//!   only when its record lies within this distance; +infinity: no limit);
//!   T bytes, 1 where the triangle crosses a fold of the sphere layout's
//!   square and is shaded by blending its corners' texels (the texel
//!   holding each corner's coordinate) with the barycentrics.
//!   The page renders the relit texture with exactly `ltm render`'s lookup
//!   (see `ltm_relight::TexturedMesh`) in its fragment shader.
//!
//! # Binary frame
//!
//! A 16-byte header of four little-endian `u32`s: magic `LTMF` (bytes),
//! width, height, format (1 = RGB half float), then `width·height·3`
//! little-endian IEEE half floats, linear RGB, rows top to bottom. Headers
//! carry the readouts: `X-Frame-Ms` (relight wall time on the server),
//! `X-Resample-Ms` (resampling the map to the rotated cubemap; 0 when the
//! rotated light was cached), `X-Light` (`exact`, or `draft` for a frame
//! asked for with `light=draft` whose exact light was not cached),
//! `X-Lights` (lights used), `X-Nonzeros`
//! (coefficients multiply-added), `X-Error` and `X-Exact-Ms` where given.

mod glossy;
mod http;
pub mod params;
mod preview;
mod server;
mod state;

use crate::common::{claim_files_and_cache, map_files, Ctx};
use anyhow::{Context, Result};
use clap::Args;
use std::io::Write;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Most files `ltm view` compares.
pub const MAX_FILES: usize = 2;

/// Arguments of `ltm view`.
#[derive(Args)]
#[command(
    after_long_help = "Open the printed URL in a browser. Drag on the image to rotate the \
lighting; the page has fields for yaw, pitch and roll, a log-scale slider for N, the map, \
the weighting, exposure and tone mapping, and readouts of the server's frame time, the \
round trip, lights used and nonzeros touched. With two files they are shown side by side \
(or under a split slider). With --reference, the exact image T·L can be shown and the \
frame's error against it is read out. Texture-space files are drawn as their mesh in WebGL \
with an orbit camera. A file baked with a [light_plane] also takes an area light: its \
texture, centre, size, intensity and angle are fields of the page, and a \
shift-drag on an image moves it.

Limits: at most 4096 connections at once (fewer where the open-file limit is lower: the \
limit less 256; it is raised toward the hard limit first), one beyond gets 503; 5 s to send \
a request's head (idle and half-open connections close then); 32 KiB per request head \
(more gets 431); 10 s for a write that makes no progress; --slots frames at once (more get \
503 at once). The URL is printed on standard output and standard error; a closed standard \
output does not stop the server."
)]
pub struct ViewArgs {
    /// One or two compressed matrices (two are compared side by side).
    #[arg(required = true, num_args = 1..=MAX_FILES)]
    pub files: Vec<PathBuf>,
    /// Environment maps to offer (lat-long EXR or HDR); the maps in
    /// ./assets/envmaps are added when that folder exists.
    #[arg(long, value_name = "MAP")]
    pub env: Vec<PathBuf>,
    /// Raw store of the same matrix: enables the exact view and its error.
    #[arg(long, value_name = "RAW")]
    pub reference: Option<PathBuf>,
    /// Port to listen on (0: any free port).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
    /// Address to listen on. The default serves only this machine; any
    /// other address must be given here explicitly. A loopback address
    /// answers only requests whose Host is localhost, 127.0.0.1, ::1 or
    /// itself; another answers any Host (0.0.0.0 prints the 127.0.0.1 URL).
    #[arg(long, value_name = "ADDR")]
    pub bind: Option<IpAddr>,
    /// An area-light texture to offer in the page (EXR or PNG, as `ltm
    /// relight --area-light` reads it); repeatable. `uniform` is always
    /// offered. Only files baked with a `[light_plane]` take area lights.
    #[arg(long = "area-light", value_name = "TEXTURE")]
    pub area_light: Vec<PathBuf>,
    /// Frames computed at once (more concurrent frame requests get 503;
    /// at most slots + 4 frame requests are handled at once).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=64))]
    pub slots: u16,
    /// A glossy material for the page's material menu (repeatable), as
    /// `ltm render --brdf` takes it (`ggx:0.2`, `plastic:0.1`,
    /// `merl:PATH`, ...). A texture-space file is then drawn as `ltm
    /// render --brdf SPEC --shading sum` draws it from the page's eye: the
    /// relit texture plus the material's glossy reflection (unshadowed),
    /// by wavelet rotation; an image-space file as `ltm relight --brdf
    /// SPEC` draws it, from the eye its surface records fix. Orbiting the mesh re-runs step 2 only (about
    /// 12 ms a step of a drag and 30–40 ms a jump, for 256² texels), and so
    /// does a new material once its slices are built (0.4 s at n = 64,
    /// 1.2 s at 128); a new lighting re-runs step 1 (about 0.16 s at
    /// n = 64, 0.6 s at 128). The first glossy frame builds the rotation
    /// matrices (about 11 s at n = 64, 47 s at 128 on 2 cores) unless
    /// --rotation-cache holds them (docs/results/glossy.md).
    #[arg(long = "brdf", value_name = "SPEC")]
    pub brdf: Vec<String>,
    /// Side n of the octahedral lighting map of the glossy materials (a
    /// power of two, 8..=128) [default: the largest the --brdf materials
    /// need: 64 for Lambert and lobes of α ≥ 0.4, else 128]. One rotation
    /// set serves the whole menu; see `ltm render --help` for what n costs
    /// and gains.
    #[arg(long, value_name = "N", requires = "brdf")]
    pub glossy_n: Option<usize>,
    /// Rotation cache of the glossy materials (a file or a folder), as
    /// `ltm render --rotation-cache` takes it.
    #[arg(long, value_name = "PATH", requires = "brdf")]
    pub rotation_cache: Option<PathBuf>,
}

/// The maps in ./assets/envmaps (EXR and HDR, by name), if any.
fn asset_maps() -> Vec<PathBuf> {
    map_files(Path::new("assets/envmaps")).unwrap_or_default()
}

/// The `--env` maps, then the asset maps not already given.
fn map_list(given: &[PathBuf]) -> Vec<PathBuf> {
    let mut maps = given.to_vec();
    let canon: Vec<_> = given.iter().filter_map(|p| p.canonicalize().ok()).collect();
    for p in asset_maps() {
        if !p.canonicalize().is_ok_and(|c| canon.contains(&c)) {
            maps.push(p);
        }
    }
    maps
}

pub fn run(a: ViewArgs, ctx: &Ctx) -> Result<()> {
    let mut inputs: Vec<(&str, &Path)> = a.files.iter().map(|f| ("input", f.as_path())).collect();
    inputs.extend(a.env.iter().map(|m| ("--env", m.as_path())));
    if let Some(r) = &a.reference {
        inputs.push(("--reference", r.as_path()));
    }
    inputs.extend(a.area_light.iter().map(|t| ("--area-light", t.as_path())));
    let materials = match a.brdf.is_empty() {
        true => None,
        false => Some(glossy::Materials::new(
            &a.brdf,
            a.glossy_n,
            a.rotation_cache.clone(),
            a.files.len(),
            ctx.limits(),
        )?),
    };
    let cache = materials.as_ref().and_then(glossy::Materials::cache_path);
    if let Some(m) = &materials {
        inputs.extend(m.measured_files().into_iter().map(|f| ("--brdf", f)));
    }
    let cache = cache.as_deref().map(|c| ("--rotation-cache", c));
    claim_files_and_cache(&inputs, &[], cache)?;
    let maps = map_list(&a.env);
    let mut textures = vec![(
        "uniform".to_string(),
        ltm_relight::nearfield::LightTexture::constant([1.0; 3])?,
    )];
    for t in &a.area_light {
        let spec = t.to_string_lossy();
        let texture = crate::area_light::read_texture(&spec, [1.0; 3], ctx.limits())
            .with_context(|| format!("--area-light {spec}"))?;
        textures.push((state::file_name(t), texture));
    }
    let viewer = Arc::new(state::Viewer::open(
        &a.files,
        &maps,
        (a.reference.as_deref(), textures, materials),
        a.slots as usize,
        ctx.limits(),
    )?);
    serve(&a, viewer)
}

/// The URL that reaches a server listening on `addr`: the address itself,
/// or this machine's loopback address for an unspecified one (0.0.0.0,
/// `::`, which take connections to every address of the machine).
pub fn url_of(addr: SocketAddr) -> String {
    let ip = match addr.ip() {
        IpAddr::V4(v4) if v4.is_unspecified() => IpAddr::V4(Ipv4Addr::LOCALHOST),
        IpAddr::V6(v6) if v6.is_unspecified() => IpAddr::V6(Ipv6Addr::LOCALHOST),
        ip => ip,
    };
    format!("http://{}/", SocketAddr::new(ip, addr.port()))
}

/// Ignores SIGPIPE (which `main` sets to end the process): a closed
/// standard output (`ltm view … | true`) or a client gone mid-answer must
/// not end the server; writes fail with `EPIPE` instead.
#[cfg(unix)]
fn survive_closed_pipes() {
    // SAFETY: sets the signal's disposition to "ignore"; no handler runs,
    // and nothing else in the process changes SIGPIPE's disposition.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_IGN);
    }
}

/// Binds, says where (standard output and standard error) and serves.
fn serve(a: &ViewArgs, viewer: Arc<state::Viewer>) -> Result<()> {
    #[cfg(unix)]
    survive_closed_pipes();
    let ip = a.bind.unwrap_or(IpAddr::V4(Ipv4Addr::LOCALHOST));
    if a.bind.is_some() && !ip.is_loopback() {
        eprintln!("warning: serving on {ip}, reachable from other machines (--bind)");
    }
    let listener = TcpListener::bind(SocketAddr::new(ip, a.port))
        .with_context(|| format!("cannot listen on {}", SocketAddr::new(ip, a.port)))?;
    let addr = listener
        .local_addr()
        .context("reading the listening address")?;
    let hosts = http::HostCheck::for_bind(ip);
    let limits = server::Limits {
        connections: server::connection_capacity(),
        jobs: a.slots as usize + server::JOB_QUEUE,
    };
    // Wavelet files decode each column when a frame first needs it; the
    // rest are decoded here meanwhile, so that later frames only relight.
    let v = viewer.clone();
    std::thread::Builder::new()
        .name("view-preload".into())
        .spawn(move || v.preload())
        .context("starting the preload thread")?;
    let url = url_of(addr);
    // Standard output may be closed: the URL also goes to standard error.
    let mut out = std::io::stdout();
    let _ = writeln!(out, "{url}").and_then(|_| out.flush());
    eprintln!(
        "ltm view: {url} ({} file(s), {} map(s){}); Ctrl-C to stop",
        viewer.files.len(),
        viewer.map_count(),
        if viewer.has_reference() {
            ", exact view on"
        } else {
            ""
        }
    );
    eprintln!("ltm view: {}", hosts.describe());
    eprintln!(
        "ltm view: limits: {} connections, {} s to send a request head, {} KiB per head, \
{} s for a stalled write, {} frames at once",
        limits.connections,
        server::HEADER_TIMEOUT.as_secs(),
        server::MAX_HEAD / 1024,
        server::WRITE_STALL.as_secs(),
        a.slots,
    );
    server::serve(listener, viewer, hosts, limits)
}

#[cfg(test)]
mod tests {
    use super::url_of;

    #[test]
    fn url_of_an_unspecified_address_is_loopback() {
        let u = |s: &str| url_of(s.parse().unwrap());
        assert_eq!(u("0.0.0.0:8080"), "http://127.0.0.1:8080/");
        assert_eq!(u("[::]:80"), "http://[::1]:80/");
        assert_eq!(u("127.0.0.2:9"), "http://127.0.0.2:9/");
        assert_eq!(u("[::1]:9"), "http://[::1]:9/");
    }
}
