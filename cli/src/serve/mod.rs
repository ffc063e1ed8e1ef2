//! `unshear serve`: a local web page and the JSON API it uses (docs/serve.md).
//!
//! The models are loaded once, then an HTTP/1 server (axum on a current-thread tokio runtime)
//! answers on 127.0.0.1 unless `--bind` says otherwise. The page, its script and styles are
//! built into the binary ([`page`]); the API ([`api`]) decodes each upload in memory with the
//! CLI's limits, works on at most `--jobs` images at once on tokio's blocking pool, and answers
//! with the CLI's JSON report or the corrected image. Nothing is read from or written to disk.

mod api;
mod page;

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use anyhow::{Context, Result};
use unshear::Config;

use crate::args::ServeArgs;
use crate::models::load_models;

/// The port tried first when `--port` is not given.
const DEFAULT_PORT: u16 = 8080;

/// Runs the server until the process is stopped (Ctrl-C).
pub fn serve(a: ServeArgs) -> Result<()> {
    if !(a.wait.is_finite() && (0.0..=3600.0).contains(&a.wait)) {
        crate::usage_error("--wait must be a number of seconds from 0 to 3600");
    }
    let jobs = a.model.jobs.map(usize::from).unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let unshear = load_models(&a.model, Config::default())?;
    let server = api::Server {
        unshear,
        max_pixels: a.model.max_pixels,
        max_upload: a.max_upload,
        jobs,
        wait: Duration::from_secs_f64(a.wait),
        loopback: a.bind.is_loopback(),
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .build()
        .context("starting the server's runtime")?;
    runtime.block_on(async move {
        let listener = bind(a.bind, a.port).await?;
        let address = listener
            .local_addr()
            .context("reading the address listened on")?;
        if !a.bind.is_loopback() {
            eprintln!(
                "unshear: warning: listening on {}, not a loopback address: anyone who can reach \
                 it can send photos to this server",
                a.bind
            );
        }
        let url = format!("http://{address}/");
        crate::print_line(&format!("listening on {url}"));
        if a.open {
            open_browser(&url);
        }
        axum::serve(listener, api::router(server))
            .await
            .context("serving")
    })
}

/// The listener on `ip`: at `port`, or with none given at [`DEFAULT_PORT`] and at a free port
/// when that one is taken.
async fn bind(ip: IpAddr, port: Option<u16>) -> Result<tokio::net::TcpListener> {
    let at = |port| tokio::net::TcpListener::bind(SocketAddr::new(ip, port));
    match port {
        Some(port) => at(port)
            .await
            .with_context(|| format!("listening on {}", SocketAddr::new(ip, port))),
        None => match at(DEFAULT_PORT).await {
            Ok(listener) => Ok(listener),
            Err(_) => at(0)
                .await
                .with_context(|| format!("listening on {ip} (port {DEFAULT_PORT} is taken)")),
        },
    }
}

/// Opens `url` in the default browser; a failure is a warning (the URL is printed anyway).
fn open_browser(url: &str) {
    let mut command = if cfg!(target_os = "macos") {
        std::process::Command::new("open")
    } else if cfg!(target_os = "windows") {
        let mut c = std::process::Command::new("cmd");
        c.args(["/C", "start", ""]);
        c
    } else {
        std::process::Command::new("xdg-open")
    };
    let opened = command
        .arg(url)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn();
    match opened {
        // Reaped on a thread of its own (the opener usually returns at once).
        Ok(mut child) => drop(std::thread::spawn(move || child.wait())),
        Err(e) => eprintln!("unshear: warning: could not open a browser ({e}): open {url} by hand"),
    }
}
