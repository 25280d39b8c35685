//! Transcendentals of our own, in IEEE basic operations only, so that every backend and every
//! machine gets the same bits (the platform's libm picks its own code per CPU: glibc's
//! `sincosf` has an FMA variant, which rounds differently).
//!
//! Only what the lane kernels need so far, on the ranges they need it: the concentric disk map
//! takes sine and cosine of angles within [-π/4, π/4], where short polynomials are accurate to
//! about one ulp without range reduction; GGX's visible normals take them of a whole turn,
//! reduced to that range by quadrants.

use super::lanes::F8;

/// Sine and cosine of `x` in [-π/4, π/4] (outside it the error grows), as minimax polynomials
/// in x² of degree 3 (sine, times x) and 4 (cosine): Cephes's single-precision coefficients,
/// evaluated by Horner's rule in plain multiplies and adds.
#[inline(always)]
pub fn sincos_quarter(x: F8) -> (F8, F8) {
    let z = x * x;
    let s = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * x + x;
    let c = (((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z) + 1.0;
    (s, c)
}

/// Sine and cosine of 2πu for u in [0, 1]: u is reduced exactly to the nearest quarter turn
/// (u - k/4 is exact by Sterbenz's lemma), the rest is within [-π/4, π/4], and the quadrant
/// swaps and negates [`sincos_quarter`]'s pair.
#[inline(always)]
pub fn sincos_turn(u: F8) -> (F8, F8) {
    let k: [u32; 8] = std::array::from_fn(|i| (u.0[i] * 4.0 + 0.5).max(0.0) as u32);
    let r = u - F8::from_fn(|i| k[i] as f32 * 0.25);
    let (s, c) = sincos_quarter(r * std::f32::consts::TAU);
    let quadrant = |q: u32| crate::engine::lanes::M8::from_fn(|i| k[i] % 4 == q);
    let (q1, q2, q3) = (quadrant(1), quadrant(2), quadrant(3));
    let sin = q1.select(c, q2.select(-s, q3.select(-c, s)));
    let cos = q1.select(-s, q2.select(-c, q3.select(s, c)));
    (sin, cos)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in ulps between `a` and the exact value `e`.
    fn ulps(a: f32, e: f64) -> f64 {
        let ef = e as f32;
        let ulp = (ef.next_up() - ef).abs() as f64;
        ((a as f64 - e) / ulp).abs()
    }

    #[test]
    fn sine_and_cosine_are_within_two_ulps_on_the_quarter_range() {
        let quarter = std::f64::consts::FRAC_PI_4;
        let (mut worst_s, mut worst_c) = (0.0f64, 0.0f64);
        let n = 1 << 16;
        for chunk in 0..n / 8 {
            let x = F8::from_fn(|i| ((chunk * 8 + i) as f64 / n as f64 * 2.0 * quarter - quarter) as f32);
            let (s, c) = sincos_quarter(x);
            for i in 0..8 {
                let xi = x.0[i] as f64;
                worst_s = worst_s.max(ulps(s.0[i], libm::sin(xi)));
                worst_c = worst_c.max(ulps(c.0[i], libm::cos(xi)));
            }
        }
        assert!(
            worst_s <= 2.0 && worst_c <= 2.0,
            "sine {worst_s} ulps, cosine {worst_c} ulps"
        );
    }

    #[test]
    fn a_turn_is_within_two_ulps_of_the_exact_sine_and_cosine() {
        let (mut worst_s, mut worst_c) = (0.0f64, 0.0f64);
        let n = 1 << 16;
        for chunk in 0..=n / 8 {
            let u = F8::from_fn(|i| ((chunk * 8 + i).min(n) as f64 / n as f64) as f32);
            let (s, c) = sincos_turn(u);
            for i in 0..8 {
                let x = std::f64::consts::TAU * u.0[i] as f64;
                // In ulps, or in units of 2^-24 near the zeros, where an ulp of the result
                // is far finer than the angle's own rounding.
                let err = |a: f32, e: f64| ulps(a, e).min((a as f64 - e).abs() * (1u32 << 24) as f64);
                worst_s = worst_s.max(err(s.0[i], libm::sin(x)));
                worst_c = worst_c.max(err(c.0[i], libm::cos(x)));
            }
        }
        assert!(
            worst_s <= 2.0 && worst_c <= 2.0,
            "sine {worst_s} ulps, cosine {worst_c} ulps"
        );
    }
}
