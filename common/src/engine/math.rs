//! Transcendentals of our own, in IEEE basic operations only, so that every backend and every
//! machine gets the same bits (the platform's libm picks its own code per CPU: glibc's
//! `sincosf` has an FMA variant, which rounds differently).
//!
//! Only what the lane kernels need so far, on the ranges they need it: the concentric disk map
//! takes sine and cosine of angles within [-π/4, π/4], where short polynomials are accurate to
//! about one ulp without range reduction; GGX's visible normals and the environment map take
//! them of a whole turn, reduced to that range by quadrants; the environment's inverse mapping
//! takes atan2 and acos over their whole domains.

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

/// atan2(y, x) in radians, in [-π, π], for finite arguments: the ratio of the smaller to
/// the larger magnitude, in [0, 1], reduced at tan(π/8) to within [-tan(π/8), tan(π/8)], then
/// Cephes's single-precision polynomial, and the octant's reflections. Both zero gives zero.
#[inline(always)]
pub fn atan2(y: F8, x: F8) -> F8 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    let zero = F8::splat(0.0);
    let t = hi.gt(zero).select(lo / hi, zero);
    let reduce = t.gt(F8::splat(0.414_213_57));
    let r = reduce.select((t - 1.0) / (t + 1.0), t);
    let z = r * r;
    let p = (((8.053_744_5e-2 * z - 1.387_768_5e-1) * z + 1.997_771_1e-1) * z - 3.333_295e-1) * z * r + r;
    let a = reduce.select(p + std::f32::consts::FRAC_PI_4, p);
    let a = ay.gt(ax).select(std::f32::consts::FRAC_PI_2 - a, a);
    let a = x.lt(zero).select(std::f32::consts::PI - a, a);
    y.lt(zero).select(-a, a)
}

/// acos(x) in radians for x in [-1, 1] (clamped there): asin of x, or of sqrt((1 − |x|) / 2)
/// above |x| = 1/2, where acos(|x|) = 2 asin of it, by Cephes's single-precision polynomial.
#[inline(always)]
pub fn acos(x: F8) -> F8 {
    let ax = x.abs().min(F8::splat(1.0));
    let big = ax.gt(F8::splat(0.5));
    let z = big.select(0.5 * (1.0 - ax), ax * ax);
    let s = big.select(z.sqrt(), ax);
    let p = ((((4.216_32e-2 * z + 2.418_131e-2) * z + 4.547_002_6e-2) * z + 7.495_300_3e-2) * z
        + 1.666_675_2e-1)
        * z
        * s
        + s;
    let a = big.select(2.0 * p, std::f32::consts::FRAC_PI_2 - p);
    x.lt(F8::splat(0.0)).select(std::f32::consts::PI - a, a)
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

    /// Error of `a` against the exact `e`: in ulps, or in units of 2^-24 near zero, where an
    /// ulp of the result is far finer than the argument's own rounding.
    fn err(a: f32, e: f64) -> f64 {
        ulps(a, e).min((a as f64 - e).abs() * (1u32 << 24) as f64)
    }

    /// Worst [`err`] of `f` against `exact` over `xs`, and where.
    fn worst(xs: &[[f32; 2]], f: impl Fn(F8, F8) -> F8, exact: impl Fn(f64, f64) -> f64) -> (f64, [f32; 2]) {
        let mut worst = (0.0f64, [0.0; 2]);
        for c in xs.chunks(8) {
            let a = F8::from_fn(|i| c[i.min(c.len() - 1)][0]);
            let b = F8::from_fn(|i| c[i.min(c.len() - 1)][1]);
            let got = f(a, b);
            for (i, x) in c.iter().enumerate() {
                let e = exact(x[0] as f64, x[1] as f64);
                let err = err(got.0[i], e);
                if err > worst.0 {
                    worst = (err, *x);
                }
            }
        }
        worst
    }

    #[test]
    fn atan2_is_within_two_ulps_all_round_the_circle() {
        // Points on the unit circle and off it, on every axis and diagonal, and tiny ones.
        let n = 1 << 16;
        let mut xs: Vec<[f32; 2]> = (0..n)
            .flat_map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                let (s, c) = (libm::sin(t), libm::cos(t));
                [
                    [s as f32, c as f32],
                    [(3.0 * s) as f32, (0.25 * c) as f32],
                    [(1e-30 * s) as f32, (1e-30 * c) as f32],
                ]
            })
            .collect();
        xs.extend([
            [0.0, 1.0],
            [0.0, -1.0],
            [1.0, 0.0],
            [-1.0, 0.0],
            [1.0, 1.0],
            [-1.0, -1.0],
            [0.0, 0.0],
        ]);
        let (err, at) = worst(&xs, atan2, |y, x| {
            if x == 0.0 && y == 0.0 {
                0.0
            } else {
                libm::atan2(y, x)
            }
        });
        assert!(err <= 2.0, "{err} ulps at {at:?}");
    }

    #[test]
    fn acos_is_within_two_ulps_over_its_domain() {
        let n = 1 << 17;
        let mut xs: Vec<[f32; 2]> = (0..=n)
            .map(|k| [(2.0 * k as f64 / n as f64 - 1.0) as f32, 0.0])
            .collect();
        xs.extend([
            [1.0f32.next_down(), 0.0],
            [(-1.0f32).next_up(), 0.0],
            [0.5, 0.0],
            [0.5f32.next_up(), 0.0],
        ]);
        let (err, at) = worst(&xs, |x, _| acos(x), |x, _| libm::acos(x));
        assert!(err <= 2.0, "{err} ulps at {at:?}");
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
