//! Transcendentals of our own, in IEEE basic operations only, so that every backend and every
//! machine gets the same bits (the platform's libm picks its own code per CPU: glibc's
//! `sincosf` has an FMA variant, which rounds differently).
//!
//! Only what the lane kernels need so far, on the ranges they need it: the concentric disk map
//! takes sine and cosine of angles within [-π/4, π/4], where short polynomials are accurate to
//! about one ulp without range reduction.

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
}
