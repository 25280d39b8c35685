//! Reading a lease's requests, the same way in the coordinator and in a relay: the lease key and
//! the result's encoding from the headers, and the result's body, whose size is bounded before
//! anything is read (by `Content-Length`) and while reading, held under one of a limited number
//! of upload slots.

use axum::body::Bytes;
use axum::extract::Request;
use axum::http::{HeaderMap, header};
use photonfarm::compression::{self, CompressionError, Encoding};
use photonfarm::protocol::LEASE_KEY_HEADER;
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
    /// The upload slots were closed.
    Closed(AcquireError),
}

/// Reads a result body sent with `encoding` whose content is at most `max` bytes. On the wire a
/// compressed body may be a little larger than its content, never more than zstd's bound; what
/// it expands to is bounded by `max` when it is decompressed. The returned slot is the caller's
/// to keep while it works on the body.
pub async fn read_result_body<'a>(
    headers: &HeaderMap,
    req: Request,
    encoding: Encoding,
    max: u64,
    slots: &'a Semaphore,
) -> Result<(Bytes, SemaphorePermit<'a>), BodyError> {
    let wire_max = match encoding {
        Encoding::Identity => max,
        Encoding::Zstd => compression::max_compressed(max),
    };
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if let Some(n) = declared
        && n > wire_max
    {
        return Err(BodyError::TooLarge(Some(n)));
    }
    let slot = slots.acquire().await.map_err(BodyError::Closed)?;
    let body = axum::body::to_bytes(req.into_body(), wire_max as usize)
        .await
        .map_err(|_| BodyError::TooLarge(None))?;
    Ok((body, slot))
}
