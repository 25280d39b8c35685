//! Light transport algorithms. Each computes the radiance of one camera path; the render loop
//! in [`crate::render`] decides which pixels and passes.

pub mod direct;
pub mod direct_illumination;
pub mod path;
pub mod ptracer;
pub mod sppm;
pub mod walk;

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
