//! Owen-scrambled Sobol points with 32-bit indices.
//!
//! Why not `sobol_burley::sample_4d` alone: its sequences stop at 2^16 points, and the particle
//! tracer's light paths (and SPPM's photons) gain from being the points of *one* sequence across
//! passes, which needs billions of points (docs/sampling.md). This is the same construction
//! (Burley's hash-based Owen scrambling of the index and of each dimension, `sobol_burley`'s
//! parts), with the Joe–Kuo direction numbers carried to all 32 index bits by the `sobol` crate.

use std::sync::LazyLock;

use sobol::Sobol;
use sobol::params::JoeKuoD6;
use sobol_burley::parts::{Int4, hash, hash_int4, owen_scramble_int4_rev, owen_scramble_rev};

/// Dimensions, in sets of four: 16 cover the pixel, the lens and the first bounce or two, where
/// stratification pays. They gave the same RMSE as 256 at equal samples, in less time (fog paths
/// 23%, cbox paths about 7%; docs/sampling.md).
pub const DIMENSION_SETS: u32 = 4;

/// Bit-reversed direction vectors, XORed together a nibble of the index at a time:
/// `[set][nibble][its value]` holds four dimensions. A point is then eight loads (8 KiB in all,
/// within L1) instead of a loop over the index's set bits.
static DIRECTIONS: LazyLock<Vec<[[Int4; 16]; 8]>> = LazyLock::new(|| {
    let dims = (DIMENSION_SETS * 4) as usize;
    let vectors = Sobol::<u32>::init_direction_vals::<u32>(dims, 32, &JoeKuoD6::minimal());
    (0..DIMENSION_SETS as usize)
        .map(|set| {
            std::array::from_fn(|nibble| {
                std::array::from_fn(|value| {
                    let xor = |d: usize| {
                        (0..4)
                            .filter(|b| value >> b & 1 == 1)
                            .fold(0, |x, b| x ^ vectors[4 * set + d][4 * nibble + b].reverse_bits())
                    };
                    Int4::from([xor(0), xor(1), xor(2), xor(3)])
                })
            })
        })
        .collect()
});

/// Dimensions `4 * set` to `4 * set + 3` of point `index` of the sequence `seed`, in [0, 1).
/// Any power-of-two run of indices starting at a multiple of its length is a scrambled net.
#[inline]
pub fn sample_4d(index: u32, set: u32, seed: u32) -> [f32; 4] {
    // Shuffling the index (an Owen scramble of its reversed bits) keeps aligned power-of-two
    // runs together, so prefixes stay nets, and makes sequences of different seeds independent.
    let shuffled = owen_scramble_rev(index.reverse_bits(), hash(seed ^ 0x79c6_8e4a)).reverse_bits();
    let tables = &DIRECTIONS[set as usize];
    let mut sobol = tables[0][(shuffled & 15) as usize];
    for (nibble, table) in tables.iter().enumerate().skip(1) {
        sobol ^= table[(shuffled >> (4 * nibble) & 15) as usize];
    }
    let scramble = Int4::from([seed.wrapping_mul(0x9c8f_2d3b) ^ set; 4])
        ^ Int4::from([0x912f_69ba, 0x174f_18ab, 0x691e_72ca, 0xb40c_c1b8]);
    owen_scramble_int4_rev(sobol, hash_int4(scramble))
        .reverse_bits()
        .to_f32_norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each dimension of an aligned run of 2^m points puts one point in every interval of length
    /// 2^-m: the direction numbers are Sobol's, past index bit 16 too (m = 18).
    #[test]
    fn aligned_runs_are_stratified_in_every_dimension() {
        for (start, m) in [(0u32, 18u32), (1 << 20, 12), (3 << 29, 8)] {
            for set in 0..DIMENSION_SETS {
                let mut seen = vec![[false; 4]; 1 << m];
                for i in start..start + (1 << m) {
                    let p = sample_4d(i, set, 7);
                    for d in 0..4 {
                        let cell = (p[d] * (1 << m) as f32) as usize;
                        assert!(!seen[cell][d], "set {set} dim {d}: two points in cell {cell}");
                        seen[cell][d] = true;
                    }
                }
            }
        }
    }

    /// The first two dimensions of an aligned run of 2^m points form a (0, m, 2)-net: every
    /// 2^-a × 2^-b box with a + b = m holds one point (m = 18 reaches past index bit 16).
    #[test]
    fn the_first_two_dimensions_form_a_net() {
        let m = 18;
        for a in 0..=m {
            let b = m - a;
            let mut seen = vec![false; 1 << m];
            for i in (5u32 << 20)..(5u32 << 20) + (1 << m) {
                let p = sample_4d(i, 0, 3);
                let cell = ((p[0] * (1 << a) as f32) as usize) << b | (p[1] * (1 << b) as f32) as usize;
                assert!(!seen[cell], "{a}+{b}: two points in cell {cell}");
                seen[cell] = true;
            }
        }
    }
}
