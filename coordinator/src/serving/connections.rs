//! The listener: caps on open connections, in all and per peer, and a timeout on silent ones.
//!
//! Why: each connection holds a file descriptor. Without a cap, a few hundred slow clients
//! (authenticated or not: the token is checked only once a request's head has arrived)
//! exhaust the descriptors and the service stops accepting anyone, workers included. Past the
//! cap, new connections wait in the kernel's listen backlog, which costs the process nothing.
//! A cap in all alone hands the service to whoever opens the most sockets, so each peer (an
//! IPv4 address, or an IPv6 /64, what one host or one customer of a provider holds) may hold
//! only its own share: past it, its new connections are closed as soon as they are accepted,
//! and other peers are served as before.
//!
//! A connection on which nothing is read or written for the idle timeout is closed, so slow
//! clients free their slots, and so is one whose request head (from its first byte to the
//! blank line) takes longer than the head timeout, however it trickles in: a client that
//! sends a byte a second is not idle, but it is slow. Empty lines before a request line
//! (which HTTP lets a server skip) are neither a head nor activity, so a client that sends
//! only `\r\n` is idle. Neither timeout applies while an authenticated request on the
//! connection is being handled ([`Busy`]): a long scene check must not cost its client the
//! answer. A body that stalls while its handler reads it is cut off there (`--body-timeout`).

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::{Instant, Sleep};

/// What a listener allows its connections.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConnectionLimits {
    /// Open connections in all.
    pub max: usize,
    /// Open connections of one peer (see [`Peer`]).
    pub per_peer: usize,
    /// Silence after which a connection is closed.
    pub idle: Duration,
    /// Longest a request head may take.
    pub head: Duration,
}

/// Who a connection comes from, for its share of the connections: an IPv4 address, or the /64
/// network of an IPv6 one (a host is usually given a whole /64).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Peer(IpAddr);

impl Peer {
    /// The peer of a remote address.
    pub fn of(addr: SocketAddr) -> Peer {
        match addr.ip() {
            IpAddr::V4(v4) => Peer(IpAddr::V4(v4)),
            IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
                Some(v4) => Peer(IpAddr::V4(v4)),
                None => {
                    let bits = u128::from(v6) & !((1u128 << 64) - 1);
                    Peer(IpAddr::V6(bits.into()))
                }
            },
        }
    }
}

/// Open connections per peer.
type PeerCounts = Arc<Mutex<HashMap<Peer, usize>>>;

/// A listener that holds at most `max` connections open, and `per_peer` of each peer.
pub struct BoundedListener {
    inner: TcpListener,
    slots: Arc<Semaphore>,
    peers: PeerCounts,
    limits: ConnectionLimits,
}

impl BoundedListener {
    /// Wraps `inner`: each connection closed after `limits.idle` of silence or when a request
    /// head takes longer than `limits.head`.
    /// Caps of 0 count as 1 (a listener that admits nobody would only hang its clients).
    pub fn new(inner: TcpListener, limits: ConnectionLimits) -> BoundedListener {
        let limits = ConnectionLimits {
            max: limits.max.max(1),
            per_peer: limits.per_peer.max(1),
            ..limits
        };
        BoundedListener {
            inner,
            slots: Arc::new(Semaphore::new(limits.max)),
            peers: Arc::default(),
            limits,
        }
    }

    /// Counts a connection of `peer`, unless the peer holds its share already.
    fn admit(&self, peer: Peer) -> Option<PeerSlot> {
        let mut counts = self.peers.lock().unwrap_or_else(|p| p.into_inner());
        let n = counts.entry(peer).or_insert(0);
        if *n >= self.limits.per_peer {
            return None;
        }
        *n += 1;
        Some(PeerSlot {
            peer,
            counts: self.peers.clone(),
        })
    }
}

/// A connection's place in its peer's share; given back when the connection is dropped.
struct PeerSlot {
    peer: Peer,
    counts: PeerCounts,
}

impl Drop for PeerSlot {
    fn drop(&mut self) {
        let mut counts = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = counts.get_mut(&self.peer) {
            *n -= 1;
            if *n == 0 {
                counts.remove(&self.peer);
            }
        }
    }
}

impl axum::serve::Listener for BoundedListener {
    type Io = Connection;
    type Addr = std::net::SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        let permit = self
            .slots
            .clone()
            .acquire_owned()
            .await
            .expect("the semaphore is never closed");
        loop {
            match self.inner.accept().await {
                Ok((stream, addr)) => {
                    let Some(peer_slot) = self.admit(Peer::of(addr)) else {
                        // Dropping the stream closes it; the slot in all stays for the next.
                        tracing::debug!(%addr, "peer holds its share of connections; closed");
                        continue;
                    };
                    let _ = stream.set_nodelay(true);
                    let idle = self.limits.idle;
                    return (
                        Connection {
                            stream,
                            _permit: permit,
                            _peer_slot: peer_slot,
                            idle,
                            idle_at: Instant::now() + idle,
                            head: self.limits.head,
                            head_by: None,
                            head_end: 0,
                            deadline: Box::pin(tokio::time::sleep(idle)),
                            busy: Busy::default(),
                        },
                        addr,
                    );
                }
                // Out of descriptors or a connection reset before it was accepted: wait a
                // little rather than spin.
                Err(e) => {
                    tracing::warn!("accept failed: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    }

    fn local_addr(&self) -> std::io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

/// An accepted connection: frees its slot when dropped; fails once silent for too long.
pub struct Connection {
    stream: TcpStream,
    _permit: OwnedSemaphorePermit,
    _peer_slot: PeerSlot,
    idle: Duration,
    /// When the connection counts as idle, unless something is read or written first.
    idle_at: Instant,
    head: Duration,
    /// While a request head is arriving: when it must be complete.
    head_by: Option<Instant>,
    /// How much of the blank line ending a head ("\r\n\r\n") the last bytes matched.
    head_end: usize,
    /// Fires at the earlier of `idle_at` and `head_by`.
    deadline: Pin<Box<Sleep>>,
    busy: Busy,
}

/// Requests of one connection being handled (after authentication): while there are any,
/// the connection is not idle, whatever its traffic. Handed to the router as connect info.
#[derive(Clone, Debug, Default)]
pub struct Busy(Arc<AtomicUsize>);

impl Busy {
    /// Marks a request as being handled until the returned guard is dropped.
    pub fn enter(&self) -> BusyGuard {
        self.0.fetch_add(1, Ordering::Relaxed);
        BusyGuard(self.0.clone())
    }
}

/// See [`Busy::enter`].
pub struct BusyGuard(Arc<AtomicUsize>);

impl Drop for BusyGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

impl axum::extract::connect_info::Connected<axum::serve::IncomingStream<'_, BoundedListener>> for Busy {
    fn connect_info(stream: axum::serve::IncomingStream<'_, BoundedListener>) -> Busy {
        stream.io().busy.clone()
    }
}

impl Connection {
    fn rearm(&mut self) {
        let at = self.head_by.map_or(self.idle_at, |h| h.min(self.idle_at));
        self.deadline.as_mut().reset(at);
    }

    fn touch(&mut self) {
        self.idle_at = Instant::now() + self.idle;
        self.rearm();
    }

    fn is_busy(&self) -> bool {
        self.busy.0.load(Ordering::Relaxed) > 0
    }

    /// Follows request heads in the bytes read: a head's clock starts at its first byte and
    /// stops at the blank line after it. Bytes read while a request is handled are its body.
    /// Returns whether the bytes were activity: empty lines between requests are not.
    fn saw(&mut self, bytes: &[u8]) -> bool {
        if self.is_busy() {
            return true;
        }
        let mut active = false;
        for &b in bytes {
            if self.head_by.is_none() {
                if b == b'\r' || b == b'\n' {
                    continue;
                }
                self.head_by = Some(Instant::now() + self.head);
                self.head_end = 0;
            }
            const END: &[u8; 4] = b"\r\n\r\n";
            self.head_end = if b == END[self.head_end] {
                self.head_end + 1
            } else if b == b'\r' {
                1
            } else {
                0
            };
            active = true;
            if self.head_end == END.len() {
                // The rest of these bytes are the request's body: the head is complete.
                self.head_by = None;
                self.head_end = 0;
                break;
            }
        }
        active
    }

    fn check_deadline(&mut self, cx: &mut Context<'_>) -> Poll<std::io::Error> {
        if self.is_busy() {
            // A request is being handled: silence is the handler working, not a slow client.
            self.touch();
            return Poll::Pending;
        }
        match self.deadline.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "connection idle, or its request head slow, for too long",
            )),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl AsyncRead for Connection {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.stream).poll_read(cx, buf) {
            Poll::Ready(r) => {
                if buf.filled().len() > before && self.saw(&buf.filled()[before..]) {
                    self.touch();
                }
                Poll::Ready(r)
            }
            Poll::Pending => match self.check_deadline(cx) {
                Poll::Ready(e) => Poll::Ready(Err(e)),
                Poll::Pending => Poll::Pending,
            },
        }
    }
}

impl AsyncWrite for Connection {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        match Pin::new(&mut self.stream).poll_write(cx, data) {
            Poll::Ready(r) => {
                // A response: whatever was read before it was a whole request.
                self.head_by = None;
                self.head_end = 0;
                self.touch();
                Poll::Ready(r)
            }
            Poll::Pending => match self.check_deadline(cx) {
                Poll::Ready(e) => Poll::Ready(Err(e)),
                Poll::Pending => Poll::Pending,
            },
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}
