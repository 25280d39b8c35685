//! A bitmap's texels as the image file gave them: 8- or 16-bit levels decoded through a table
//! at each lookup, or linear floats.
//!
//! Why not decode every texel once, at load: a linear texel takes 16 bytes (`Rgb` is a `Vec3A`),
//! an 8-bit one 3. Bitterli's staircase holds 27 million texels in ten JPEGs: 430 MB decoded,
//! far beyond the caches, where `Bitmap::eval` spent three quarters of its time waiting on the
//! first texel of a lookup. The table holds the very values the load used to store, so a
//! lookup gives the same bits.

use crate::color::Rgb;

/// Row by row from the top, three samples a texel.
#[derive(Clone, Debug)]
pub(super) enum Texels {
    /// Integer levels (8- or 16-bit samples) and each level's linear value (a table as long as
    /// there are levels, so that indexing it needs no bounds check).
    Levels8 {
        samples: Vec<u8>,
        table: Box<[f32; 1 << 8]>,
    },
    /// As `Levels8`, for 16-bit images (a 256 KiB table).
    Levels16 {
        samples: Vec<u16>,
        table: Box<[f32; 1 << 16]>,
    },
    /// Linear values (floating-point images, and bitmaps made in code).
    Linear(Vec<Rgb>),
}

impl Texels {
    /// How many texels there are.
    pub(super) fn len(&self) -> usize {
        match self {
            Texels::Levels8 { samples, .. } => samples.len() / 3,
            Texels::Levels16 { samples, .. } => samples.len() / 3,
            Texels::Linear(t) => t.len(),
        }
    }

    /// Texel `i`'s linear value.
    #[inline]
    pub(super) fn get(&self, i: usize) -> Rgb {
        match self {
            Texels::Levels8 { samples, table } => {
                let [r, g, b] = samples[3 * i..3 * i + 3] else {
                    unreachable!()
                };
                Rgb::new(table[r as usize], table[g as usize], table[b as usize])
            }
            Texels::Levels16 { samples, table } => {
                let [r, g, b] = samples[3 * i..3 * i + 3] else {
                    unreachable!()
                };
                Rgb::new(table[r as usize], table[g as usize], table[b as usize])
            }
            Texels::Linear(t) => t[i],
        }
    }

    /// Every texel's linear value, in order.
    pub(super) fn iter(&self) -> impl Iterator<Item = Rgb> + '_ {
        (0..self.len()).map(|i| self.get(i))
    }
}
