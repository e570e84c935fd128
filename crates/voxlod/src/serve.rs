//! `voxlod serve FILE`: a local HTTP server for the browser viewer (`web/`, embedded in the
//! binary) and one octree file, which the viewer reads by range requests (RFC 9110 section
//! 14: one range per request, 206 Partial Content, 416 for an unsatisfiable range). Nothing
//! else is served. `/` redirects to the viewer on FILE, keeping the URL's parameters;
//! `/.voxlod/stats` says how many bytes of FILE were sent (the browser test reads it).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use http_range_header::{parse_range_header, RangeUnsatisfiableError};
use tiny_http::{Header, Method, Request, Response, Server, StatusCode};
use voxlod_format::Reader;

#[derive(Args)]
pub struct ServeArgs {
    /// The octree file to serve.
    file: PathBuf,
    /// TCP port; 0 picks a free one (the URL printed says which).
    #[arg(long, default_value_t = 8000)]
    port: u16,
    /// Address to listen on: 127.0.0.1 (this machine only) by default; 0.0.0.0 for every
    /// interface (anyone who can reach the machine can then read the file).
    #[arg(long, default_value = "127.0.0.1")]
    bind: String,
}

pub const EXAMPLES: &str = "Examples:
  voxlod serve dragon.voxlod
      then open the URL it prints; orbit with the left button, pan with the right (or
      shift), zoom with the wheel
  voxlod serve dragon.voxlod --port 9000 --bind 0.0.0.0
      reachable from other machines
  http://127.0.0.1:8000/?view=1,0.2,0.3&zoom=4&error=2
      the viewer takes render's camera: view, up, fov, zoom, target, size, error (README,
      \"In a browser\")";

/// The viewer's files (web/), served as they are in the repository.
const ASSETS: &[(&str, &str, &str)] = &[
    (
        "/index.html",
        "text/html; charset=utf-8",
        include_str!("../../../web/index.html"),
    ),
    ("/viewer.mjs", JS, include_str!("../../../web/viewer.mjs")),
    ("/camera.mjs", JS, include_str!("../../../web/camera.mjs")),
    (
        "/renderer.mjs",
        JS,
        include_str!("../../../web/renderer.mjs"),
    ),
    ("/worker.mjs", JS, include_str!("../../../web/worker.mjs")),
    (
        "/fetch-range.mjs",
        JS,
        include_str!("../../../web/fetch-range.mjs"),
    ),
    (
        "/voxlod-reader.mjs",
        JS,
        include_str!("../../../web/voxlod-reader.mjs"),
    ),
    (
        "/vendor/fzstd.mjs",
        JS,
        include_str!("../../../web/vendor/fzstd.mjs"),
    ),
    (
        "/vendor/fzstd.LICENSE",
        "text/plain; charset=utf-8",
        include_str!("../../../web/vendor/fzstd.LICENSE"),
    ),
];
const JS: &str = "text/javascript; charset=utf-8";

/// Bytes of the file sent and requests for it.
#[derive(Default)]
struct Stats {
    bytes: AtomicU64,
    requests: AtomicU64,
}

struct Served {
    path: PathBuf,
    /// URL path of the file: `/` and its file name, if that name needs no escaping.
    url_path: String,
    size: u64,
    stats: Stats,
}

/// The file's URL path: its name where every character is safe in a URL path, else a fixed one.
fn url_path(file: &std::path::Path) -> String {
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned());
    match name {
        Some(n)
            if !n.is_empty()
                && !n.starts_with('.')
                && n.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b)) =>
        {
            format!("/{n}")
        }
        _ => "/octree.voxlod".into(),
    }
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("a valid header")
}

pub fn run(a: ServeArgs) -> Result<()> {
    // only a file voxlod reads is served
    let reader = Reader::open(&a.file)?;
    drop(reader);
    let size = std::fs::metadata(&a.file)
        .with_context(|| format!("{}", a.file.display()))?
        .len();
    let addr = format!("{}:{}", a.bind, a.port);
    let server = Server::http(&addr).map_err(|e| {
        anyhow::anyhow!(
            "cannot listen on {addr}: {e} (another --port, or --port 0 for any free one)"
        )
    })?;
    let port = server
        .server_addr()
        .to_ip()
        .map(|s| s.port())
        .context("the server has no IP address")?;
    let served = Arc::new(Served {
        path: a.file.canonicalize()?,
        url_path: url_path(&a.file),
        size,
        stats: Stats::default(),
    });
    let host = if a.bind == "0.0.0.0" {
        "127.0.0.1"
    } else {
        &a.bind
    };
    println!(
        "serving {} ({}) and the viewer at http://{host}:{port}/ (open it in a browser; Ctrl-C stops)",
        a.file.display(),
        voxlod_pipeline::format_size(size)
    );
    let server = Arc::new(server);
    let threads: Vec<_> = (0..4)
        .map(|_| {
            let server = Arc::clone(&server);
            let served = Arc::clone(&served);
            std::thread::spawn(move || {
                for req in server.incoming_requests() {
                    // a client that goes away mid-answer is not the server's error
                    let _ = answer(&served, req);
                }
            })
        })
        .collect();
    for t in threads {
        if t.join().is_err() {
            bail!("a server thread panicked");
        }
    }
    Ok(())
}

/// Answers one request.
fn answer(s: &Served, req: Request) -> std::io::Result<()> {
    let cors = [
        header("Access-Control-Allow-Origin", "*"),
        header("Access-Control-Allow-Headers", "Range"),
        header(
            "Access-Control-Expose-Headers",
            "Content-Range, Content-Length, Accept-Ranges",
        ),
    ];
    let url = req.url().to_string();
    let (path, query) = url.split_once('?').unwrap_or((&url, ""));
    let head = *req.method() == Method::Head;
    if *req.method() == Method::Options {
        let mut r = Response::empty(204).with_header(header("Allow", "GET, HEAD, OPTIONS"));
        for h in cors {
            r.add_header(h);
        }
        return req.respond(r);
    }
    if !(head || *req.method() == Method::Get) {
        return req.respond(
            Response::from_string("voxlod serve answers GET and HEAD only\n")
                .with_status_code(405)
                .with_header(header("Allow", "GET, HEAD, OPTIONS")),
        );
    }
    if path == "/" {
        let file = &s.url_path[1..];
        let location = if query.is_empty() {
            format!("/index.html?file={file}")
        } else {
            format!("/index.html?file={file}&{query}")
        };
        return req.respond(Response::empty(302).with_header(header("Location", &location)));
    }
    if path == "/.voxlod/stats" {
        let body = serde_json::json!({
            "file": s.path,
            "url": s.url_path,
            "size": s.size,
            "bytes_sent": s.stats.bytes.load(Ordering::Relaxed),
            "requests": s.stats.requests.load(Ordering::Relaxed),
        })
        .to_string();
        return req.respond(
            Response::from_string(body)
                .with_header(header("Content-Type", "application/json"))
                .with_header(header("Cache-Control", "no-store")),
        );
    }
    if let Some((_, kind, body)) = ASSETS.iter().find(|(p, _, _)| *p == path) {
        // (tiny_http sends no body for HEAD)
        return req.respond(Response::from_string(*body).with_header(header("Content-Type", kind)));
    }
    if path != s.url_path {
        return req.respond(
            Response::from_string(format!(
                "not found: voxlod serve serves only the viewer and {}\n",
                s.url_path
            ))
            .with_status_code(404),
        );
    }
    s.stats.requests.fetch_add(1, Ordering::Relaxed);
    let range = req
        .headers()
        .iter()
        .find(|h| h.field.equiv("Range"))
        .map(|h| h.value.as_str().to_string());
    // RFC 9110 14.2: one satisfiable range → 206; unsatisfiable → 416; a header that does not
    // parse, or several ranges, may be ignored → the whole file (200)
    let part = match range.as_deref().map(parse_range_header) {
        None => None,
        Some(Ok(p)) => match p.validate(s.size) {
            Ok(r) if r.len() == 1 => Some(r[0].clone()),
            Ok(_) => None,
            Err(RangeUnsatisfiableError::Unsatisfiable) => {
                let mut r = Response::empty(416)
                    .with_header(header("Content-Range", &format!("bytes */{}", s.size)));
                for h in cors {
                    r.add_header(h);
                }
                return req.respond(r);
            }
            Err(_) => None,
        },
        Some(Err(RangeUnsatisfiableError::Unsatisfiable)) => {
            return req.respond(
                Response::empty(416)
                    .with_header(header("Content-Range", &format!("bytes */{}", s.size))),
            );
        }
        Some(Err(_)) => None,
    };
    let (start, len, status) = match &part {
        Some(r) => (*r.start(), r.end() - r.start() + 1, 206),
        None => (0, s.size, 200),
    };
    let mut file = File::open(&s.path)?;
    file.seek(SeekFrom::Start(start))?;
    if !head {
        s.stats.bytes.fetch_add(len, Ordering::Relaxed);
    }
    let mut headers = vec![
        header("Content-Type", "application/octet-stream"),
        header("Accept-Ranges", "bytes"),
        header("Cache-Control", "no-cache"),
    ];
    headers.extend(cors);
    if let Some(r) = &part {
        headers.push(header(
            "Content-Range",
            &format!("bytes {}-{}/{}", r.start(), r.end(), s.size),
        ));
    }
    // tiny_http sends no body for HEAD; with Content-Length, never chunked (tiny_http chunks
    // bodies above 32 KiB by default)
    let r = Response::new(
        StatusCode(status),
        headers,
        file.take(len),
        Some(len as usize),
        None,
    )
    .with_chunked_threshold(usize::MAX);
    req.respond(r)
}
