//! Owen-scrambled Sobol points with 32-bit indices.
//!
//! Why not `sobol_burley::sample_4d` alone: its sequences stop at 2^16 points, and the particle
//! tracer's light paths gain from being the points of *one* sequence across passes, which needs
//! billions of points (docs/sampling.md). This is the same construction (Burley's hash-based
//! Owen scrambling of the index and of each dimension, `sobol_burley`'s parts), with the Joe–Kuo
//! direction numbers carried to all 32 index bits by the `sobol` crate.

use std::sync::LazyLock;

use sobol::Sobol;
use sobol::params::JoeKuoD6;
use sobol_burley::parts::{Int4, hash, hash_int4, owen_scramble_int4_rev, owen_scramble_rev};

/// Dimensions held, in sets of four: the sampler's `SOBOL_DIMENSIONS` (sampling.rs says why 16).
pub const DIMENSION_SETS: u32 = 4;

/// `[dimension][index bit]`: the generator matrices' columns, most significant output bit first.
fn direction_vectors() -> Vec<Vec<u32>> {
    Sobol::<u32>::init_direction_vals::<u32>((DIMENSION_SETS * 4) as usize, 32, &JoeKuoD6::minimal())
}

/// Bit-reversed direction vectors XORed together a nibble of the index at a time:
/// `[set][nibble][its value]` holds four dimensions. A point is then eight loads (8 KiB in all,
/// within L1) instead of a loop over the index's set bits.
static TABLES: LazyLock<Vec<[[Int4; 16]; 8]>> = LazyLock::new(|| {
    let vectors = direction_vectors();
    let nibble_xor = |dim: usize, nibble: usize, value: usize| {
        (0..4)
            .filter(|b| value >> b & 1 == 1)
            .fold(0, |x, b| x ^ vectors[dim][4 * nibble + b].reverse_bits())
    };
    (0..DIMENSION_SETS as usize)
        .map(|set| {
            std::array::from_fn(|nibble| {
                std::array::from_fn(|value| {
                    Int4::from(std::array::from_fn(|d| nibble_xor(4 * set + d, nibble, value)))
                })
            })
        })
        .collect()
});

/// The unscrambled Sobol point `index`, dimensions `4 * set` to `4 * set + 3`, bit-reversed.
#[inline]
fn sobol_rev(index: u32, set: u32) -> Int4 {
    let tables = &TABLES[set as usize];
    let mut sobol = tables[0][(index & 15) as usize];
    for (nibble, table) in tables.iter().enumerate().skip(1) {
        sobol ^= table[(index >> (4 * nibble) & 15) as usize];
    }
    sobol
}

/// Point `index` of the sequence `seed`. Any power-of-two run of indices starting at a multiple
/// of its length is a scrambled net.
#[derive(Clone, Copy)]
pub struct Point {
    /// The index shuffled once for all the point's dimensions: an Owen scramble of its reversed
    /// bits keeps aligned power-of-two runs together, so prefixes stay nets, and makes
    /// sequences of different seeds independent.
    shuffled: u32,
    seed: u32,
}

impl Point {
    /// Point `index` of the sequence `seed`.
    #[inline]
    pub fn new(index: u32, seed: u32) -> Point {
        let shuffled = owen_scramble_rev(index.reverse_bits(), hash(seed ^ 0x79c6_8e4a)).reverse_bits();
        Point { shuffled, seed }
    }

    /// Dimensions `4 * set` to `4 * set + 3`, in [0, 1). Panics if `set >= DIMENSION_SETS`.
    #[inline]
    pub fn four(&self, set: u32) -> [f32; 4] {
        let scramble = Int4::from([self.seed.wrapping_mul(0x9c8f_2d3b) ^ set; 4])
            ^ Int4::from([0x912f_69ba, 0x174f_18ab, 0x691e_72ca, 0xb40c_c1b8]);
        owen_scramble_int4_rev(sobol_rev(self.shuffled, set), hash_int4(scramble))
            .reverse_bits()
            .to_f32_norm()
    }
}

#[cfg(test)]
mod tests {
    use sobol_burley::parts::{sobol_int4_rev, u32_to_f32_norm};

    use super::*;

    /// Int4 has no accessor: compare lanes as floats (their top 23 bits).
    fn lanes(reversed: Int4) -> [f32; 4] {
        reversed.reverse_bits().to_f32_norm()
    }

    /// The tables give the XOR of the direction vectors over the index's set bits, for indices
    /// with any of their 32 bits set; below 2^16 that is `sobol_burley`'s own Sobol point.
    #[test]
    fn tables_give_the_sobol_points_of_every_index_bit() {
        let vectors = direction_vectors();
        let mut index = 0x9e37_79b9u32;
        for _ in 0..2000 {
            index = index.wrapping_mul(0x2c1b_3c6d).wrapping_add(0x297a_2d39);
            for set in 0..DIMENSION_SETS {
                let naive: [u32; 4] = std::array::from_fn(|d| {
                    (0..32)
                        .filter(|b| index >> b & 1 == 1)
                        .fold(0, |x, b| x ^ vectors[4 * set as usize + d][b])
                });
                assert_eq!(lanes(sobol_rev(index, set)), naive.map(u32_to_f32_norm));
                let low = index & 0xffff;
                assert_eq!(
                    lanes(sobol_rev(low, set)),
                    lanes(sobol_int4_rev(low.reverse_bits(), set)),
                    "index {low}, set {set}"
                );
            }
        }
    }

    /// Rank over GF(2) of 32-bit rows.
    fn rank(mut rows: Vec<u32>) -> usize {
        let mut rank = 0;
        for bit in (0..32).rev() {
            let Some(i) = (rank..rows.len()).find(|&i| rows[i] >> bit & 1 == 1) else {
                continue;
            };
            rows.swap(rank, i);
            for j in 0..rows.len() {
                if j != rank && rows[j] >> bit & 1 == 1 {
                    rows[j] ^= rows[rank];
                }
            }
            rank += 1;
        }
        rank
    }

    /// Row `k` of a dimension's generator matrix: output bit k (from the top) of each column.
    fn row(columns: &[u32], k: usize, m: usize) -> u32 {
        (0..m).fold(0, |r, c| r | (columns[c] >> (31 - k) & 1) << c)
    }

    /// Over all 32 index bits: every dimension alone is a (0, m, 1)-net for every m (its
    /// top-left m × m matrix is invertible), and the first two together a (0, m, 2)-net (the
    /// top a rows of one with the top m − a of the other are independent, for every a).
    #[test]
    fn generator_matrices_make_nets_of_every_size_up_to_2_to_the_32() {
        let v = direction_vectors();
        for m in 1..=32 {
            for (d, columns) in v.iter().enumerate() {
                let rows = (0..m).map(|k| row(columns, k, m)).collect();
                assert_eq!(rank(rows), m, "dimension {d}, m {m}");
            }
            for a in 0..=m {
                let rows = (0..a)
                    .map(|k| row(&v[0], k, m))
                    .chain((0..m - a).map(|k| row(&v[1], k, m)));
                assert_eq!(rank(rows.collect()), m, "dimensions 0 and 1, {a} + {}", m - a);
            }
        }
    }

    /// Scrambled points keep the nets: each dimension of an aligned run of 2^m points puts one
    /// point in every interval of length 2^-m.
    #[test]
    fn aligned_runs_are_stratified_in_every_dimension() {
        for (start, m) in [(0u32, 18u32), (1 << 20, 12), (3 << 29, 8)] {
            for set in 0..DIMENSION_SETS {
                let mut seen = vec![[false; 4]; 1 << m];
                for i in start..start + (1 << m) {
                    let p = Point::new(i, 7).four(set);
                    for d in 0..4 {
                        let cell = (p[d] * (1 << m) as f32) as usize;
                        assert!(!seen[cell][d], "set {set} dim {d}: two points in cell {cell}");
                        seen[cell][d] = true;
                    }
                }
            }
        }
    }
}
