//! Reading a lease's requests, the same way in the coordinator and in a relay: the lease key and
//! the result's encoding from the headers, and the result's body, whose size is bounded before
//! anything is read (by `Content-Length`) and while reading.
//!
//! The coordinator streams a result to a file of its lease's own and takes one of its limited
//! decoding slots only once the whole body is there, so a body that stalls holds a file and a
//! connection, never a slot that other workers wait for. A relay adds results into sums in
//! memory, so it reads them under one of its upload slots; there the body timeout
//! (`--body-timeout`) frees a stalled body's slot.

use axum::body::Bytes;
use axum::extract::Request;
use axum::http::{HeaderMap, header};
use photonfarm::compression::{self, CompressionError, Encoding};
use photonfarm::protocol::LEASE_KEY_HEADER;
use std::path::Path;

use futures_util::StreamExt;
use tokio::io::AsyncWriteExt;
use tokio::sync::{AcquireError, Semaphore, SemaphorePermit};

/// The lease key a request carries (empty if none: no lease has it).
pub fn lease_key(headers: &HeaderMap) -> String {
    headers
        .get(LEASE_KEY_HEADER)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string()
}

/// The encoding a result is sent with, from its `Content-Encoding`.
pub fn result_encoding(headers: &HeaderMap) -> Result<Encoding, CompressionError> {
    Encoding::from_header(
        headers
            .get(header::CONTENT_ENCODING)
            .and_then(|v| v.to_str().ok()),
    )
}

/// Why a result's body was not read.
#[derive(Debug)]
pub enum BodyError {
    /// The body is larger than its bound on the wire: its declared length when that was what
    /// exceeded it, None when reading found it larger.
    TooLarge(Option<u64>),
    /// No byte of the body arrived for the body timeout.
    Stalled,
    /// The connection failed while the body was read.
    Broken(String),
    /// The file it was written to could not be written.
    Io(std::io::Error),
    /// The upload slots were closed.
    Closed(AcquireError),
}

impl BodyError {
    fn of_read(e: axum::Error) -> BodyError {
        let inner = e.into_inner();
        if crate::serving::is_stall(&*inner) {
            BodyError::Stalled
        } else if inner.is::<http_body_util::LengthLimitError>() {
            BodyError::TooLarge(None)
        } else {
            BodyError::Broken(inner.to_string())
        }
    }
}

/// The most bytes a body sent with `encoding` may take on the wire for `max` bytes of content:
/// a compressed body may be a little larger than its content, never more than zstd's bound;
/// what it expands to is bounded by `max` when it is decompressed. Refuses a larger declared
/// length before anything is read.
fn wire_bound(headers: &HeaderMap, encoding: Encoding, max: u64) -> Result<u64, BodyError> {
    let wire_max = match encoding {
        Encoding::Identity => max,
        Encoding::Zstd => compression::max_compressed(max),
    };
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    match declared {
        Some(n) if n > wire_max => Err(BodyError::TooLarge(Some(n))),
        _ => Ok(wire_max),
    }
}

/// Reads a result body sent with `encoding` whose content is at most `max` bytes into memory,
/// under one of `slots`. The returned slot is the caller's to keep while it works on the body.
pub async fn read_result_body<'a>(
    headers: &HeaderMap,
    req: Request,
    encoding: Encoding,
    max: u64,
    slots: &'a Semaphore,
) -> Result<(Bytes, SemaphorePermit<'a>), BodyError> {
    let wire_max = wire_bound(headers, encoding, max)?;
    let slot = slots.acquire().await.map_err(BodyError::Closed)?;
    let body = axum::body::to_bytes(req.into_body(), wire_max as usize)
        .await
        .map_err(BodyError::of_read)?;
    Ok((body, slot))
}

/// Streams a result body sent with `encoding` whose content is at most `max` bytes to a new
/// file at `path` (a stale file or a planted symlink there is removed, never followed), made
/// durable before it returns the body's length. The caller removes the file if this fails.
pub async fn receive_result_to(
    headers: &HeaderMap,
    req: Request,
    encoding: Encoding,
    max: u64,
    path: &Path,
) -> Result<u64, BodyError> {
    let wire_max = wire_bound(headers, encoding, max)?;
    match tokio::fs::remove_file(path).await {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(BodyError::Io(e)),
        _ => {}
    }
    let mut file = tokio::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .await
        .map_err(BodyError::Io)?;
    let mut stream = req.into_body().into_data_stream();
    let mut len = 0u64;
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(BodyError::of_read)?;
        len += chunk.len() as u64;
        if len > wire_max {
            return Err(BodyError::TooLarge(None));
        }
        file.write_all(&chunk).await.map_err(BodyError::Io)?;
    }
    // Flushed first, or a failed last write (a full disk) would go unreported (see the
    // coordinator's bundle_to_disk).
    file.flush().await.map_err(BodyError::Io)?;
    file.sync_all().await.map_err(BodyError::Io)?;
    Ok(len)
}
