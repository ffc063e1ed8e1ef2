//! The routes of `unshear serve`: the page ([`super::page`]) and the JSON API it uses, each
//! endpoint described in docs/serve.md.
//!
//! Every upload is read into memory under `--max-upload` (413 past it, while reading), decoded
//! by the library's reader with the pixel limit checked before decoding, and worked on by one
//! of `--jobs` workers (a semaphore; a request that waits longer than `--wait` for one is
//! answered 503 with `Retry-After`). Failures are JSON: `{"error": {"code", "message"}}` with a
//! 4xx status for bad input. A name sent with an upload is only a label in the answer: nothing
//! is ever read from or written to a path.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::extract::{DefaultBodyLimit, FromRequest, Multipart, Query, Request, State};
use axum::http::{header, HeaderMap, HeaderName, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use image::DynamicImage;
use serde::{Deserialize, Serialize};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use unshear::imageio::{self, Metadata, WriteOptions};
use unshear::pipeline::Region;
use unshear::{CorrectOptions, ImageReport, Unshear};

use super::page;
use crate::args::{CanvasArg, InterpArg, RegionArg};
use crate::report::{r4, JsonLine};

/// The header that carries the shear a correction used (or an annotation found).
pub const K_HEADER: &str = "x-unshear-k";

/// What the server works with: the corrector and the limits.
pub struct Server {
    /// The corrector, models loaded.
    pub unshear: Unshear,
    /// `--max-pixels`: the decoded-size limit, checked before decoding.
    pub max_pixels: u64,
    /// `--max-upload`: the largest request body read, bytes.
    pub max_upload: u64,
    /// `--jobs`: images worked on at once.
    pub jobs: usize,
    /// `--wait`: how long a request waits for a worker before a 503.
    pub wait: Duration,
    /// Whether only this machine can connect (a loopback `--bind`): requests must then name
    /// a loopback host, so that a web site whose name is made to point at 127.0.0.1 (DNS
    /// rebinding) cannot use the server from a browser.
    pub loopback: bool,
}

/// The server and its workers, shared by the handlers.
struct Shared {
    server: Server,
    workers: Arc<Semaphore>,
}

type AppState = State<Arc<Shared>>;

/// The router: the page's files and the API.
pub fn router(server: Server) -> Router {
    let limit = usize::try_from(server.max_upload).unwrap_or(usize::MAX);
    let workers = Arc::new(Semaphore::new(server.jobs.max(1)));
    Router::new()
        .route("/", get(page::index))
        .route("/app.js", get(page::script))
        .route("/style.css", get(page::style))
        .route("/example.png", get(page::example))
        .route("/api/health", get(health))
        .route("/api/estimate", post(estimate))
        .route("/api/correct", post(correct))
        .route("/api/annotate", post(annotate))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(limit))
        .layer(axum::middleware::from_fn_with_state(
            server.loopback,
            check_host,
        ))
        .with_state(Arc::new(Shared { server, workers }))
}

/// Refuses (403) a request to a loopback server whose `Host` is not a loopback name.
async fn check_host(
    State(loopback): State<bool>,
    request: Request,
    next: axum::middleware::Next,
) -> Response {
    let host = request
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .unwrap_or_default();
    if loopback && !is_loopback_host(host) {
        return ApiError::new(
            StatusCode::FORBIDDEN,
            "forbidden_host",
            format!("Host {host}: this server answers only to localhost, 127.0.0.1 or [::1]"),
        )
        .into_response();
    }
    next.run(request).await
}

/// Whether `host` (a `Host` header: a name or address and maybe a port) names this machine.
fn is_loopback_host(host: &str) -> bool {
    let name = match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or_default(),
        None => host.rsplit_once(':').map_or(host, |(name, _)| name),
    };
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// A failed request: its status, a stable code and a message in words.
#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    code: &'static str,
    message: String,
}

impl ApiError {
    fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        Self {
            status,
            code,
            message: message.into(),
        }
    }

    fn bad_parameter(message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, "bad_parameter", message)
    }

    fn upload_too_large(limit: u64) -> Self {
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "upload_too_large",
            format!("the upload is larger than the server's limit of {limit} bytes (--max-upload)"),
        )
    }

    fn internal(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", message)
    }

    /// A library error about an upload: too many pixels (413) or unreadable (400).
    fn from_library(e: &unshear::Error) -> Self {
        let message = crate::one_line("<memory>", &e.to_string());
        match e {
            unshear::Error::TooLarge { .. } | unshear::Error::FileTooLarge { .. } => Self::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                "too_many_pixels",
                format!("{message} (--max-pixels)"),
            ),
            unshear::Error::Image { .. } | unshear::Error::Io { .. } => Self::new(
                StatusCode::BAD_REQUEST,
                "unreadable",
                format!("not a readable image (JPEG, PNG, PNM, BMP, TIFF or WebP): {message}"),
            ),
            unshear::Error::InvalidArgument(_) => Self::bad_parameter(message),
            _ => Self::internal(message),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::json!({"error": {"code": self.code, "message": self.message}});
        let mut response = (self.status, json_headers(), body.to_string()).into_response();
        if self.status == StatusCode::SERVICE_UNAVAILABLE {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("2"));
        }
        response
    }
}

fn json_headers() -> [(HeaderName, HeaderValue); 1] {
    [(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    )]
}

fn json_response(value: &impl Serialize) -> Response {
    match serde_json::to_string(value) {
        Ok(text) => (json_headers(), text).into_response(),
        Err(e) => ApiError::internal(e.to_string()).into_response(),
    }
}

async fn not_found() -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "not_found",
        "no such page or endpoint",
    )
}

async fn method_not_allowed() -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        "the API's endpoints take POST with the image as the body (GET for /api/health)",
    )
}

/// `GET /api/health`.
async fn health(State(shared): AppState) -> Response {
    let s = &shared.server;
    json_response(&serde_json::json!({
        "status": "ok",
        "version": env!("CARGO_PKG_VERSION"),
        "max_upload": s.max_upload,
        "max_pixels": s.max_pixels,
        "jobs": s.jobs,
        "busy": s.jobs.saturating_sub(shared.workers.available_permits()),
    }))
}

/// The query of every image endpoint (each uses the fields it needs; unknown ones are
/// refused, so a misspelt parameter is not silently ignored).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    /// A label for the upload (`file` in the report, the download's name).
    name: Option<String>,
    /// `estimate`: also the annotated picture and the description in words (the page).
    annotate: Option<bool>,
    /// `correct`: the shear to undo instead of the estimate.
    k: Option<String>,
    canvas: Option<String>,
    region: Option<String>,
    interp: Option<String>,
    /// `correct`: the output format (`jpeg`, `png`, ...) instead of the input's.
    format: Option<String>,
}

fn params(request: &Request) -> Result<Params, ApiError> {
    Query::<Params>::try_from_uri(request.uri())
        .map(|Query(p)| p)
        .map_err(|e| ApiError::bad_parameter(e.body_text()))
}

/// One of a clap value enum's names, case-insensitive.
fn choice<T: clap::ValueEnum>(what: &str, value: Option<&str>, default: T) -> Result<T, ApiError> {
    match value {
        None => Ok(default),
        Some(v) => T::from_str(v, true).map_err(|_| {
            let names: Vec<String> = T::value_variants()
                .iter()
                .filter_map(|x| x.to_possible_value().map(|p| p.get_name().to_string()))
                .collect();
            ApiError::bad_parameter(format!("{what}={v}: not one of {}", names.join(", ")))
        }),
    }
}

/// An upload: its bytes and the name it came with, if any.
struct Upload {
    name: Option<String>,
    bytes: Bytes,
}

/// Checks what can be checked before a worker is taken: the content type (415) and a declared
/// length over the limit (413).
fn check_request(request: &Request, max_upload: u64) -> Result<(), ApiError> {
    let length = request
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if length.is_some_and(|n| n > max_upload) {
        return Err(ApiError::upload_too_large(max_upload));
    }
    match mime(request.headers()).as_str() {
        "multipart/form-data" | "application/octet-stream" => Ok(()),
        m if m.starts_with("image/") => Ok(()),
        m => Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            format!(
                "Content-Type {m}: send the image's bytes as application/octet-stream or image/*, \
                 or as the field `file` of multipart/form-data"
            ),
        )),
    }
}

/// The request's media type, lower case without parameters; `application/octet-stream` when
/// none is given.
fn mime(headers: &HeaderMap) -> String {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .map(|v| v.trim().to_ascii_lowercase())
        .filter(|v| !v.is_empty())
        .unwrap_or_else(|| "application/octet-stream".to_string())
}

/// Reads the upload: the whole body, or the form's file field (`file`, or the first one with a
/// file name). The body limit ([`DefaultBodyLimit`]) applies while reading.
async fn read_upload(request: Request, max_upload: u64) -> Result<Upload, ApiError> {
    let body_error = |status: StatusCode, text: String| {
        if status == StatusCode::PAYLOAD_TOO_LARGE {
            ApiError::upload_too_large(max_upload)
        } else {
            ApiError::new(StatusCode::BAD_REQUEST, "bad_upload", text)
        }
    };
    let upload = if mime(request.headers()) == "multipart/form-data" {
        let mut form = Multipart::from_request(request, &())
            .await
            .map_err(|e| body_error(e.status(), e.body_text()))?;
        let mut found = None;
        while let Some(field) = form
            .next_field()
            .await
            .map_err(|e| body_error(e.status(), e.body_text()))?
        {
            if field.name() == Some("file") || field.file_name().is_some() {
                let name = field.file_name().map(str::to_string);
                let bytes = field
                    .bytes()
                    .await
                    .map_err(|e| body_error(e.status(), e.body_text()))?;
                found = Some(Upload { name, bytes });
                break;
            }
        }
        found.ok_or_else(|| {
            ApiError::new(
                StatusCode::BAD_REQUEST,
                "empty",
                "the form has no file: send the image as the field `file`",
            )
        })?
    } else {
        let bytes = Bytes::from_request(request, &())
            .await
            .map_err(|e| body_error(e.status(), e.body_text()))?;
        Upload { name: None, bytes }
    };
    if upload.bytes.is_empty() {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "empty",
            "the upload is empty: send the image's bytes",
        ));
    }
    Ok(upload)
}

/// The label of an upload: the last part of the name given (a path's folders dropped, control
/// characters removed, at most 200 characters), `upload` without one. Only ever printed.
fn label(name: Option<&str>) -> String {
    let last = name
        .unwrap_or_default()
        .rsplit(['/', '\\'])
        .next()
        .unwrap_or_default();
    let clean: String = last.chars().filter(|c| !c.is_control()).take(200).collect();
    if clean.trim().is_empty() {
        "upload".to_string()
    } else {
        clean
    }
}

impl Shared {
    /// Takes a worker, waiting at most `--wait`; 503 when none came free.
    async fn worker(&self) -> Result<OwnedSemaphorePermit, ApiError> {
        match tokio::time::timeout(self.server.wait, self.workers.clone().acquire_owned()).await {
            Ok(Ok(permit)) => Ok(permit),
            _ => Err(ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "busy",
                format!(
                    "all {} workers are busy: try again shortly (--jobs, --wait)",
                    self.server.jobs
                ),
            )),
        }
    }

    /// Checks the request, takes a worker, reads the upload and runs `work` on it (decoded) on
    /// the blocking pool, the worker held throughout.
    async fn run<T: Send + 'static>(
        self: Arc<Self>,
        request: Request,
        work: impl FnOnce(&Server, Upload, DynamicImage, Metadata) -> Result<T, ApiError>
            + Send
            + 'static,
    ) -> Result<T, ApiError> {
        check_request(&request, self.server.max_upload)?;
        let permit = self.worker().await?;
        let upload = read_upload(request, self.server.max_upload).await?;
        let shared = Arc::clone(&self);
        let done = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            let server = &shared.server;
            let (img, metadata) =
                imageio::read_image_with_metadata_from_memory(&upload.bytes, server.max_pixels)
                    .map_err(|e| ApiError::from_library(&e))?;
            work(server, upload, img, metadata)
        })
        .await;
        done.map_err(|e| ApiError::internal(format!("the image's worker failed: {e}")))?
    }
}

/// `POST /api/estimate`: the CLI's `estimate --json` object; with `annotate=true` also
/// `description` (the CLI's sentence) and `annotated` (the annotated picture, a PNG data URL).
async fn estimate(State(shared): AppState, request: Request) -> Response {
    let result = async {
        let params = params(&request)?;
        let annotate = params.annotate.unwrap_or(false);
        shared
            .run(request, move |server, upload, img, metadata| {
                let report = server.unshear.estimate_photo(&img, &metadata);
                let file = label(params.name.as_deref().or(upload.name.as_deref()));
                let line = JsonLine::ok(&file, &report);
                if !annotate {
                    return Ok(json_response(&line));
                }
                let png = annotated_png(&img, &report)?;
                Ok(json_response(&PageReport {
                    line,
                    description: crate::describe(&report),
                    annotated: format!("data:image/png;base64,{}", base64(&png)),
                }))
            })
            .await
    };
    result.await.unwrap_or_else(IntoResponse::into_response)
}

/// The page's report: the CLI's object, its sentence and the annotated picture.
#[derive(Serialize)]
struct PageReport {
    #[serde(flatten)]
    line: JsonLine,
    description: String,
    annotated: String,
}

/// The CLI's `--annotate` picture as PNG bytes.
fn annotated_png(img: &DynamicImage, report: &ImageReport) -> Result<Vec<u8>, ApiError> {
    imageio::encode_image(
        &crate::annotated(img, report),
        Path::new("annotated.png"),
        &WriteOptions::default(),
    )
    .map_err(|e| ApiError::internal(e.to_string()))
}

/// `POST /api/annotate`: the annotated picture (PNG), the shear found in `X-Unshear-K`.
async fn annotate(State(shared): AppState, request: Request) -> Response {
    let result = async {
        params(&request)?;
        shared
            .run(request, |server, _upload, img, metadata| {
                let report = server.unshear.estimate_photo(&img, &metadata);
                let png = annotated_png(&img, &report)?;
                Ok(image_response(png, "png", None, report.k))
            })
            .await
    };
    result.await.unwrap_or_else(IntoResponse::into_response)
}

/// `POST /api/correct`: the corrected image, in the input's format (or `format`), its colour
/// profile and EXIF kept; the shear used in `X-Unshear-K`. 422 when no shear is found and none
/// is given.
async fn correct(State(shared): AppState, request: Request) -> Response {
    let result = async {
        let params = params(&request)?;
        let k = match params.k.as_deref() {
            None | Some("") => None,
            Some(v) => match v.trim().parse::<f64>() {
                Ok(k) if k.is_finite() && k.abs() <= 10.0 => Some(k),
                _ => {
                    return Err(ApiError::bad_parameter(format!(
                        "k={v}: not a number from -10 to 10"
                    )))
                }
            },
        };
        let region: Region = choice("region", params.region.as_deref(), RegionArg::Image)?.into();
        let options = CorrectOptions {
            region,
            canvas: choice("canvas", params.canvas.as_deref(), CanvasArg::Same)?.into(),
            interpolation: choice("interp", params.interp.as_deref(), InterpArg::Linear)?.into(),
            k,
            blur: None,
        };
        let format = match params.format.as_deref() {
            None | Some("") => None,
            Some(f) => {
                let ext = f.to_ascii_lowercase();
                if !imageio::output_format_supported(Path::new(&format!("x.{ext}"))) {
                    return Err(ApiError::bad_parameter(format!(
                        "format={f}: not one of jpeg, png, pnm, bmp, tiff, webp"
                    )));
                }
                Some(ext)
            }
        };
        shared
            .run(request, move |server, upload, img, metadata| {
                let ext = format.unwrap_or_else(|| output_extension(&upload.bytes).to_string());
                drop(upload.bytes);
                // A shear given for the whole image needs no estimate: only the readout's
                // direction, from the EXIF orientation.
                let report = if k.is_some() && region == Region::Image {
                    let empty = ImageReport::empty(img.width(), img.height());
                    if metadata.turned {
                        server.unshear.read_by_columns(empty)
                    } else {
                        empty
                    }
                } else {
                    server.unshear.estimate_photo(&img, &metadata)
                };
                if !options.changes(&report) {
                    return Err(ApiError::new(
                        StatusCode::UNPROCESSABLE_ENTITY,
                        "no_face",
                        format!(
                            "{}: nothing to correct (give k to correct anyway)",
                            crate::no_shear_reason(&report)
                        ),
                    ));
                }
                let fixed = Unshear::correct(&img, &report, &options)
                    .map_err(|e| ApiError::from_library(&e))?;
                drop(img);
                let bytes = imageio::encode_image(
                    &fixed,
                    Path::new(&format!("corrected.{ext}")),
                    &WriteOptions {
                        metadata,
                        ..WriteOptions::default()
                    },
                )
                .map_err(|e| ApiError::internal(e.to_string()))?;
                let name = label(params.name.as_deref().or(upload.name.as_deref()));
                Ok(image_response(
                    bytes,
                    &ext,
                    Some(&name),
                    options.k.or(report.k),
                ))
            })
            .await
    };
    result.await.unwrap_or_else(IntoResponse::into_response)
}

/// The extension the corrected image is written with: the input's format (found from its
/// content), PNG for those only read (1-bit PBM, PAM) or not recognised.
fn output_extension(bytes: &[u8]) -> &'static str {
    use image::ImageFormat as F;
    match image::guess_format(bytes) {
        Ok(F::Jpeg) => "jpg",
        Ok(F::Bmp) => "bmp",
        Ok(F::Tiff) => "tif",
        Ok(F::WebP) => "webp",
        Ok(F::Pnm)
            if [b"P2", b"P3", b"P5", b"P6"]
                .iter()
                .any(|m| bytes.starts_with(*m)) =>
        {
            "pnm"
        }
        _ => "png",
    }
}

/// An image answer: its bytes and type, a download name made from `name`, and the shear.
fn image_response(bytes: Vec<u8>, ext: &str, name: Option<&str>, k: Option<f64>) -> Response {
    let content_type = match ext {
        "jpg" | "jpeg" => "image/jpeg",
        "png" => "image/png",
        "bmp" => "image/bmp",
        "tif" | "tiff" => "image/tiff",
        "webp" => "image/webp",
        "pgm" => "image/x-portable-graymap",
        "ppm" => "image/x-portable-pixmap",
        _ => "image/x-portable-anymap",
    };
    let mut response = (
        [(header::CONTENT_TYPE, HeaderValue::from_static(content_type))],
        Body::from(bytes),
    )
        .into_response();
    let headers = response.headers_mut();
    if let Some(k) = k.filter(|k| k.is_finite()) {
        if let Ok(v) = HeaderValue::from_str(&format!("{:.4}", r4(k))) {
            headers.insert(HeaderName::from_static(K_HEADER), v);
        }
    }
    if let Some(name) = name {
        let stem = Path::new(name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let safe: String = stem
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let disposition = format!("attachment; filename=\"{safe}.unshear.{ext}\"");
        if let Ok(v) = HeaderValue::from_str(&disposition) {
            headers.insert(header::CONTENT_DISPOSITION, v);
        }
    }
    response
}

/// Standard base64 with padding (RFC 4648), for the page's data URLs.
fn base64(bytes: &[u8]) -> String {
    use ::base64::Engine as _;
    ::base64::engine::general_purpose::STANDARD.encode(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64(plain.as_bytes()), encoded);
        }
    }

    #[test]
    fn labels_are_names_never_paths() {
        assert_eq!(label(Some("../../etc/passwd")), "passwd");
        assert_eq!(label(Some("C:\\photos\\a.jpg")), "a.jpg");
        assert_eq!(label(Some("a\nb.png")), "ab.png");
        assert_eq!(label(Some("dir/")), "upload");
        assert_eq!(label(None), "upload");
    }

    #[test]
    fn only_loopback_hosts_are_loopback() {
        for host in [
            "localhost",
            "localhost:8080",
            "127.0.0.1:1",
            "127.1.2.3",
            "[::1]:80",
            "[::1]",
        ] {
            assert!(is_loopback_host(host), "{host}");
        }
        for host in [
            "",
            "evil.example",
            "evil.example:8080",
            "10.0.0.1:80",
            "[::2]:80",
            "localhost.evil",
        ] {
            assert!(!is_loopback_host(host), "{host}");
        }
    }

    #[test]
    fn outputs_keep_the_input_format_where_it_is_written() {
        assert_eq!(output_extension(b"\xFF\xD8\xFF\xE0"), "jpg");
        assert_eq!(output_extension(b"P5 1 1 255\n\0"), "pnm");
        assert_eq!(output_extension(b"P4 1 1\n\0"), "png");
        assert_eq!(output_extension(b"hello"), "png");
    }
}
