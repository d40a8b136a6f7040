//! Shared by the `ltm view` tests: a tiny baked and compressed scene, the
//! server as a child process, and a plain HTTP/1.1 client over a socket
//! (so that tests can also send malformed requests).

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

pub fn ltm(args: &[&str]) -> String {
    ltm_testkit::run_ok(env!("CARGO_BIN_EXE_ltm"), args)
}

pub fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets")
}

pub fn map(name: &str) -> PathBuf {
    assets().join("envmaps").join(name)
}

/// A baked (24×20 pixels, 6·4² lights) and compressed scene, made once per
/// test binary.
pub struct Scene {
    _dir: tempfile::TempDir,
    pub dir: PathBuf,
    pub raw: PathBuf,
    pub ltm: PathBuf,
    pub ltm2: PathBuf,
}

pub fn scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path();
        let (raw, ltm_path, ltm2) = (p.join("t.raw"), p.join("t.ltm"), p.join("t2d.ltm"));
        let scene = assets().join("scenes/default.toml");
        let s = |p: &Path| p.to_str().unwrap().to_string();
        ltm(&[
            "bake",
            &s(&scene),
            "-o",
            &s(&raw),
            "--width",
            "24",
            "--height",
            "20",
            "--face-res",
            "4",
            "--texel-samples",
            "1",
        ]);
        ltm(&[
            "compress",
            &s(&raw),
            "-o",
            &s(&ltm_path),
            "--max-error",
            "0.05",
        ]);
        ltm(&[
            "compress",
            &s(&raw),
            "-o",
            &s(&ltm2),
            "--mode",
            "2d",
            "--max-error",
            "0.05",
        ]);
        Scene {
            dir: p.to_path_buf(),
            _dir: dir,
            raw,
            ltm: ltm_path,
            ltm2,
        }
    })
}

/// `ltm view` running as a child process; killed when dropped.
pub struct Server {
    child: Child,
    pub addr: String,
}

impl Server {
    /// Starts `ltm view ARGS --port 0` in an empty folder (so that no
    /// asset maps are added) and reads the URL it prints.
    pub fn start(args: &[&str]) -> Server {
        let cwd = &scene().dir;
        // Measurements run a release binary: LTM_VIEW_BIN.
        let bin = std::env::var_os("LTM_VIEW_BIN")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_ltm")));
        let mut child = Command::new(bin)
            .arg("view")
            .args(args)
            .args(["--port", "0"])
            .current_dir(cwd)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start ltm view");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .expect("read the URL");
        let addr = line
            .trim()
            .strip_prefix("http://")
            .and_then(|s| s.strip_suffix('/'))
            .unwrap_or_else(|| panic!("ltm view printed {line:?}, not a URL"))
            .to_string();
        Server { child, addr }
    }

    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Sends raw bytes and reads the whole answer.
    pub fn raw(&self, request: &[u8]) -> Vec<u8> {
        let mut s = TcpStream::connect(&self.addr).expect("connect");
        s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        let _ = s.write_all(request);
        // End of request: a server waiting for more bytes sees end of file.
        let _ = s.shutdown(std::net::Shutdown::Write);
        let mut out = Vec::new();
        let _ = s.read_to_end(&mut out);
        out
    }

    /// A GET: status, headers (lower-case names) and body.
    pub fn get(&self, target: &str) -> Response {
        let req = format!("GET {target} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
        Response::parse(&self.raw(req.as_bytes()))
    }

    /// The server's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    pub fn is_alive(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub struct Response {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Response {
    fn parse(bytes: &[u8]) -> Response {
        let split = bytes
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .unwrap_or_else(|| panic!("no header end in {:?}", String::from_utf8_lossy(bytes)));
        let head = String::from_utf8_lossy(&bytes[..split]);
        let mut lines = head.split("\r\n");
        let status = lines
            .next()
            .unwrap()
            .split(' ')
            .nth(1)
            .unwrap()
            .parse()
            .unwrap();
        let headers: Vec<(String, String)> = lines
            .filter_map(|l| l.split_once(':'))
            .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
            .collect();
        let mut body = bytes[split + 4..].to_vec();
        if headers
            .iter()
            .any(|(k, v)| k == "transfer-encoding" && v.contains("chunked"))
        {
            body = dechunk(&body);
        }
        Response {
            status,
            headers,
            body,
        }
    }

    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    /// Decodes a binary frame: width, height, RGB values.
    pub fn frame(&self) -> (usize, usize, Vec<f32>) {
        let b = &self.body;
        assert_eq!(&b[..4], b"LTMF", "{}", self.text());
        let u = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as usize;
        let (w, h) = (u(4), u(8));
        assert_eq!(u(12), 1);
        assert_eq!(b.len(), 16 + w * h * 6);
        let v = b[16..]
            .chunks_exact(2)
            .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect();
        (w, h, v)
    }
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let Some(eol) = b.windows(2).position(|w| w == b"\r\n") else {
            return out;
        };
        let size_str = String::from_utf8_lossy(&b[..eol]);
        let size = usize::from_str_radix(size_str.split(';').next().unwrap().trim(), 16).unwrap();
        if size == 0 {
            return out;
        }
        out.extend_from_slice(&b[eol + 2..eol + 2 + size]);
        b = &b[eol + 2 + size + 2..];
    }
}

/// `ltm relight` at the given settings: the image's RGB values and the
/// JSON line it printed.
pub fn relight(
    file: &Path,
    map: &Path,
    rotate: &str,
    terms: usize,
    weighting: &str,
    reference: Option<&Path>,
) -> (Vec<f32>, serde_json::Value) {
    let out = scene().dir.join(format!(
        "relit-{:x}.exr",
        rand_suffix(&[
            file.to_str().unwrap(),
            map.to_str().unwrap(),
            rotate,
            weighting,
            &terms.to_string()
        ])
    ));
    let mut args = vec![
        "relight".to_string(),
        file.to_str().unwrap().into(),
        "--env".into(),
        map.to_str().unwrap().into(),
        format!("--rotate={rotate}"),
        "--terms".into(),
        terms.to_string(),
        "--weighting".into(),
        weighting.into(),
        "-o".into(),
        out.to_str().unwrap().into(),
        "--json".into(),
    ];
    if let Some(r) = reference {
        args.extend(["--reference".into(), r.to_str().unwrap().into()]);
    }
    let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let json: serde_json::Value = serde_json::from_str(ltm(&args).trim()).unwrap();
    let img = ltm_relight::Image::read_exr(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    (img.data.iter().flatten().copied().collect(), json)
}

/// `ltm reference` at the given map and rotation: the exact image's path.
pub fn reference(map: &Path, rotate: &str) -> PathBuf {
    let s = scene();
    let out = s.dir.join(format!(
        "exact-{:x}.exr",
        rand_suffix(&[map.to_str().unwrap(), rotate])
    ));
    ltm(&[
        "reference",
        s.raw.to_str().unwrap(),
        "--env",
        map.to_str().unwrap(),
        &format!("--rotate={rotate}"),
        "-o",
        out.to_str().unwrap(),
    ]);
    out
}

/// A name suffix from settings (distinct settings, distinct files).
fn rand_suffix(parts: &[&str]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    parts.hash(&mut h);
    std::thread::current().id().hash(&mut h);
    h.finish()
}

/// Largest difference of a half float from the f32 value it encodes:
/// half an ulp of f16 (relative 2^-11), or the subnormal step.
pub fn f16_tolerance(v: f32) -> f32 {
    v.abs() * 2f32.powi(-11) + 2f32.powi(-25)
}

/// Relative L2 distance of two frames' values, `‖a − b‖ / ‖b‖`.
pub fn frame_distance(a: &[f32], b: &[f32]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| f64::from(*y).powi(2)).sum();
    (num / den).sqrt()
}

/// The blob of `ltm_testkit::blob_obj` baked with `texture` (a
/// `[texture]` section) and compressed.
pub fn texture_file(dir: &Path, texture: &str) -> PathBuf {
    std::fs::write(dir.join("blob.obj"), ltm_testkit::blob_obj(6)).unwrap();
    let toml = dir.join("tex.toml");
    std::fs::write(
        &toml,
        ltm_testkit::scene_toml("blob.obj", 8, 8, 2) + texture,
    )
    .unwrap();
    let (raw, tex) = (dir.join("tex.raw"), dir.join("tex.ltm"));
    let p = |p: &Path| p.to_str().unwrap().to_string();
    ltm(&[
        "bake",
        &p(&toml),
        "-o",
        &p(&raw),
        "--face-res",
        "2",
        "--texel-samples",
        "1",
    ]);
    ltm(&["compress", &p(&raw), "-o", &p(&tex), "--max-error", "0.05"]);
    tex
}
