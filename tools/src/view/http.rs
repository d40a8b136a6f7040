//! Routing and responses over tiny_http: every request is answered, bad
//! ones with a 4xx status and a one-line message.

use super::params::{self, BadRequest, Bounds, FrameParams};
use super::state::{FrameError, FrameOut, Viewer};
use half::f16;
use ltm_relight::Image;
use std::io::Cursor;
use std::time::Instant;
use tiny_http::{Header, Method, Request, Response, Server, StatusCode};

/// The page and its script, embedded so that the viewer works offline.
const PAGE: &str = include_str!("page.html");
const SCRIPT: &str = include_str!("view.js");

/// Magic of a binary frame.
pub const FRAME_MAGIC: &[u8; 4] = b"LTMF";
/// Format code of RGB half floats.
pub const FORMAT_RGB_F16: u32 = 1;
/// Magic of a binary surface (geometry image).
pub const SURFACE_MAGIC: &[u8; 4] = b"LTMS";

type Reply = Response<Cursor<Vec<u8>>>;

fn header(name: &str, value: &str) -> Header {
    // Names and values are ours (ASCII); a failure here is a bug.
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header")
}

fn text(status: u16, msg: &str) -> Reply {
    Response::from_data(format!("{msg}\n").into_bytes())
        .with_status_code(StatusCode(status))
        .with_header(header("Content-Type", "text/plain; charset=utf-8"))
}

fn bad(e: BadRequest) -> Reply {
    text(400, &e.0)
}

fn body(data: Vec<u8>, content_type: &str) -> Reply {
    Response::from_data(data)
        .with_header(header("Content-Type", content_type))
        .with_header(header("Cache-Control", "no-store"))
}

/// Serves requests until the server is dropped; one call per worker
/// thread, so that the worker count bounds the requests handled at once
/// (tiny_http holds the others until a worker is free).
pub fn serve(server: &Server, viewer: &Viewer, loopback: bool) {
    loop {
        let request = match server.recv() {
            Ok(r) => r,
            Err(_) => continue,
        };
        // A bug must not take a worker down with it: it becomes a 500.
        let reply = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            route(&request, viewer, loopback)
        }))
        .unwrap_or_else(|_| text(500, "internal error"));
        // A client that went away is not an error of ours.
        let _ = request.respond(reply);
    }
}

/// Whether the Host header names this machine (guards a loopback server
/// against pages of other sites reaching it through DNS rebinding).
fn local_host(request: &Request) -> bool {
    let Some(h) = request.headers().iter().find(|h| h.field.equiv("Host")) else {
        return true;
    };
    let host = h.value.as_str();
    let name = match host.rfind(':') {
        Some(i) if !host.ends_with(']') => &host[..i],
        _ => host,
    };
    matches!(name, "127.0.0.1" | "localhost" | "[::1]")
}

fn route(request: &Request, viewer: &Viewer, loopback: bool) -> Reply {
    let url = request.url();
    if url.len() > params::MAX_URL {
        return text(
            414,
            &format!(
                "request target of {} bytes (valid: at most {})",
                url.len(),
                params::MAX_URL
            ),
        );
    }
    if *request.method() != Method::Get {
        return text(405, "only GET is served");
    }
    if loopback && !local_host(request) {
        return text(403, "this server answers only requests to localhost");
    }
    let (path, query) = url.split_once('?').unwrap_or((url, ""));
    let b = Bounds {
        files: viewer.files.len(),
        maps: viewer.map_count(),
    };
    match path {
        "/" | "/index.html" => body(PAGE.as_bytes().to_vec(), "text/html; charset=utf-8"),
        "/view.js" => body(SCRIPT.as_bytes().to_vec(), "text/javascript; charset=utf-8"),
        "/api/info" => no_query(query).map_or_else(bad, |_| info(viewer)),
        "/api/frame" => match params::frame(query, &b, &|f| viewer.files[f].info.max_terms) {
            Ok(p) => frame(viewer, &p),
            Err(e) => bad(e),
        },
        "/api/exact" => match params::frame(query, &b, &|f| viewer.files[f].info.max_terms) {
            Ok(p) => exact(viewer, &p),
            Err(e) => bad(e),
        },
        "/api/surface" => match params::parse_query(query, &["file"])
            .and_then(|q| params::index(&q, "file", b.files))
        {
            Ok(f) => surface(viewer, f),
            Err(e) => bad(e),
        },
        _ => text(404, "not found"),
    }
}

fn no_query(q: &str) -> Result<(), BadRequest> {
    params::parse_query(q, &[]).map(|_| ())
}

fn info(viewer: &Viewer) -> Reply {
    let v = serde_json::json!({
        "files": viewer.files.iter().map(|f| &f.info).collect::<Vec<_>>(),
        "maps": viewer.maps().collect::<Vec<_>>(),
        "reference": viewer.reference_name(),
        "weightings": ["unweighted", "transport", "area"],
        "max_angle": params::MAX_ANGLE,
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
        FrameError::Stale => text(204, "").with_header(header("X-Stale", "1")),
        FrameError::Busy => text(503, "busy: every frame slot is taken; try again"),
        FrameError::Bad(m) => text(400, &m),
        FrameError::Internal(m) => text(500, &m),
    }
}

fn ms(d: std::time::Duration) -> String {
    format!("{:.3}", d.as_secs_f64() * 1e3)
}

fn frame_reply(f: &FrameOut, image: &Image) -> Reply {
    let mut r = body(encode_frame(image), "application/octet-stream")
        .with_header(header("X-Frame-Ms", &ms(f.frame_time)))
        .with_header(header("X-Resample-Ms", &ms(f.resample_time)))
        .with_header(header("X-Lights", &f.stats.lights.to_string()))
        .with_header(header("X-Nonzeros", &f.stats.nonzeros.to_string()));
    if let Some(e) = f.error {
        r = r.with_header(header("X-Error", &format!("{e:.9}")));
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
    let p = FrameParams {
        client: None,
        ..p.clone()
    };
    match viewer.frame(&p) {
        Ok(f) => frame_reply(&f, &exact).with_header(header("X-Exact-Ms", &ms(took))),
        Err(e) => frame_error(e),
    }
}

/// A texture-space file's geometry image: header (magic, side, side, 2),
/// then x, y, z as little-endian f32 per texel, then one valid byte per
/// texel. An image-space file gets 400.
fn surface(viewer: &Viewer, f: usize) -> Reply {
    let Some(s) = &viewer.files[f].surface else {
        return text(
            400,
            &format!("file {f} is an image-space file; it has no surface"),
        );
    };
    let side = viewer.files[f].info.width as u32;
    let mut out = Vec::with_capacity(16 + s.len() * 13);
    out.extend_from_slice(SURFACE_MAGIC);
    for v in [side, side, 2] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for (p, _) in s {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    out.extend(s.iter().map(|(_, v)| u8::from(*v)));
    body(out, "application/octet-stream")
}
