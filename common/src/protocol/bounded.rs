//! Decoding a result no larger than the image it was rendered for: each vector's length is
//! checked against that image's pixel count as the length is read, before any element is.
//!
//! Why: a result's plain bytes are bounded ([`super::max_encoded_batch`]), but a zero takes one
//! byte as a varint and eight in memory, and a vector's length is the sender's word. Four
//! 5 KB zstd results for a 2048² job claimed 56 M pixels and decoded to about 1.3 GB each,
//! enough to abort a coordinator capped at 4 GB (issue 31). Read this way, decoding allocates
//! at most what the expected image takes, whatever the bytes claim.

use std::fmt;
use std::marker::PhantomData;

use serde::Deserialize;
use serde::de::{DeserializeSeed, Deserializer, Error as _, SeqAccess, Visitor};

use crate::features::Features;
use crate::film::FilmSum;
use crate::parity::{OddSums, sample_len};

/// A [`FilmSum`] of exactly `width` × `height` pixels.
#[derive(Clone, Copy)]
pub(super) struct SumSeed {
    pub width: u32,
    pub height: u32,
}

/// A `PFBATCH2` result: the sum and its odd passes' sample, followed by `features` sums of the
/// denoiser's features (in the order of `Features::NAMES`: four in `PFBATCH4`, the first three
/// in `PFBATCH3`), each of the sum's size.
#[derive(Clone, Copy)]
pub(super) struct ResultSeed {
    pub sum: SumSeed,
    pub features: usize,
}

/// An [`OddSums`] with at most `len` sampled pixels.
struct OddSeed {
    len: usize,
}

/// A vector of at most `max` elements.
struct Capped<T> {
    what: &'static str,
    max: usize,
    element: PhantomData<T>,
}

impl<T> Capped<T> {
    fn new(what: &'static str, max: usize) -> Capped<T> {
        Capped {
            what,
            max,
            element: PhantomData,
        }
    }
}

impl<'de, T: Deserialize<'de>> DeserializeSeed<'de> for Capped<T> {
    type Value = Vec<T>;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Vec<T>, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de, T: Deserialize<'de>> Visitor<'de> for Capped<T> {
    type Value = Vec<T>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "at most {} {}", self.max, self.what)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<T>, A::Error> {
        // bincode gives the length it read as the hint: refused here, nothing was allocated.
        let claimed = seq.size_hint().unwrap_or(0);
        let too_many = |n: &dyn fmt::Display| {
            A::Error::custom(format!(
                "{n} {} where the image has room for {}",
                self.what, self.max
            ))
        };
        if claimed > self.max {
            return Err(too_many(&claimed));
        }
        let mut v = Vec::with_capacity(claimed);
        while let Some(x) = seq.next_element()? {
            if v.len() == self.max {
                return Err(too_many(&format_args!("more than {}", self.max)));
            }
            v.push(x);
        }
        Ok(v)
    }
}

/// The next field of a struct read as a sequence (as bincode reads them).
fn field<'de, A: SeqAccess<'de>, S: DeserializeSeed<'de>>(
    seq: &mut A,
    seed: S,
    name: &str,
) -> Result<S::Value, A::Error> {
    seq.next_element_seed(seed)?
        .ok_or_else(|| A::Error::custom(format!("missing the field {name}")))
}

/// A plain field, with serde's own reading of its type.
fn plain<'de, A: SeqAccess<'de>, T: Deserialize<'de>>(seq: &mut A, name: &str) -> Result<T, A::Error> {
    field(seq, PhantomData::<T>, name)
}

impl<'de> DeserializeSeed<'de> for SumSeed {
    type Value = FilmSum;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<FilmSum, D::Error> {
        // The fields in FilmSum's order, as its derived Serialize writes them.
        const FIELDS: &[&str] = &["width", "height", "sums", "weights", "passes", "nonfinite"];
        d.deserialize_struct("FilmSum", FIELDS, self)
    }
}

impl<'de> Visitor<'de> for SumSeed {
    type Value = FilmSum;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "the sums of a {}x{} image", self.width, self.height)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<FilmSum, A::Error> {
        let width: u32 = plain(&mut seq, "width")?;
        let height: u32 = plain(&mut seq, "height")?;
        if (width, height) != (self.width, self.height) {
            return Err(A::Error::custom(format!(
                "a {width}x{height} image where {}x{} was expected",
                self.width, self.height
            )));
        }
        let pixels = (width as u64 * height as u64) as usize;
        Ok(FilmSum {
            width,
            height,
            sums: field(&mut seq, Capped::new("pixel sums", pixels), "sums")?,
            weights: field(&mut seq, Capped::new("pixel weights", pixels), "weights")?,
            passes: plain(&mut seq, "passes")?,
            nonfinite: plain(&mut seq, "nonfinite")?,
        })
    }
}

impl<'de> DeserializeSeed<'de> for OddSeed {
    type Value = OddSums;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<OddSums, D::Error> {
        d.deserialize_struct("OddSums", &["sums", "weights", "passes"], self)
    }
}

impl<'de> Visitor<'de> for OddSeed {
    type Value = OddSums;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "the odd passes of {} sampled pixels", self.len)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<OddSums, A::Error> {
        Ok(OddSums {
            sums: field(&mut seq, Capped::new("odd-pass sums", self.len), "sums")?,
            weights: field(&mut seq, Capped::new("odd-pass weights", self.len), "weights")?,
            passes: plain(&mut seq, "passes")?,
        })
    }
}

/// What a [`ResultSeed`] reads.
pub(super) type Decoded = (FilmSum, OddSums, Vec<FilmSum>);

impl<'de> DeserializeSeed<'de> for ResultSeed {
    type Value = Decoded;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_tuple(2 + self.features, self)
    }
}

impl<'de> Visitor<'de> for ResultSeed {
    type Value = Decoded;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "a sum and its odd passes' sample")?;
        if self.features > 0 {
            write!(f, ", then its features")?;
        }
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let sum = field(&mut seq, self.sum, "sum")?;
        let len = sample_len(self.sum.width, self.sum.height);
        let odd = field(&mut seq, OddSeed { len }, "odd")?;
        let features = Features::NAMES[..self.features.min(Features::NAMES.len())]
            .iter()
            .map(|name| field(&mut seq, self.sum, name))
            .collect::<Result<_, _>>()?;
        Ok((sum, odd, features))
    }
}
