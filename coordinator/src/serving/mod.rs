//! Serving a router behind the same limits in the coordinator and in a relay: the bounded
//! listener (connections in all and per peer, idle and head timeouts), a body timeout, the
//! busy marker and a small default body limit.
//!
//! Why one stack: a relay takes the same requests from the same kind of clients as the
//! coordinator (it serves the workers' API), so every attack on one is an attack on the other.
//! A relay built without these limits was aborted by one 2.5 GB release body and locked out by
//! 300 idle sockets.

pub mod connections;
pub mod result_body;

use std::time::Duration;

use axum::Router;
use axum::extract::{DefaultBodyLimit, Request};
use axum::middleware::{self, Next};
use axum::response::Response;
use tokio::net::TcpListener;
use tower_http::timeout::RequestBodyTimeoutLayer;

use crate::serving::connections::{BoundedListener, Busy, ConnectionLimits};

/// Bodies of JSON endpoints (and the `settings` form field) are small; 64 KiB is plenty.
pub const JSON_LIMIT: usize = 64 * 1024;

/// What a served router allows its clients.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServingLimits {
    /// Connections and their timeouts.
    pub connections: ConnectionLimits,
    /// Longest a request body may stall (no byte arriving) while its handler reads it: a
    /// stalled body fails and gives back whatever slot its handler holds.
    pub body_timeout: Duration,
}

impl Default for ServingLimits {
    fn default() -> ServingLimits {
        ConnectionArgs::default().limits()
    }
}

/// The flags of [`ServingLimits`], shared by `coordinator serve` and `coordinator relay`.
#[derive(Clone, Debug, clap::Args)]
pub struct ConnectionArgs {
    /// Open connections at most; more wait to be accepted.
    #[arg(long, default_value_t = 256)]
    pub max_connections: usize,
    /// Open connections of one peer (an IPv4 address or an IPv6 /64) at most; its further
    /// connections are closed at once, so that one peer cannot take every slot.
    #[arg(long, default_value_t = 64)]
    pub max_connections_per_peer: usize,
    /// Seconds of silence after which a connection is closed (not while an authenticated
    /// request on it is handled).
    #[arg(long, default_value_t = 60)]
    pub idle_timeout: u64,
    /// Seconds a request head may take to arrive, from its first byte.
    #[arg(long, default_value_t = 10)]
    pub header_timeout: u64,
    /// Seconds a request body may stall (no byte arriving) while it is read.
    #[arg(long, default_value_t = 20)]
    pub body_timeout: u64,
}

impl Default for ConnectionArgs {
    fn default() -> ConnectionArgs {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Defaults {
            #[command(flatten)]
            args: ConnectionArgs,
        }
        Defaults::parse_from(["defaults"]).args
    }
}

impl ConnectionArgs {
    /// The limits, or which flag is 0.
    pub fn checked(&self) -> Result<ServingLimits, String> {
        let zero = [
            ("--max-connections", self.max_connections as u64),
            ("--max-connections-per-peer", self.max_connections_per_peer as u64),
            ("--idle-timeout", self.idle_timeout),
            ("--header-timeout", self.header_timeout),
            ("--body-timeout", self.body_timeout),
        ];
        match zero.iter().find(|(_, v)| *v == 0) {
            Some((flag, _)) => Err(format!("{flag} must be at least 1")),
            None => Ok(self.limits()),
        }
    }

    /// The limits as given ([`ConnectionArgs::checked`] refuses zeros; the defaults have none).
    fn limits(&self) -> ServingLimits {
        ServingLimits {
            connections: ConnectionLimits {
                max: self.max_connections,
                per_peer: self.max_connections_per_peer,
                idle: Duration::from_secs(self.idle_timeout),
                head: Duration::from_secs(self.header_timeout),
            },
            body_timeout: Duration::from_secs(self.body_timeout),
        }
    }
}

/// `router` behind the limits' layers: bodies of at most [`JSON_LIMIT`] unless a route says
/// otherwise, a stall timeout on every body, and the connection marked busy while a request
/// is handled. Authentication goes outside (added after this), so that only authenticated
/// requests keep a connection busy.
pub fn guarded<S: Clone + Send + Sync + 'static>(router: Router<S>, limits: &ServingLimits) -> Router<S> {
    router
        .layer(DefaultBodyLimit::max(JSON_LIMIT))
        .layer(RequestBodyTimeoutLayer::new(limits.body_timeout))
        .layer(middleware::from_fn(busy))
}

/// Serves `router` (made with [`guarded`]) on `listener` until `shutdown`, then finishes the
/// requests under way.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    limits: ServingLimits,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let listener = BoundedListener::new(listener, limits.connections);
    axum::serve(listener, router.into_make_service_with_connect_info::<Busy>())
        .with_graceful_shutdown(shutdown)
        .await
}

/// Marks the connection busy while a request is handled, so the idle timeout does not close
/// it under a long handler (see [`crate::serving::connections`]).
async fn busy(req: Request, next: Next) -> Response {
    let guard = req
        .extensions()
        .get::<axum::extract::ConnectInfo<Busy>>()
        .map(|b| b.0.enter());
    let response = next.run(req).await;
    drop(guard);
    response
}

/// Whether a body error is the body timeout's (the client stalled), not a malformed body.
pub fn is_stall(e: &(dyn std::error::Error + 'static)) -> bool {
    std::iter::successors(Some(e), |e| e.source()).any(|e| e.is::<tower_http::timeout::TimeoutError>())
}
