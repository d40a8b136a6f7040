//! Routing and responses: every request is answered, bad ones with a 4xx
//! status and a one-line message. Routing is cheap and runs on the server's
//! I/O threads; frames and exact images are returned as a [`Job`] that the
//! server runs on its bounded blocking pool (`server.rs`).

use super::params::{self, BadRequest, Bounds, FrameParams, Resampling};
use super::state::{FrameError, FrameOut, Viewer};
use half::f16;
use http_body_util::Full;
use hyper::body::Bytes;
use hyper::header::{HeaderName, HeaderValue};
use hyper::{Method, Response, StatusCode};
use ltm_relight::Image;
use std::net::IpAddr;
use std::time::Instant;

/// The page and its script, embedded so that the viewer works offline.
const PAGE: &str = include_str!("page.html");
const SCRIPT: &str = include_str!("view.js");

/// Magic of a binary frame.
pub const FRAME_MAGIC: &[u8; 4] = b"LTMF";
/// Format code of RGB half floats.
pub const FORMAT_RGB_F16: u32 = 1;
/// Magic of a binary surface (geometry image).
pub const SURFACE_MAGIC: &[u8; 4] = b"LTMS";
/// Magic of a binary drawn mesh.
pub const MESH_MAGIC: &[u8; 4] = b"LTMG";
/// The answer to a frame when every frame slot and queue place is taken.
pub const BUSY: &str = "busy: every frame slot is taken; try again";

/// A complete response.
pub type Reply = Response<Full<Bytes>>;

/// Adds a header; names and values are ours (ASCII), so neither fails, and
/// one that did would be left out rather than bring anything down.
fn with_header(mut r: Reply, name: &str, value: &str) -> Reply {
    if let (Ok(n), Ok(v)) = (
        HeaderName::from_bytes(name.as_bytes()),
        HeaderValue::from_str(value),
    ) {
        r.headers_mut().append(n, v);
    }
    r
}

fn with_status(data: Vec<u8>, status: u16) -> Reply {
    let mut r = Response::new(Full::new(Bytes::from(data)));
    *r.status_mut() = StatusCode::from_u16(status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
    r
}

/// A status with a one-line text message.
pub fn text(status: u16, msg: &str) -> Reply {
    with_header(
        with_status(format!("{msg}\n").into_bytes(), status),
        "Content-Type",
        "text/plain; charset=utf-8",
    )
}

fn bad(e: BadRequest) -> Reply {
    text(400, &e.0)
}

fn body(data: Vec<u8>, content_type: &str) -> Reply {
    let r = with_header(with_status(data, 200), "Content-Type", content_type);
    with_header(r, "Cache-Control", "no-store")
}

/// The answer to a bug of ours (a panic while answering).
pub fn internal() -> Reply {
    text(500, "internal error")
}

/// Which `Host` headers are answered. A loopback server answers only names
/// of this machine (which guards it against pages of other sites reaching
/// it through DNS rebinding): `localhost`, `127.0.0.1`, `[::1]` and the
/// bound address itself, with any port. A server bound to another address
/// is reachable from other machines by their names for it: any Host.
#[derive(Clone, Debug)]
pub struct HostCheck(Option<Vec<String>>);

impl HostCheck {
    /// The check for a server bound to `ip`.
    pub fn for_bind(ip: IpAddr) -> HostCheck {
        if !ip.is_loopback() {
            return HostCheck(None);
        }
        let mut names: Vec<String> = ["localhost", "127.0.0.1", "[::1]"].map(String::from).into();
        let own = match ip {
            IpAddr::V4(v4) => v4.to_string(),
            IpAddr::V6(v6) => format!("[{v6}]"),
        };
        if !names.contains(&own) {
            names.push(own);
        }
        HostCheck(Some(names))
    }

    /// Whether a request with this Host header (none: HTTP/1.0) is answered.
    pub fn allows(&self, host: Option<&HeaderValue>) -> bool {
        let Some(names) = &self.0 else {
            return true;
        };
        let Some(h) = host else {
            return true;
        };
        let Ok(host) = h.to_str() else {
            return false;
        };
        let name = match host.rfind(':') {
            Some(i) if !host.ends_with(']') => &host[..i],
            _ => host,
        };
        names.iter().any(|n| n.eq_ignore_ascii_case(name))
    }

    /// One line saying what the check allows.
    pub fn describe(&self) -> String {
        match &self.0 {
            Some(names) => format!(
                "answers requests whose Host is {} (any port); other hosts get 403",
                names.join(", ")
            ),
            None => "answers requests for any Host (bound to an address other machines reach)"
                .to_string(),
        }
    }
}

/// A request's heavy part, run on the server's blocking pool.
pub enum Job {
    /// `/api/frame`.
    Frame(FrameParams),
    /// `/api/exact`.
    Exact(FrameParams),
}

impl Job {
    /// Makes the frame (or exact image) and its reply.
    pub fn run(&self, viewer: &Viewer) -> Reply {
        match self {
            Job::Frame(p) => frame(viewer, p),
            Job::Exact(p) => exact(viewer, p),
        }
    }
}

/// What a request needs: an answer now, or a job.
pub enum Routed {
    /// Answered.
    Reply(Reply),
    /// To be run on the blocking pool.
    Job(Job),
}

/// Routes a request (`url`: its target as sent, path and query) and
/// answers what needs no relighting.
pub fn route(
    method: &Method,
    url: &str,
    host: Option<&HeaderValue>,
    viewer: &Viewer,
    hosts: &HostCheck,
) -> Routed {
    if url.len() > params::MAX_URL {
        return Routed::Reply(text(
            414,
            &format!(
                "request target of {} bytes (valid: at most {})",
                url.len(),
                params::MAX_URL
            ),
        ));
    }
    if *method != Method::GET {
        return Routed::Reply(text(405, "only GET is served"));
    }
    if !hosts.allows(host) {
        return Routed::Reply(text(403, "this server answers only requests to localhost"));
    }
    let (path, query) = url.split_once('?').unwrap_or((url, ""));
    let b = Bounds {
        files: viewer.files.len(),
        maps: viewer.map_count(),
        textures: viewer.area_textures().count(),
        materials: viewer.materials().map_or(0, |m| m.count()),
    };
    let terms = |f: usize| viewer.files[f].info.max_terms;
    Routed::Reply(match path {
        "/" | "/index.html" => body(PAGE.as_bytes().to_vec(), "text/html; charset=utf-8"),
        "/view.js" => body(SCRIPT.as_bytes().to_vec(), "text/javascript; charset=utf-8"),
        "/api/info" => no_query(query).map_or_else(bad, |_| info(viewer)),
        "/api/frame" => match params::frame(query, &b, &terms) {
            Ok(p) => return Routed::Job(Job::Frame(p)),
            Err(e) => bad(e),
        },
        "/api/exact" => match params::frame(query, &b, &terms) {
            Ok(p) => return Routed::Job(Job::Exact(p)),
            Err(e) => bad(e),
        },
        "/api/map" => match params::parse_query(query, &["map", "yaw", "pitch", "roll"])
            .and_then(|q| params::lighting(&q, &b))
        {
            Ok(l) => body(
                encode_frame(&viewer.map_preview(&l)),
                "application/octet-stream",
            ),
            Err(e) => bad(e),
        },
        "/api/surface" => match params::parse_query(query, &["file"])
            .and_then(|q| params::index(&q, "file", b.files))
        {
            Ok(f) => surface(viewer, f),
            Err(e) => bad(e),
        },
        "/api/mesh" => match params::parse_query(query, &["file"])
            .and_then(|q| params::index(&q, "file", b.files))
        {
            Ok(f) => mesh(viewer, f),
            Err(e) => bad(e),
        },
        _ => text(404, "not found"),
    })
}

fn no_query(q: &str) -> Result<(), BadRequest> {
    params::parse_query(q, &[]).map(|_| ())
}

fn info(viewer: &Viewer) -> Reply {
    let v = serde_json::json!({
        "files": viewer.files.iter().map(|f| &f.info).collect::<Vec<_>>(),
        "maps": viewer.maps().collect::<Vec<_>>(),
        "reference": viewer.reference_name(),
        "area_textures": viewer.area_textures().collect::<Vec<_>>(),
        "brdfs": viewer.materials().map(|m| m.names()).unwrap_or_default(),
        "glossy_n": viewer.materials().map(|m| m.side()),
        "weightings": ["unweighted", "transport", "area"],
        "max_angle": params::MAX_ANGLE,
        "preloaded": viewer.preloaded(),
    });
    body(v.to_string().into_bytes(), "application/json")
}

/// Encodes an image: the 16-byte header (magic, width, height, format,
/// little-endian u32s) and RGB half floats, rows top to bottom.
pub fn encode_frame(image: &Image) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 + image.data.len() * 6);
    out.extend_from_slice(FRAME_MAGIC);
    for v in [image.width as u32, image.height as u32, FORMAT_RGB_F16] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for p in &image.data {
        for c in p {
            out.extend_from_slice(&f16::from_f32(*c).to_le_bytes());
        }
    }
    out
}

fn frame_error(e: FrameError) -> Reply {
    match e {
        FrameError::Stale => with_header(text(204, ""), "X-Stale", "1"),
        FrameError::Busy => text(503, BUSY),
        FrameError::Bad(m) => text(400, &m),
        FrameError::Internal(m) => text(500, &m),
    }
}

fn ms(d: std::time::Duration) -> String {
    format!("{:.3}", d.as_secs_f64() * 1e3)
}

fn frame_reply(f: &FrameOut, image: &Image) -> Reply {
    let mut r = body(encode_frame(image), "application/octet-stream");
    r = with_header(r, "X-Frame-Ms", &ms(f.frame_time));
    r = with_header(r, "X-Resample-Ms", &ms(f.resample_time));
    if let Some(t) = f.area_time {
        r = with_header(r, "X-Area-Ms", &ms(t));
    }
    if let Some(g) = &f.glossy {
        r = with_header(r, "X-Glossy-Setup-Ms", &ms(g.setup));
        r = with_header(r, "X-Step1-Ms", &ms(g.step1));
        r = with_header(r, "X-Step2-Ms", &ms(g.step2));
    }
    r = with_header(r, "X-Light", if f.draft { "draft" } else { "exact" });
    r = with_header(r, "X-Lights", &f.stats.lights.to_string());
    r = with_header(r, "X-Nonzeros", &f.stats.nonzeros.to_string());
    if let Some(e) = f.error {
        r = with_header(r, "X-Error", &format!("{e:.9}"));
    }
    r
}

fn frame(viewer: &Viewer, p: &FrameParams) -> Reply {
    match viewer.frame(p) {
        Ok(f) => frame_reply(&f, &f.image),
        Err(e) => frame_error(e),
    }
}

fn exact(viewer: &Viewer, p: &FrameParams) -> Reply {
    let t = Instant::now();
    let exact = match viewer.exact(&p.lighting) {
        Ok((img, _)) => img,
        Err(e) => return frame_error(e),
    };
    let took = t.elapsed();
    // The exact view is the map's T·L: its frame is the map's alone.
    let p = FrameParams {
        client: None,
        resampling: Resampling::Exact,
        area: None,
        glossy: None,
        ..p.clone()
    };
    match viewer.frame(&p) {
        Ok(f) => with_header(frame_reply(&f, &exact), "X-Exact-Ms", &ms(took)),
        Err(e) => frame_error(e),
    }
}

/// The 400 answer for an image-space file asked for its mesh or surface.
fn no_mesh(f: usize) -> Reply {
    text(
        400,
        &format!("file {f} is an image-space file; it has no surface"),
    )
}

/// A texture-space file's geometry image: header (magic, side, side, 2),
/// then x, y, z as little-endian f32 per texel (its surface record), then
/// one valid byte per texel. An image-space file gets 400.
fn surface(viewer: &Viewer, f: usize) -> Reply {
    let Some(m) = &viewer.files[f].mesh else {
        return no_mesh(f);
    };
    let side = m.size() as u32;
    let (records, valid) = m.records();
    let mut out = Vec::with_capacity(16 + records.len() * 13);
    out.extend_from_slice(SURFACE_MAGIC);
    for v in [side, side, 2] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for p in records {
        for c in p.to_array() {
            out.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    out.extend(valid.iter().map(|&v| u8::from(v)));
    body(out, "application/octet-stream")
}

/// What `ltm render` draws for a texture-space file (see the module docs
/// for the layout). An image-space file gets 400.
fn mesh(viewer: &Viewer, f: usize) -> Reply {
    let Some(m) = &viewer.files[f].mesh else {
        return no_mesh(f);
    };
    let (v, t) = (m.positions().len(), m.triangles().len());
    let mut out = Vec::with_capacity(16 + v * 20 + t * 17);
    out.extend_from_slice(MESH_MAGIC);
    // Format 1: every triangle drawn; 2: back faces culled.
    let format = if m.culls_back_faces() { 2 } else { 1 };
    for n in [v as u32, t as u32, format] {
        out.extend_from_slice(&n.to_le_bytes());
    }
    let mut f32s = |vals: &mut dyn Iterator<Item = f64>| {
        for x in vals {
            out.extend_from_slice(&(x as f32).to_le_bytes());
        }
    };
    f32s(&mut m.positions().iter().flat_map(|p| p.to_array()));
    f32s(&mut m.uvs().iter().flat_map(|q| q.to_array()));
    for i in m.triangles().iter().flatten() {
        out.extend_from_slice(&i.to_le_bytes());
    }
    for r in m.reach() {
        out.extend_from_slice(&(*r as f32).to_le_bytes());
    }
    out.extend(m.folded().iter().map(|&x| u8::from(x)));
    body(out, "application/octet-stream")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn allows(check: &HostCheck, host: &str) -> bool {
        check.allows(Some(&HeaderValue::from_str(host).unwrap()))
    }

    #[test]
    fn host_check_allows_local_names_and_the_bound_address() {
        let c = HostCheck::for_bind("127.0.0.2".parse().unwrap());
        for h in [
            "localhost",
            "LOCALHOST:8080",
            "127.0.0.1:1",
            "[::1]:80",
            "127.0.0.2:9",
        ] {
            assert!(allows(&c, h), "{h}");
        }
        for h in ["evil.example", "127.0.0.3:80", "localhost.evil:80", "[::2]"] {
            assert!(!allows(&c, h), "{h}");
        }
        assert!(c.allows(None));
        let v6 = HostCheck::for_bind("::1".parse().unwrap());
        assert!(allows(&v6, "[::1]:8080") && !allows(&v6, "evil"));
        assert!(v6
            .describe()
            .ends_with("Host is localhost, 127.0.0.1, [::1] (any port); other hosts get 403"));
        let any = HostCheck::for_bind("0.0.0.0".parse().unwrap());
        assert!(allows(&any, "evil.example"));
    }
}
