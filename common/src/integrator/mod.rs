//! Light transport algorithms. Each computes the radiance of one camera path; the render loop
//! in [`crate::render`] decides which pixels and passes.

pub mod direct;
pub mod direct_illumination;
pub mod path;
pub mod sppm;

/// Multiple importance sampling's power heuristic (β = 2).
#[inline]
pub fn mis_weight(pdf_a: f32, pdf_b: f32) -> f32 {
    let (a, b) = (pdf_a * pdf_a, pdf_b * pdf_b);
    if a + b > 0.0 && a.is_finite() {
        a / (a + b)
    } else if a.is_infinite() {
        1.0
    } else {
        0.0
    }
}

/// Mitsuba's Russian roulette for camera paths: past `rr_depth` bounces a path survives with
/// probability max(throughput) · η² (at most 0.95) and carries 1/q more. False when the path
/// ends, or when nothing more could reach the camera along it.
pub(crate) fn russian_roulette(
    beta: &mut crate::color::Rgb,
    eta: f32,
    depth: u32,
    rr_depth: u32,
    sampler: &mut crate::sampling::Sampler,
) -> bool {
    if depth > rr_depth {
        let q = (beta.max_element() * eta * eta).min(0.95);
        if sampler.next_1d() >= q {
            return false;
        }
        *beta /= q;
    }
    *beta != crate::color::Rgb::ZERO
}
