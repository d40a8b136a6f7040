//! The HTTP server of `ltm view`: hyper (HTTP/1.1) on a small tokio
//! runtime that `run` starts and blocks on, with every resource a client
//! can hold bounded:
//!
//! - connections: at most [`Limits::connections`] at once (from the
//!   open-file limit, see [`connection_capacity`]); one beyond gets a
//!   one-line 503 and is closed;
//! - time: a connection has [`HEADER_TIMEOUT`] to send a request's head,
//!   also between requests (so half-open, idle and slow-loris connections
//!   close then); a write that makes no progress for [`WRITE_STALL`] ends
//!   the connection;
//! - memory: a request head (request line and headers) of more than
//!   [`MAX_HEAD`] bytes gets 431 and the connection is closed, so a client
//!   costs at most that buffer;
//! - work: frames and exact images run on a blocking pool of at most
//!   [`Limits::jobs`] threads (`--slots` + [`JOB_QUEUE`]); a frame request
//!   beyond them gets 503 at once (load shedding), never a place in an
//!   unbounded queue, and one beyond the `Viewer`'s slots gets 503 there;
//! - failures: an `accept` that fails (out of file descriptors or memory)
//!   is reported once per run of failures and retried after
//!   [`ACCEPT_PAUSE`]; nothing here panics on I/O, and a panic while
//!   answering becomes a 500.

use super::http::{self, HostCheck, Reply, Routed};
use super::state::Viewer;
use anyhow::{Context, Result};
use hyper::body::Incoming;
use hyper::server::conn::http1;
use hyper::service::service_fn;
use hyper::Request;
use hyper_util::rt::{TokioIo, TokioTimer};
use std::convert::Infallible;
use std::future::Future;
use std::io;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context as TaskContext, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;
use tokio::time::Sleep;

/// Time a connection has to send a request's head (request line and
/// headers), counted from when the server starts waiting for it: after the
/// connection opens and after each answer (keep-alive idle time).
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);
/// Longest time a write to a client may make no progress.
pub const WRITE_STALL: Duration = Duration::from_secs(10);
/// Largest request head, in bytes (also the most a connection buffers).
pub const MAX_HEAD: usize = 32 * 1024;
/// Most connections served at once, whatever the open-file limit.
pub const MAX_CONNECTIONS: usize = 4096;
/// File descriptors kept for everything but connections (files, maps,
/// threads, the listener, refusals).
pub const FD_RESERVE: u64 = 256;
/// Frame requests handled at once beyond the frame slots (they are
/// answered 204 or 503 by the `Viewer` without waiting).
pub const JOB_QUEUE: usize = 4;
/// Pause after a failed `accept` (out of file descriptors or memory).
pub const ACCEPT_PAUSE: Duration = Duration::from_millis(100);
/// Refusals (503, connection limit) written at once; more are just closed.
const REFUSALS: usize = 64;
/// How long a refusal may take (writing the 503, reading what was sent).
const REFUSAL_TIME: Duration = Duration::from_secs(1);
/// I/O threads of the runtime (frames run on the blocking pool).
const IO_THREADS: usize = 2;

/// What the server bounds.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Connections served at once.
    pub connections: usize,
    /// Frame and exact-image requests at once (running or queued).
    pub jobs: usize,
}

/// The answer to a connection beyond the limit.
const REFUSAL: &[u8] = b"HTTP/1.1 503 Service Unavailable\r\n\
Content-Type: text/plain; charset=utf-8\r\nContent-Length: 38\r\nConnection: close\r\n\r\n\
busy: too many connections; try again\n";

/// Raises the soft open-file limit toward the hard one (as far as the
/// connections need) and returns the connection capacity: the soft limit
/// less [`FD_RESERVE`] (at least half of it), at most [`MAX_CONNECTIONS`].
#[cfg(unix)]
pub fn connection_capacity() -> usize {
    use rustix::process::{getrlimit, setrlimit, Resource, Rlimit};
    let want = MAX_CONNECTIONS as u64 + FD_RESERVE;
    let now = getrlimit(Resource::Nofile);
    let mut soft = now.current.unwrap_or(u64::MAX);
    if soft < want {
        let target = now.maximum.map_or(want, |h| h.min(want));
        if target > soft
            && setrlimit(
                Resource::Nofile,
                Rlimit {
                    current: Some(target),
                    maximum: now.maximum,
                },
            )
            .is_ok()
        {
            soft = target;
        }
    }
    let cap = soft.saturating_sub(FD_RESERVE).max(soft / 2);
    (cap.min(MAX_CONNECTIONS as u64) as usize).max(1)
}

/// The connection capacity where there is no open-file limit to read.
#[cfg(not(unix))]
pub fn connection_capacity() -> usize {
    MAX_CONNECTIONS
}

/// What every connection shares.
struct Shared {
    viewer: Arc<Viewer>,
    hosts: HostCheck,
    jobs: Arc<Semaphore>,
}

/// Serves on `listener` until the process ends (errors only when the
/// runtime cannot start).
pub fn serve(
    listener: std::net::TcpListener,
    viewer: Arc<Viewer>,
    hosts: HostCheck,
    limits: Limits,
) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(IO_THREADS)
        .max_blocking_threads(limits.jobs + 1)
        .thread_name("view-io")
        .enable_io()
        .enable_time()
        .build()
        .context("starting the server's threads")?;
    listener
        .set_nonblocking(true)
        .context("setting up the listening socket")?;
    let shared = Arc::new(Shared {
        viewer,
        hosts,
        jobs: Arc::new(Semaphore::new(limits.jobs)),
    });
    runtime.block_on(async move {
        let listener =
            TcpListener::from_std(listener).context("setting up the listening socket")?;
        accept_loop(listener, shared, limits.connections).await;
        Ok(())
    })
}

/// Whether an `accept` error concerns only the connection being accepted
/// (which is gone), not the server's resources.
fn connection_only(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::ConnectionAborted
            | io::ErrorKind::ConnectionReset
            | io::ErrorKind::Interrupted
            | io::ErrorKind::WouldBlock
    )
}

async fn accept_loop(listener: TcpListener, shared: Arc<Shared>, connections: usize) {
    let mut h1 = http1::Builder::new();
    h1.timer(TokioTimer::new())
        .header_read_timeout(HEADER_TIMEOUT)
        .max_buf_size(MAX_HEAD)
        // A client may shut its side down after sending its request and
        // still be answered.
        .half_close(true)
        .title_case_headers(true);
    let h1 = Arc::new(h1);
    let open = Arc::new(Semaphore::new(connections));
    let refusals = Arc::new(Semaphore::new(REFUSALS));
    let mut failing = false;
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => {
                failing = false;
                stream
            }
            Err(e) if connection_only(&e) => continue,
            Err(e) => {
                if !failing {
                    eprintln!("ltm view: cannot accept connections ({e}); retrying");
                    failing = true;
                }
                tokio::time::sleep(ACCEPT_PAUSE).await;
                continue;
            }
        };
        let Ok(permit) = open.clone().try_acquire_owned() else {
            refuse(stream, &refusals);
            continue;
        };
        let (h1, shared) = (h1.clone(), shared.clone());
        tokio::spawn(async move {
            let service = service_fn(move |req| {
                let shared = shared.clone();
                async move { Ok::<_, Infallible>(answer(req, &shared).await) }
            });
            let io = TokioIo::new(WriteStall::new(stream));
            // Errors (timeouts, bad requests, clients gone) end the
            // connection; hyper has answered what could be answered.
            let _ = h1.serve_connection(io, service).await;
            drop(permit);
        });
    }
}

/// Answers a connection beyond the limit with a 503 and closes it, within
/// [`REFUSAL_TIME`]; beyond [`REFUSALS`] refusals at once, just closes it.
fn refuse(stream: TcpStream, refusals: &Arc<Semaphore>) {
    let Ok(permit) = refusals.clone().try_acquire_owned() else {
        return;
    };
    tokio::spawn(async move {
        let mut stream = stream;
        let _ = tokio::time::timeout(REFUSAL_TIME, async {
            stream.write_all(REFUSAL).await?;
            stream.shutdown().await?;
            // Read what the client sent, so that closing does not reset
            // the connection before the client has read the answer.
            let mut buf = [0u8; 4096];
            let mut left = MAX_HEAD;
            while left > 0 {
                let n = stream.read(&mut buf).await?;
                if n == 0 {
                    break;
                }
                left = left.saturating_sub(n);
            }
            io::Result::Ok(())
        })
        .await;
        drop(permit);
    });
}

/// Answers one request: routing here, frames on the blocking pool.
async fn answer(req: Request<Incoming>, shared: &Arc<Shared>) -> Reply {
    let url = req.uri().to_string();
    let routed = catch_unwind(AssertUnwindSafe(|| {
        http::route(
            req.method(),
            &url,
            req.headers().get(hyper::header::HOST),
            &shared.viewer,
            &shared.hosts,
        )
    }));
    let job = match routed {
        Ok(Routed::Reply(r)) => return r,
        Ok(Routed::Job(job)) => job,
        Err(_) => return http::internal(),
    };
    let Ok(permit) = shared.jobs.clone().try_acquire_owned() else {
        return http::text(503, http::BUSY);
    };
    let viewer = shared.viewer.clone();
    // The permit goes with the job: a client that leaves does not free its
    // place until the frame ends.
    tokio::task::spawn_blocking(move || {
        let reply = catch_unwind(AssertUnwindSafe(|| job.run(&viewer)));
        drop(permit);
        reply.unwrap_or_else(|_| http::internal())
    })
    .await
    .unwrap_or_else(|_| http::internal())
}

/// A TCP stream whose writes fail with `TimedOut` after making no progress
/// for [`WRITE_STALL`] (a client that stops reading its answer).
struct WriteStall {
    io: TcpStream,
    stall: Option<Pin<Box<Sleep>>>,
}

impl WriteStall {
    fn new(io: TcpStream) -> WriteStall {
        WriteStall { io, stall: None }
    }

    /// Passes a write's result on, starting the stall clock while it is
    /// pending and failing once the clock runs out.
    fn watch<T>(
        &mut self,
        cx: &mut TaskContext<'_>,
        r: Poll<io::Result<T>>,
    ) -> Poll<io::Result<T>> {
        if r.is_ready() {
            self.stall = None;
            return r;
        }
        let stall = self
            .stall
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(WRITE_STALL)));
        if stall.as_mut().poll(cx).is_ready() {
            self.stall = None;
            return Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "the client stopped reading",
            )));
        }
        Poll::Pending
    }
}

impl AsyncRead for WriteStall {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut TaskContext<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl AsyncWrite for WriteStall {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut TaskContext<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.io).poll_write(cx, buf);
        self.watch(cx, r)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut TaskContext<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.io).poll_write_vectored(cx, bufs);
        self.watch(cx, r)
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut TaskContext<'_>) -> Poll<io::Result<()>> {
        let r = Pin::new(&mut self.io).poll_flush(cx);
        self.watch(cx, r)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut TaskContext<'_>) -> Poll<io::Result<()>> {
        let r = Pin::new(&mut self.io).poll_shutdown(cx);
        self.watch(cx, r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusal_is_well_formed() {
        let text = std::str::from_utf8(REFUSAL).unwrap();
        let (head, body) = text.split_once("\r\n\r\n").unwrap();
        assert!(head.contains(&format!("Content-Length: {}", body.len())));
        assert_eq!(body, "busy: too many connections; try again\n");
    }

    #[test]
    fn capacity_is_bounded() {
        let c = connection_capacity();
        assert!((1..=MAX_CONNECTIONS).contains(&c), "{c}");
    }
}
