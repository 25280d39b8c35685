//! What the coordinator and the workers send each other, and the one binary codec.
//!
//! JSON for the small control messages; bincode (2.x, pinned: its 2.x line is the last that
//! builds) for partial images, which are large. Only this module knows the codec, so it can be
//! swapped without touching either program.

use serde::de::DeserializeSeed;
use serde::{Deserialize, Serialize};

use crate::features::Features;
use crate::film::FilmSum;
use crate::parity::{OddSums, sample_len};
use crate::render::RenderSettings;

mod bounded;
#[cfg(feature = "http")]
mod endpoint;
pub mod routes;

#[cfg(feature = "http")]
pub use endpoint::Endpoint;

/// A job's lifecycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    /// Accepted, nothing rendered yet.
    Queued,
    /// Some passes rendered.
    Running,
    /// Every pass rendered.
    Done,
    /// A batch failed on too many workers.
    Failed,
    /// Cancelled by a user.
    Cancelled,
}

impl JobState {
    /// Whether the job will never change again.
    pub fn is_final(self) -> bool {
        matches!(self, JobState::Done | JobState::Failed | JobState::Cancelled)
    }

    /// The name used in the API and the database.
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// Parses [`JobState::as_str`].
    pub fn parse(s: &str) -> Option<JobState> {
        [
            JobState::Queued,
            JobState::Running,
            JobState::Done,
            JobState::Failed,
            JobState::Cancelled,
        ]
        .into_iter()
        .find(|j| j.as_str() == s)
    }
}

/// What `GET /api/jobs/{id}` answers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobStatus {
    /// Job id.
    pub id: u64,
    /// queued, running, done, failed or cancelled.
    pub state: JobState,
    /// Passes (iterations or samples per pixel) rendered and received.
    pub iterations_done: u64,
    /// Passes asked for.
    pub iterations_total: u64,
    /// Passes in the latest checkpoint image.
    pub checkpoint_iterations: u64,
    /// Workers holding a batch of this job now.
    pub workers: Vec<String>,
    /// Workers that asked the coordinator for work recently, on any job: 0 says why a queued
    /// job does not start.
    pub workers_present: usize,
    /// Seconds a coordinator spent on the job since its first batch was handed out (time
    /// while the coordinator was down does not count; restarts do not reset it).
    pub elapsed_seconds: f64,
    /// Passes per second over that time.
    pub rate: f64,
    /// `path` or `sppm`.
    pub integrator: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Why the job failed, if it did.
    pub message: Option<String>,
    /// When the job was submitted, Unix milliseconds.
    pub created_unix_ms: u64,
    /// Batch results received (across coordinator restarts).
    pub batches_received: u64,
    /// Bytes of batch results received (across coordinator restarts).
    pub bytes_received: u64,
    /// Of a frame of a sequence: the sequence's job.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<u64>,
    /// Of a frame of a sequence: its number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<u32>,
    /// Of a sequence: its frames, in the order given. The sequence's passes, checkpoint passes
    /// and counters are its frames' summed; its state is failed if a frame failed, done when
    /// every frame is, running once any started.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<FrameStatus>,
    /// Whether its checkpoints get a denoised preview (`image.denoised.exr`, `.png`): it was
    /// submitted with `denoise`.
    #[serde(default)]
    pub denoise: bool,
}

/// One frame of a sequence's status. Its image is its job's (`GET /api/jobs/{job}/image.exr`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameStatus {
    /// The frame number.
    pub frame: u32,
    /// The frame's job.
    pub job: u64,
    /// Its state.
    pub state: JobState,
    /// Passes rendered and received.
    pub iterations_done: u64,
    /// Passes asked for.
    pub iterations_total: u64,
    /// Passes in its latest image.
    pub checkpoint_iterations: u64,
}

/// What `GET /api/jobs` answers.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct JobList {
    /// Every job, oldest first.
    pub jobs: Vec<JobStatus>,
}

/// What `POST /api/jobs` answers: the new job's status and the scene's warnings.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Submitted {
    /// The job.
    #[serde(flatten)]
    pub status: JobStatus,
    /// What the scene check warned of (unsupported elements rendered as Mitsuba would not).
    #[serde(default)]
    pub warnings: Vec<String>,
}

/// A worker asking for work.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LeaseRequest {
    /// The worker's name (for logs, job status and failure tracking).
    pub worker: String,
    /// Threads it renders with (a hint for the batch size).
    pub threads: u32,
    /// How many machines render what this client leases: a relay (`coordinator relay`) leases
    /// for all its workers, so its first batch has one pass for each of them. None (one) for a
    /// worker; omitted on the wire then, so older coordinators accept the request.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub renderers: Option<u32>,
}

/// A batch of passes lent to a worker until `deadline_ms` from now, renewable by heartbeats.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Lease {
    /// The lease: results and heartbeats refer to it.
    pub lease_id: u64,
    /// The job.
    pub job_id: u64,
    /// First pass of the batch.
    pub start: u64,
    /// One past the last pass.
    pub end: u64,
    /// SPPM: the (surface, volume) radii of each pass of the batch, from the coordinator's
    /// schedule, so every machine uses the same radii whatever its maths library. Empty for
    /// path tracing.
    pub radii: Vec<[f32; 2]>,
    /// What to render.
    pub settings: RenderSettings,
    /// Content hash of the job's bundle (scene and files), to fetch it once and cache it.
    pub bundle: String,
    /// The scene file's path inside the bundle.
    pub scene: String,
    /// `-D` parameters for loading the scene.
    pub defines: Vec<(String, String)>,
    /// Milliseconds until the lease expires without a heartbeat.
    pub deadline_ms: u64,
    /// How often to heartbeat, in milliseconds.
    pub heartbeat_ms: u64,
    /// The lease's secret: heartbeats, the result and the release must carry it (header
    /// [`LEASE_KEY_HEADER`]), so that only the worker granted the lease can use it.
    pub key: String,
    /// The `Content-Encoding`s the coordinator accepts for the result (`zstd`); empty from an
    /// older coordinator, which takes results uncompressed only.
    #[serde(default)]
    pub accept_encoding: Vec<String>,
    /// The image's width and height (0 from an older coordinator): a relay bounds its
    /// workers' results by them before reading them.
    #[serde(default)]
    pub width: u32,
    /// See `width`.
    #[serde(default)]
    pub height: u32,
    /// Whether the job asks for the denoiser's features: the result must then carry them
    /// ([`encode_result`]), summed over the same passes ([`crate::features`]).
    #[serde(default)]
    pub features: bool,
}

/// The header that carries a lease's secret.
pub const LEASE_KEY_HEADER: &str = "x-photonfarm-lease-key";

/// The largest encoding of a batch result of a `width` × `height` image, with the denoiser's
/// `features` if its job asks for them: results are checked against it before they are read,
/// so no upload can be larger than its lease implies.
pub fn max_encoded_batch(width: u32, height: u32, features: bool) -> u64 {
    // Magic, then bincode varints: at most 5 bytes per u32, 9 per u64 (the two vectors'
    // lengths included) and 10 per zigzag i64: three sums per pixel and, with a filter wider
    // than a box, one weight.
    let sum = 2 * 5 + 4 * 9 + width as u64 * height as u64 * 40;
    // The odd passes' sample (see [`crate::parity`]) adds its lengths, its pass count and at
    // most 40 bytes per sampled pixel; the features are four more sums.
    MAGIC.len() as u64
        + sum
        + 3 * 9
        + sample_len(width, height) as u64 * 40
        + if features {
            Features::NAMES.len() as u64 * sum
        } else {
            0
        }
}

/// The coordinator's answer to a heartbeat.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct HeartbeatReply {
    /// Milliseconds until the lease now expires.
    pub deadline_ms: u64,
}

/// A worker giving up a batch (it failed, or the worker is shutting down).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Release {
    /// Why; None for a clean hand-back (shutdown), which does not count as a failure.
    pub error: Option<String>,
}

/// Why a payload could not be decoded.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// Not a valid encoding.
    #[error("malformed batch result: {0}")]
    Decode(String),
    /// Decoded, but inconsistent.
    #[error("inconsistent batch result: {0}")]
    Invalid(String),
}

const MAGIC: &[u8; 8] = b"PFBATCH1";
/// A result with its odd passes' sample: [`encode_result`].
const MAGIC_WITH_ODD: &[u8; 8] = b"PFBATCH2";
/// A result with its odd passes' sample and the denoiser's four features: [`encode_result`].
const MAGIC_WITH_FEATURES: &[u8; 8] = b"PFBATCH4";
/// As [`MAGIC_WITH_FEATURES`], from before `emitted_dense`: three features. Still read, so that
/// a coordinator upgraded mid-job keeps its stored batches; `emitted` then stands for
/// `emitted_dense` too (the same mean, from the image's own rays).
const MAGIC_WITH_THREE_FEATURES: &[u8; 8] = b"PFBATCH3";

/// A batch's result: its exact sum and, from workers that send it, the sums of its odd passes
/// on the sampled pixels (for the noise estimate; see [`crate::parity`]).
#[derive(Clone, Debug, PartialEq)]
pub struct BatchResult {
    /// Every pass of the batch, summed: what the image is made of.
    pub sum: FilmSum,
    /// The odd passes on the sampled pixels; None from a worker that does not send them.
    pub odd: Option<OddSums>,
    /// The denoiser's features of the same passes, for a job that asks for them.
    pub features: Option<Features>,
}

/// Encodes a result with its odd passes' sample (`PFBATCH2`): the full sum is encoded exactly
/// as by [`encode_batch`], followed by the sample; with features (`PFBATCH4`), followed by
/// their four sums.
pub fn encode_result(sum: &FilmSum, odd: &OddSums, features: Option<&Features>) -> Vec<u8> {
    let config = bincode::config::standard();
    let (magic, body) = match features {
        None => (MAGIC_WITH_ODD, bincode::serde::encode_to_vec((sum, odd), config)),
        Some(f) => {
            let [albedo, normal, emitted, emitted_dense] = f.sums();
            let all = (sum, odd, albedo, normal, emitted, emitted_dense);
            (MAGIC_WITH_FEATURES, bincode::serde::encode_to_vec(all, config))
        }
    };
    let mut out = magic.to_vec();
    out.extend(body.expect("sums always encode"));
    out
}

/// Decodes a result for a `width` × `height` image, with ([`encode_result`]) or without
/// ([`encode_batch`]) its odd passes' sample, and checks that it is whole. The size is the
/// receiver's (a lease's, a job's): a result of another size, or one whose vectors claim more
/// pixels, is refused before anything is allocated for it (see [`bounded`]).
pub fn decode_result(bytes: &[u8], width: u32, height: u32) -> Result<BatchResult, CodecError> {
    let (body, features) = match [MAGIC_WITH_ODD, MAGIC_WITH_THREE_FEATURES, MAGIC_WITH_FEATURES]
        .iter()
        .zip([0, 3, Features::NAMES.len()])
        .find_map(|(magic, n)| Some((bytes.strip_prefix(magic.as_slice())?, n)))
    {
        Some(found) => found,
        None => {
            return decode_batch(bytes, width, height).map(|sum| BatchResult {
                sum,
                odd: None,
                features: None,
            });
        }
    };
    let seed = bounded::ResultSeed {
        sum: bounded::SumSeed { width, height },
        features,
    };
    let (sum, odd, features) = decode_whole(seed, body)?;
    check_sum(&sum)?;
    odd.check(sum.width, sum.height, sum.passes)
        .map_err(CodecError::Invalid)?;
    let features = match features {
        sums if sums.is_empty() => None,
        mut sums => {
            for f in &sums {
                check_sum(f)?;
                if f.passes != sum.passes {
                    return Err(CodecError::Invalid(format!(
                        "features of {} passes with a sum of {}",
                        f.passes, sum.passes
                    )));
                }
            }
            if sums.len() == 3 {
                sums.push(sums[2].clone());
            }
            Some(Features::from_sums(sums.try_into().expect("one sum per name")))
        }
    };
    Ok(BatchResult {
        sum,
        odd: Some(odd),
        features,
    })
}

/// Decodes all of `body` with `seed`: trailing bytes are an error.
fn decode_whole<'a, S: DeserializeSeed<'a>>(seed: S, body: &'a [u8]) -> Result<S::Value, CodecError> {
    let (value, used) = bincode::serde::seed_decode_from_slice(seed, body, bincode::config::standard())
        .map_err(|e| CodecError::Decode(e.to_string()))?;
    if used != body.len() {
        return Err(CodecError::Invalid(format!(
            "{} trailing bytes",
            body.len() - used
        )));
    }
    Ok(value)
}

/// Encodes a partial image.
pub fn encode_batch(sum: &FilmSum) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend(
        bincode::serde::encode_to_vec(sum, bincode::config::standard()).expect("FilmSum always encodes"),
    );
    out
}

/// Decodes a partial image of `width` × `height` pixels and checks that it is whole (bounded
/// as [`decode_result`] is).
pub fn decode_batch(bytes: &[u8], width: u32, height: u32) -> Result<FilmSum, CodecError> {
    let body = bytes
        .strip_prefix(MAGIC.as_slice())
        .ok_or_else(|| CodecError::Decode("missing the PFBATCH1 header".into()))?;
    let sum = decode_whole(bounded::SumSeed { width, height }, body)?;
    check_sum(&sum)?;
    Ok(sum)
}

/// Checks that a decoded sum's vectors fit its size.
fn check_sum(sum: &FilmSum) -> Result<(), CodecError> {
    if !sum.weights.is_empty() && sum.weights.len() != sum.sums.len() {
        return Err(CodecError::Invalid(format!(
            "{} pixel weights for {} pixels",
            sum.weights.len(),
            sum.sums.len()
        )));
    }
    if sum.sums.len() as u64 != sum.width as u64 * sum.height as u64 {
        return Err(CodecError::Invalid(format!(
            "{} pixels for a {}x{} image",
            sum.sums.len(),
            sum.width,
            sum.height
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_rejects_garbage() {
        let mut f = FilmSum::new(3, 2);
        f.sums[4] = [1, -2, 1 << 40];
        f.passes = 7;
        let bytes = encode_batch(&f);
        assert_eq!(decode_batch(&bytes, 3, 2).unwrap(), f);
        assert!(decode_batch(b"nonsense", 3, 2).is_err());
        assert!(decode_batch(&bytes[..bytes.len() - 3], 3, 2).is_err());
        let mut extra = bytes.clone();
        extra.push(0);
        assert!(decode_batch(&extra, 3, 2).is_err());
        let mut worst = FilmSum::new(3, 2);
        worst
            .sums
            .iter_mut()
            .for_each(|s| *s = [i64::MIN, i64::MAX, i64::MIN]);
        worst.weights = vec![i64::MIN; 6];
        worst.passes = u64::MAX;
        worst.nonfinite = u64::MAX;
        assert!(encode_batch(&worst).len() as u64 <= max_encoded_batch(3, 2, false));
        let odd_worst = OddSums {
            sums: vec![[i64::MIN; 3]; 6],
            weights: vec![i64::MIN; 6],
            passes: u64::MAX,
        };
        assert!(encode_result(&worst, &odd_worst, None).len() as u64 <= max_encoded_batch(3, 2, false));
        let features = Features::from_sums(std::array::from_fn(|_| worst.clone()));
        let with = encode_result(&worst, &odd_worst, Some(&features));
        assert!(with.len() as u64 <= max_encoded_batch(3, 2, true));
        assert!(with.len() as u64 > max_encoded_batch(3, 2, false));
    }

    #[test]
    fn results_with_odd_passes_round_trip_and_old_ones_still_decode() {
        let mut f = FilmSum::new(3, 2);
        f.sums[1] = [5, 6, 7];
        f.passes = 3;
        let mut odd = OddSums::empty(3, 2);
        odd.sums[1] = [2, 2, 2];
        odd.passes = 1;
        let r = decode_result(&encode_result(&f, &odd, None), 3, 2).unwrap();
        assert_eq!((r.sum, r.odd, r.features), (f.clone(), Some(odd.clone()), None));
        assert_eq!(decode_result(&encode_batch(&f), 3, 2).unwrap().odd, None);
        // More odd passes than passes, or a sample of the wrong size, is refused.
        odd.passes = 4;
        assert!(decode_result(&encode_result(&f, &odd, None), 3, 2).is_err());
        assert!(decode_result(&encode_result(&f, &OddSums::empty(2, 2), None), 3, 2).is_err());
        let bytes = encode_result(&f, &OddSums::empty(3, 2), None);
        assert!(decode_result(&bytes[..bytes.len() - 1], 3, 2).is_err());
    }

    /// A result with features carries them exactly; features of other passes, another size
    /// or cut short are refused.
    #[test]
    fn results_with_features_round_trip_and_are_checked() {
        let mut f = FilmSum::new(3, 2);
        f.sums[1] = [5, 6, 7];
        f.passes = 2;
        let odd = OddSums::empty(3, 2);
        let mut features = Features::new(3, 2);
        for (k, s) in features.sums_mut().into_iter().enumerate() {
            s.sums[k] = [k as i64 + 1; 3];
            s.passes = 2;
        }
        let bytes = encode_result(&f, &odd, Some(&features));
        let r = decode_result(&bytes, 3, 2).unwrap();
        assert_eq!((r.sum, r.features), (f.clone(), Some(features.clone())));
        assert!(decode_result(&bytes[..bytes.len() - 1], 3, 2).is_err());
        features.normal.passes = 3;
        let e = decode_result(&encode_result(&f, &odd, Some(&features)), 3, 2).unwrap_err();
        assert!(e.to_string().contains("features of 3 passes"), "{e}");
        let other = Features::new(2, 3);
        assert!(decode_result(&encode_result(&f, &odd, Some(&other)), 3, 2).is_err());
    }

    /// A `PFBATCH3` result, from before the dense emission (a batch stored by an older
    /// coordinator), still reads: its own emission stands for the dense one.
    #[test]
    fn results_with_three_features_still_decode() {
        let mut f = FilmSum::new(3, 2);
        f.sums[1] = [5, 6, 7];
        f.passes = 2;
        let odd = OddSums::empty(3, 2);
        let mut three: Vec<FilmSum> = (0..3).map(|_| f.clone()).collect();
        three[2].sums[0] = [9, 9, 9];
        let body = (&f, &odd, &three[0], &three[1], &three[2]);
        let mut bytes = MAGIC_WITH_THREE_FEATURES.to_vec();
        bytes.extend(bincode::serde::encode_to_vec(body, bincode::config::standard()).unwrap());
        let r = decode_result(&bytes, 3, 2).unwrap().features.unwrap();
        assert_eq!(r.emitted, three[2]);
        assert_eq!(r.emitted_dense, three[2]);
        // And with a fourth sum after it, the three-feature kind has trailing bytes.
        bytes.extend(bincode::serde::encode_to_vec(&f, bincode::config::standard()).unwrap());
        assert!(decode_result(&bytes, 3, 2).is_err());
    }

    #[test]
    fn a_result_of_another_size_or_claiming_more_pixels_is_refused() {
        let f = FilmSum::new(3, 2);
        let e = decode_batch(&encode_batch(&f), 2, 3).unwrap_err().to_string();
        assert!(e.contains("a 3x2 image where 2x3 was expected"), "{e}");
        // A 3x2 header whose pixel vector claims a million pixels: refused at the length.
        let mut bytes = MAGIC.to_vec();
        bytes.extend(
            bincode::serde::encode_to_vec((3u32, 2u32, 1_000_000u64), bincode::config::standard()).unwrap(),
        );
        let e = decode_batch(&bytes, 3, 2).unwrap_err().to_string();
        assert!(
            e.contains("1000000 pixel sums where the image has room for 6"),
            "{e}"
        );
        // So is an odd-pass sample longer than the image's.
        let odd = OddSums {
            sums: vec![[0; 3]; 7],
            weights: Vec::new(),
            passes: 0,
        };
        let e = decode_result(&encode_result(&f, &odd, None), 3, 2)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("7 odd-pass sums where the image has room for 6"),
            "{e}"
        );
    }
}
