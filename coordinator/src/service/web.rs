//! The web page (`GET /`): one HTML file, its script and its style sheet, embedded in the
//! binary so the coordinator needs no files and the project no JavaScript build step.
//!
//! The files hold no data and are served without a token; the page asks the JSON API for
//! everything, sending the token its user typed in as an `Authorization` header (kept in the
//! tab's `sessionStorage`, never in a URL, so it cannot leak through history, logs or
//! `Referer`). Views are hash routes (`#/jobs/3`), so every view is this one page.

use axum::Router;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;

const INDEX: &str = include_str!("web/index.html");
const SCRIPT: &str = include_str!("web/app.js");
const STYLE: &str = include_str!("web/style.css");

/// Only the page's own files may run or load: no inline script, no other origin; images
/// come from `blob:` URLs the script makes from authenticated downloads.
const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; \
                   connect-src 'self'; form-action 'none'; frame-ancestors 'none'; base-uri 'none'";

/// Whether `path` is one of the page's files (served without a token).
pub fn is_asset(path: &str) -> bool {
    matches!(path, "/" | "/app.js" | "/style.css")
}

/// The page's routes.
pub fn routes<S: Clone + Send + Sync + 'static>() -> Router<S> {
    Router::new()
        .route("/", get(|| async { asset(INDEX, "text/html; charset=utf-8") }))
        .route(
            "/app.js",
            get(|| async { asset(SCRIPT, "text/javascript; charset=utf-8") }),
        )
        .route(
            "/style.css",
            get(|| async { asset(STYLE, "text/css; charset=utf-8") }),
        )
}

fn asset(body: &'static str, mime: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, mime),
            (header::CONTENT_SECURITY_POLICY, CSP),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
            (header::REFERRER_POLICY, "no-referrer"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}
