//! Light transport algorithms. Each computes the radiance of one camera path; the render loop
//! in [`crate::render`] decides which pixels and passes.

pub mod direct;
pub mod direct_illumination;
pub mod path;
pub mod ptracer;
pub mod sppm;
pub mod walk;

/// Which paths an estimator counts, so that two estimators can split a scene's paths between
/// them without counting any twice.
///
/// Why: a path tracer cannot find light that reaches a diffuse surface through glass or a
/// mirror from a small light (a caustic: its last bounce before the light is specular, so light
/// sampling is blocked and only a lucky BSDF sample hits the light, never for a point or spot
/// light), and a particle tracer finds it easily; the particle tracer, for its part, is a noisy
/// estimator of plain direct and indirect light, which the path tracer's light sampling
/// handles well. The hybrid method (LuxCore's "hybrid back/forward path tracing") gives each
/// the paths it is good at: a path x0 (camera), x1, …, xk (light) belongs to the particle
/// tracer when its bounce at x1 is not specular (so a light path can connect x1 to the camera)
/// and its bounce at x(k−1), the light path's first, is specular (so light sampling could not
/// have found it); every other path belongs to the path tracer. Specular means a delta lobe
/// was sampled, so a BSDF with both kinds of lobe splits by lobe, the same way on both sides.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Share {
    /// Every path the estimator can find.
    All,
    /// The path tracer's share in the hybrid method: all but the caustics.
    CameraSide,
    /// The particle tracer's share in the hybrid method: the caustics.
    LightSide,
}

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
