//! `ltm view`'s server under hostile clients, against the binary: idle and
//! half-open connections, a huge header, a slow-loris client, a flood of
//! frames and more connections than it serves do not starve a normal
//! request, which is answered within [`LIVENESS`] afterwards (and the
//! server is still alive). Also: the URL printed for `--bind`, and a
//! closed standard output.
//!
//! The times here are bounds for liveness, not performance figures.

use crate::view_support;

use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use view_support::*;

/// A normal request after (or during) an attack is answered within this.
const LIVENESS: Duration = Duration::from_secs(1);

/// The server's header timeout (`HEADER_TIMEOUT` in tools/src/view/server.rs).
const HEADER_TIMEOUT: Duration = Duration::from_secs(5);

fn args() -> Vec<String> {
    let s = scene();
    vec![
        s.ltm.to_str().unwrap().to_string(),
        "--env".into(),
        map("interior.exr").to_str().unwrap().to_string(),
    ]
}

fn start() -> Server {
    let a = args();
    Server::start(&a.iter().map(String::as_str).collect::<Vec<_>>())
}

/// `GET target` on a new connection, with a `Host` header, read until the
/// server closes: the status line and the whole answer, within `limit`.
fn get_within(addr: &str, host: &str, target: &str, limit: Duration) -> (u16, String) {
    let t = Instant::now();
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(limit)).unwrap();
    s.set_write_timeout(Some(limit)).unwrap();
    write!(
        s,
        "GET {target} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .expect("send the request");
    let mut out = Vec::new();
    let read = s.read_to_end(&mut out);
    let took = t.elapsed();
    let text = String::from_utf8_lossy(&out).into_owned();
    assert!(
        read.is_ok() && took <= limit,
        "GET {target} took {took:?} (bound {limit:?}): {read:?}, {text:?}"
    );
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("GET {target}: no status in {text:?}"));
    (status, text)
}

/// The page, answered within [`LIVENESS`], and the server still alive.
fn assert_answering(srv: &mut Server) {
    let (status, text) = get_within(&srv.addr, "localhost", "/", LIVENESS);
    assert_eq!(status, 200, "{text}");
    assert!(text.contains("/view.js"));
    assert!(srv.is_alive(), "the server died");
}

/// Raises this process's soft open-file limit to the hard one (children
/// inherit it) and returns it.
fn raise_nofile() -> u64 {
    use rustix::process::{getrlimit, setrlimit, Resource, Rlimit};
    let now = getrlimit(Resource::Nofile);
    let hard = now.maximum.unwrap_or(1 << 20).min(1 << 20);
    let _ = setrlimit(
        Resource::Nofile,
        Rlimit {
            current: Some(hard),
            maximum: now.maximum,
        },
    );
    getrlimit(Resource::Nofile).current.unwrap_or(hard)
}

/// The server's peak resident memory (VmHWM), in bytes.
fn peak_rss(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .expect("VmHWM in /proc/PID/status");
    let kib: u64 = line
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap();
    kib * 1024
}

#[test]
fn thousands_of_half_open_connections_do_not_starve_a_request() {
    let soft = raise_nofile();
    // Ours and the server's (which serves at most 4096): keep a margin.
    let count = 2000.min(soft.saturating_sub(300) as usize);
    if count < 2000 {
        println!("open-file limit {soft}: holding {count} connections, not 2000");
    }
    let mut srv = start();
    let held: Vec<TcpStream> = (0..count)
        .map(|i| TcpStream::connect(&srv.addr).unwrap_or_else(|e| panic!("connection {i}: {e}")))
        .collect();
    assert_answering(&mut srv);
    // They are still open (the header timeout has not run out): the
    // server took them all and still answers.
    let (status, _) = get_within(&srv.addr, "localhost", "/api/info", LIVENESS);
    assert_eq!(status, 200);
    drop(held);
    assert_answering(&mut srv);
}

#[test]
fn a_256_mib_header_is_cut_off() {
    let mut srv = start();
    let before = peak_rss(srv.pid());
    let mut s = TcpStream::connect(&srv.addr).unwrap();
    s.set_write_timeout(Some(Duration::from_secs(10))).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(b"GET / HTTP/1.1\r\nHost: localhost\r\nX-Big: ")
        .unwrap();
    let chunk = vec![b'a'; 1 << 20];
    let mut sent = 0usize;
    let cut = loop {
        if sent >= 256 << 20 {
            break None;
        }
        match s.write(&chunk) {
            Ok(n) => sent += n,
            Err(e) => break Some(e),
        }
    };
    let e = cut.expect("the server read a 256 MiB header");
    assert_ne!(
        e.kind(),
        ErrorKind::WouldBlock,
        "the server stopped reading without closing"
    );
    assert_ne!(
        e.kind(),
        ErrorKind::TimedOut,
        "the server stopped reading without closing"
    );
    let mut answer = Vec::new();
    let _ = s.read_to_end(&mut answer);
    let answer = String::from_utf8_lossy(&answer);
    assert!(
        answer.is_empty() || answer.starts_with("HTTP/1.1 431"),
        "{answer}"
    );
    let peak = peak_rss(srv.pid());
    println!("cut after {sent} bytes; peak RSS {before} before, {peak} after");
    assert!(peak < 200 << 20, "peak RSS {peak} bytes");
    assert!(
        peak < before + (64 << 20),
        "peak RSS {before} -> {peak} bytes"
    );
    assert_answering(&mut srv);
}

#[test]
fn a_slow_loris_is_dropped_and_others_are_served_meanwhile() {
    let mut srv = start();
    let mut s = TcpStream::connect(&srv.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let start = Instant::now();
    let head = b"GET / HTTP/1.1\r\nHost: localhost\r\nX-Slow: ";
    let mut next_check = Instant::now();
    let mut i = 0usize;
    let dropped_after = loop {
        let byte = head.get(i).copied().unwrap_or(b'a');
        i += 1;
        let mut buf = [0u8; 256];
        let closed = s.write_all(&[byte]).is_err()
            || match s.read(&mut buf) {
                Ok(_) => true,
                Err(e) => !matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut),
            };
        if closed {
            break start.elapsed();
        }
        assert!(
            start.elapsed() < HEADER_TIMEOUT * 3,
            "a client sending one header byte per 100 ms was kept {:?}",
            start.elapsed()
        );
        if Instant::now() >= next_check {
            assert_answering(&mut srv);
            next_check = Instant::now() + Duration::from_secs(1);
        }
    };
    println!("slow loris dropped after {dropped_after:?}");
    assert!(dropped_after >= HEADER_TIMEOUT / 2, "{dropped_after:?}");
    assert_answering(&mut srv);
}

#[test]
fn a_flood_of_frames_is_shed_and_nothing_hangs() {
    let s = scene();
    let mut srv = Server::start(&[
        s.ltm.to_str().unwrap(),
        "--env",
        map("interior.exr").to_str().unwrap(),
        "--slots",
        "1",
    ]);
    let statuses: Vec<u16> = std::thread::scope(|sc| {
        let handles: Vec<_> = (0..16)
            .map(|t| {
                let addr = &srv.addr;
                sc.spawn(move || {
                    (0..8)
                        .map(|i| {
                            let q = format!("/api/frame?file=0&map=0&yaw={}&n=96", t * 8 + i);
                            get_within(addr, "localhost", &q, Duration::from_secs(60)).0
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    let ok = statuses.iter().filter(|&&c| c == 200).count();
    let busy = statuses.iter().filter(|&&c| c == 503).count();
    println!("{ok} frames, {busy} refused (503) of {}", statuses.len());
    assert_eq!(ok + busy, statuses.len(), "{statuses:?}");
    assert!(ok > 0);
    assert_answering(&mut srv);
    let (status, _) = get_within(
        &srv.addr,
        "localhost",
        "/api/frame?file=0&map=0&n=4",
        LIVENESS,
    );
    assert_eq!(status, 200);
}

/// Starts `ltm view` through `sh -c SCRIPT` (SCRIPT ends in `exec "$0" "$@"`)
/// with stdout and stderr piped; killed when dropped.
struct Raw(Child);

impl Raw {
    fn start(script: &str, extra: &[&str], stdout: Stdio) -> Raw {
        let child = Command::new("sh")
            .arg("-c")
            .arg(script)
            .arg(env!("CARGO_BIN_EXE_ltm"))
            .arg("view")
            .args(args())
            .args(extra)
            .args(["--port", "0"])
            .current_dir(&scene().dir)
            .stdout(stdout)
            .stderr(Stdio::piped())
            .spawn()
            .expect("start ltm view");
        Raw(child)
    }

    /// Standard error's lines up to and including the one naming the URL
    /// (`ltm view: http://…/ …`), and that URL's address.
    fn stderr_url(&mut self) -> (Vec<String>, String) {
        let mut err = BufReader::new(self.0.stderr.take().unwrap());
        let mut lines = Vec::new();
        loop {
            let mut line = String::new();
            if err.read_line(&mut line).unwrap() == 0 {
                panic!("ltm view ended: {lines:?}");
            }
            lines.push(line.trim_end().to_string());
            if let Some(rest) = line.strip_prefix("ltm view: http://") {
                let addr = rest.split('/').next().unwrap().to_string();
                // The rest of standard error: the Host check and limits.
                for _ in 0..2 {
                    let mut l = String::new();
                    let _ = err.read_line(&mut l);
                    lines.push(l.trim_end().to_string());
                }
                // Keep standard error drained so that the server never blocks on it.
                std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()));
                return (lines, addr);
            }
        }
    }

    fn alive(&mut self) -> bool {
        self.0.try_wait().unwrap().is_none()
    }
}

impl Drop for Raw {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

const EXEC: &str = "exec \"$0\" \"$@\"";

#[test]
fn connections_beyond_the_limit_get_503_and_the_server_recovers() {
    // 300 file descriptors: the server takes 150 connections (half of them).
    let mut srv = Raw::start(&format!("ulimit -n 300; {EXEC}"), &[], Stdio::null());
    let (lines, addr) = srv.stderr_url();
    let limit_line = lines.last().unwrap();
    assert!(limit_line.contains("150 connections"), "{lines:?}");
    let held: Vec<TcpStream> = (0..150)
        .map(|_| TcpStream::connect(&addr).unwrap())
        .collect();
    // Wait until the server has taken them all: then the next is refused.
    let deadline = Instant::now() + Duration::from_secs(5);
    let refused = loop {
        let (status, text) = get_within(&addr, "localhost", "/", LIVENESS);
        if status == 503 {
            break text;
        }
        assert!(Instant::now() < deadline, "never refused: {text}");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(
        refused.ends_with("\r\n\r\nbusy: too many connections; try again\n"),
        "{refused}"
    );
    drop(held);
    // Closed connections free their places at once.
    let deadline = Instant::now() + LIVENESS;
    loop {
        let (status, text) = get_within(&addr, "localhost", "/", LIVENESS);
        if status == 200 {
            break;
        }
        assert!(Instant::now() < deadline, "still refused: {text}");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(srv.alive());
}

#[test]
fn bind_to_another_loopback_address_prints_a_url_that_works() {
    let mut srv = Raw::start(EXEC, &["--bind", "127.0.0.2"], Stdio::piped());
    let mut url = String::new();
    BufReader::new(srv.0.stdout.take().unwrap())
        .read_line(&mut url)
        .unwrap();
    let (lines, addr) = srv.stderr_url();
    assert_eq!(url.trim(), format!("http://{addr}/"), "{lines:?}");
    assert!(addr.starts_with("127.0.0.2:"), "{addr}");
    let check = &lines[lines.len() - 2];
    assert!(
        check.contains("Host is localhost, 127.0.0.1, [::1], 127.0.0.2 (any port)"),
        "{lines:?}"
    );
    // What a browser sends for that URL, and the other local names.
    for host in [addr.as_str(), "127.0.0.2", "localhost:1", "127.0.0.1"] {
        let (status, text) = get_within(&addr, host, "/api/info", LIVENESS);
        assert_eq!(status, 200, "Host {host}: {text}");
    }
    let (status, _) = get_within(&addr, "evil.example", "/api/info", LIVENESS);
    assert_eq!(status, 403);
    assert!(srv.alive());
}

#[test]
fn a_closed_standard_output_does_not_stop_the_server() {
    // `ltm view … | true`: standard output is a pipe whose reader is gone.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let mut srv = Raw::start(EXEC, &[], Stdio::from(writer));
    let (_, addr) = srv.stderr_url();
    let (status, _) = get_within(&addr, "localhost", "/", LIVENESS);
    assert_eq!(status, 200);
    assert!(
        srv.alive(),
        "ltm view ended when its standard output was closed"
    );
}
