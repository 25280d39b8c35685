//! Batch results compressed on the wire (HTTP `Content-Encoding: zstd`, RFC 8878).
//!
//! Why: a result is a whole image's exact sums (about 3 bytes per channel after bincode's
//! varints), so the coordinator's network link and disk, not its CPU, were the first limit
//! on how many workers it feeds. zstd at level 1 was chosen over lz4 from measurements on
//! real fixed-point sums (docs/scaling.md): it roughly halves the bytes where lz4 saves a
//! few percent, and decompresses at several hundred MB/s on one core.
//!
//! Why bounded: the coordinator is a network service, and a few kilobytes of zstd can
//! expand to gigabytes. [`decompress_bounded`] stops reading past a limit the caller derives
//! from the lease (the largest result its image could have) and never allocates more.

use std::borrow::Cow;
use std::io::Read;

/// The zstd frame's magic number (RFC 8878), with which stored results are recognised.
const ZSTD_MAGIC: [u8; 4] = [0x28, 0xb5, 0x2f, 0xfd];

/// zstd's level for results: level 1 is its fastest, and higher levels gain little on
/// noisy sums (measured in docs/scaling.md) while costing the workers much more time.
pub const LEVEL: i32 = 1;

/// The `Content-Encoding` token of compressed results.
pub const ZSTD: &str = "zstd";

/// How a body is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// As is.
    Identity,
    /// A zstd frame.
    Zstd,
}

/// Why a body cannot be decoded.
#[derive(Debug, thiserror::Error)]
pub enum CompressionError {
    /// A `Content-Encoding` this program does not speak.
    #[error("unsupported Content-Encoding \"{0}\" (supported: identity, zstd)")]
    Unsupported(String),
    /// The body decompresses to more than the limit.
    #[error("the body decompresses to more than {0} bytes")]
    TooLarge(u64),
    /// Not a valid zstd frame.
    #[error("malformed zstd body: {0}")]
    Malformed(String),
}

impl Encoding {
    /// The encoding named by a `Content-Encoding` header (none: identity).
    pub fn from_header(value: Option<&str>) -> Result<Encoding, CompressionError> {
        match value.map(|v| v.trim().to_ascii_lowercase()) {
            None => Ok(Encoding::Identity),
            Some(v) if v.is_empty() || v == "identity" => Ok(Encoding::Identity),
            Some(v) if v == ZSTD => Ok(Encoding::Zstd),
            Some(v) => Err(CompressionError::Unsupported(v)),
        }
    }

    /// The header value to send, if any.
    pub fn header(self) -> Option<&'static str> {
        match self {
            Encoding::Identity => None,
            Encoding::Zstd => Some(ZSTD),
        }
    }

    /// The encoding of stored bytes, recognised by the zstd magic number (results are stored
    /// as received; a `PFBATCH` encoding never starts with it).
    pub fn sniff(bytes: &[u8]) -> Encoding {
        if bytes.starts_with(&ZSTD_MAGIC) {
            Encoding::Zstd
        } else {
            Encoding::Identity
        }
    }
}

/// Compresses a result with zstd at [`LEVEL`].
pub fn compress(bytes: &[u8]) -> Vec<u8> {
    // In-memory compression of a slice cannot fail but for allocation failure.
    zstd::bulk::compress(bytes, LEVEL).unwrap_or_else(|_| {
        let mut out = Vec::new();
        let _ = zstd::stream::copy_encode(bytes, &mut out, LEVEL);
        out
    })
}

/// The largest compressed body of a result at most `max` bytes decompressed: zstd's own
/// bound for incompressible input.
pub fn max_compressed(max: u64) -> u64 {
    max + max / 128 + (64 << 10)
}

/// Decodes `bytes` sent with `encoding`, refusing (without allocating for it) a body that
/// expands beyond `max` bytes.
pub fn decompress_bounded(
    encoding: Encoding,
    bytes: &[u8],
    max: u64,
) -> Result<Cow<'_, [u8]>, CompressionError> {
    match encoding {
        Encoding::Identity if bytes.len() as u64 > max => Err(CompressionError::TooLarge(max)),
        Encoding::Identity => Ok(Cow::Borrowed(bytes)),
        // A body stored as received is recognised by the magic number of its first frame, so
        // one that opened with a skippable frame would be accepted now and misread as plain
        // bytes, then dropped, at a restart.
        Encoding::Zstd if !bytes.starts_with(&ZSTD_MAGIC) => Err(CompressionError::Malformed(
            "a zstd body must start with a zstd frame (not a skippable frame)".into(),
        )),
        Encoding::Zstd => {
            let decoder = zstd::stream::read::Decoder::with_buffer(bytes)
                .map_err(|e| CompressionError::Malformed(e.to_string()))?;
            // The frame's declared size (if any) is not trusted: reading stops at max + 1.
            let mut out = Vec::with_capacity((bytes.len() as u64 * 3).min(max) as usize);
            decoder
                .take(max + 1)
                .read_to_end(&mut out)
                .map_err(|e| CompressionError::Malformed(e.to_string()))?;
            if out.len() as u64 > max {
                return Err(CompressionError::TooLarge(max));
            }
            Ok(Cow::Owned(out))
        }
    }
}

/// Decodes stored bytes whatever their encoding (see [`Encoding::sniff`]).
pub fn decode_stored(bytes: Vec<u8>, max: u64) -> Result<Vec<u8>, CompressionError> {
    match Encoding::sniff(&bytes) {
        Encoding::Identity => Ok(bytes),
        e => decompress_bounded(e, &bytes, max).map(Cow::into_owned),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_refuses_bombs_and_garbage() {
        let data: Vec<u8> = (0..100_000u32).map(|i| (i % 251) as u8).collect();
        let z = compress(&data);
        assert!(z.len() < data.len() / 10);
        assert_eq!(Encoding::sniff(&z), Encoding::Zstd);
        assert_eq!(*decompress_bounded(Encoding::Zstd, &z, 100_000).unwrap(), *data);
        assert!(matches!(
            decompress_bounded(Encoding::Zstd, &z, 99_999),
            Err(CompressionError::TooLarge(99_999))
        ));
        // A bomb: 1 GB of zeros in about 40 KB, refused after reading just past the limit.
        let bomb = {
            let mut enc = zstd::stream::write::Encoder::new(Vec::new(), 19).unwrap();
            let zeros = vec![0u8; 1 << 20];
            for _ in 0..1024 {
                std::io::Write::write_all(&mut enc, &zeros).unwrap();
            }
            enc.finish().unwrap()
        };
        assert!(bomb.len() < 1 << 20);
        assert!(matches!(
            decompress_bounded(Encoding::Zstd, &bomb, 1 << 20),
            Err(CompressionError::TooLarge(_))
        ));
        assert!(matches!(
            decompress_bounded(Encoding::Zstd, b"\x28\xb5\x2f\xfdgarbage", 1000),
            Err(CompressionError::Malformed(_))
        ));
        assert!(decompress_bounded(Encoding::Identity, &data, 10).is_err());
        assert_eq!(decode_stored(data.clone(), 1).unwrap(), data);
        assert_eq!(decode_stored(z, 1 << 20).unwrap(), data);
    }

    #[test]
    fn parses_content_encoding() {
        assert_eq!(Encoding::from_header(None).unwrap(), Encoding::Identity);
        assert_eq!(Encoding::from_header(Some(" ZSTD ")).unwrap(), Encoding::Zstd);
        assert_eq!(
            Encoding::from_header(Some("identity")).unwrap(),
            Encoding::Identity
        );
        assert!(Encoding::from_header(Some("gzip")).is_err());
        assert_eq!(Encoding::Zstd.header(), Some("zstd"));
    }

    #[test]
    fn a_body_that_opens_with_a_skippable_frame_is_refused() {
        // A skippable frame (magic 0x184D2A50, little-endian, then a 4-byte length) before a
        // real one: zstd itself skips it.
        let data = b"PFBATCH1 plain bytes".to_vec();
        let mut body = vec![0x50, 0x2a, 0x4d, 0x18, 3, 0, 0, 0, 1, 2, 3];
        body.extend(compress(&data));
        let e = decompress_bounded(Encoding::Zstd, &body, 1 << 20).unwrap_err();
        assert!(e.to_string().contains("must start with a zstd frame"), "{e}");
        // What is accepted is what a restart reads back the same.
        let z = compress(&data);
        assert_eq!(
            decompress_bounded(Encoding::Zstd, &z, 1 << 20).unwrap(),
            data.as_slice()
        );
        assert_eq!(decode_stored(z, 1 << 20).unwrap(), data);
    }
}
