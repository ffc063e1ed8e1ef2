//! The page of `unshear serve`: HTML, script and styles built into the binary (no CDN, works
//! offline), and the bundled example photo the page's `?demo=example` puts through the API.

use axum::http::{header, HeaderValue};
use axum::response::IntoResponse;

/// `page.html`: the page's markup.
const HTML: &str = include_str!("page.html");
/// `page.js`: the page's script (plain JavaScript, no build step).
const SCRIPT: &str = include_str!("page.js");
/// `page.css`: the page's styles.
const STYLE: &str = include_str!("page.css");
/// The README's example: a face sheared by k = 0.30 (the CLI estimates 0.3175).
const EXAMPLE: &[u8] = include_bytes!("../../../assets/example/face-k0.30.png");

/// A built-in file with its type; the browser revalidates nothing (the binary is the version).
fn file(content_type: &'static str, body: &'static [u8]) -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
        ],
        body,
    )
}

/// `GET /`.
pub async fn index() -> impl IntoResponse {
    file("text/html; charset=utf-8", HTML.as_bytes())
}

/// `GET /app.js`.
pub async fn script() -> impl IntoResponse {
    file("text/javascript; charset=utf-8", SCRIPT.as_bytes())
}

/// `GET /style.css`.
pub async fn style() -> impl IntoResponse {
    file("text/css; charset=utf-8", STYLE.as_bytes())
}

/// `GET /example.png`.
pub async fn example() -> impl IntoResponse {
    file("image/png", EXAMPLE)
}
