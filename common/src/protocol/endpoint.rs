//! The farm's one HTTP client: a coordinator's (or a relay's) address and the bearer token its
//! requests carry, used by `submit` and the job commands, the worker, a relay's upstream side
//! and `loadgen`.

/// A coordinator or relay to send requests to.
#[derive(Clone, Debug)]
pub struct Endpoint {
    base: String,
    token: Option<String>,
    http: reqwest::Client,
}

impl Endpoint {
    /// The service at `base` (`http://host:port`, a trailing `/` dropped), with `token` (None or
    /// empty: none) on every request, through `http` (its timeouts are the caller's).
    pub fn new(base: &str, token: Option<String>, http: reqwest::Client) -> Endpoint {
        Endpoint {
            base: base.trim_end_matches('/').to_string(),
            token: token.filter(|t| !t.is_empty()),
            http,
        }
    }

    /// The address, for messages.
    pub fn base(&self) -> &str {
        &self.base
    }

    /// A request for `path` (from [`super::routes`]), with the token.
    pub fn request(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        let r = self.http.request(method, format!("{}{path}", self.base));
        match &self.token {
            Some(t) => r.bearer_auth(t),
            None => r,
        }
    }
}
