//! Scattering functions. All work in the local shading frame (normal = +z), in Mitsuba's
//! convention: `wi` points towards where the path came from, `wo` is the sampled or queried
//! direction, and `eval` includes the cosine of `wo`.

mod conductor;
mod dielectric;
mod diffuse;
pub mod fresnel;
pub mod microfacet;
mod perturbed;
mod plastic;
mod principled;
mod rough_dielectric;
mod thin_dielectric;

pub use conductor::Conductor;
pub use dielectric::Dielectric;
pub use diffuse::Diffuse;
pub use microfacet::{Distribution, Microfacet, Roughness};
pub use perturbed::{Perturbation, Perturbed};
pub use plastic::{Coating, Plastic};
pub use principled::{Principled, eta_from_specular};
pub use rough_dielectric::RoughDielectric;
pub use thin_dielectric::ThinDielectric;

use glam::{Vec2, Vec3A};

use crate::color::Rgb;
use crate::geometry::Frame;
use crate::texture::{Param, TexAt};

/// Where a material is evaluated: its texture coordinates, and the surface around the point in
/// world space, which bump and normal maps tilt the shading frame by. Directions given to a
/// BSDF are local to `frame`.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceAt {
    /// Texture coordinates.
    pub uv: Vec2,
    /// The mesh attribute the material reads, interpolated here ([`TexAt::attr`]).
    pub attr: Rgb,
    /// The shading frame the directions are local to.
    pub frame: Frame,
    /// ∂p/∂u, with its length (a bump map's slope is relative to it).
    pub dpdu: Vec3A,
    /// ∂p/∂v, with its length.
    pub dpdv: Vec3A,
    /// The geometric normal.
    pub ng: Vec3A,
}

impl SurfaceAt {
    /// Where the material's textures are looked up.
    #[inline]
    pub fn tex(&self) -> TexAt {
        TexAt {
            uv: self.uv,
            attr: self.attr,
        }
    }

    /// A flat surface in the xy plane, facing +z, parameterised by x and y: for materials
    /// tested on their own.
    pub const fn flat(uv: Vec2) -> SurfaceAt {
        SurfaceAt {
            uv,
            attr: Rgb::ZERO,
            frame: Frame {
                s: Vec3A::X,
                t: Vec3A::Y,
                n: Vec3A::Z,
            },
            dpdu: Vec3A::X,
            dpdv: Vec3A::Y,
            ng: Vec3A::Z,
        }
    }
}

/// Which quantity a path carries: camera paths carry radiance, photons carry importance's
/// adjoint (power). Refraction scales the two differently.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportMode {
    /// Camera paths.
    Radiance,
    /// Light paths (photons).
    Importance,
}

/// A sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// The direction, in the local frame.
    pub wo: Vec3A,
    /// f · |cos θo| / pdf: what the throughput is multiplied by.
    pub weight: Rgb,
    /// Density per unit solid angle (for a delta lobe, the lobe's selection probability).
    pub pdf: f32,
    /// Whether the direction came from a delta (perfectly specular) lobe.
    pub delta: bool,
    /// Relative index of refraction crossed (1 for reflection), for Russian roulette.
    pub eta: f32,
}

/// A material, as the scene declares it.
#[derive(Clone, Debug)]
pub enum Bsdf {
    /// Lambertian.
    Diffuse(Diffuse),
    /// Smooth or rough metal.
    Conductor(Conductor),
    /// Smooth glass.
    Dielectric(Dielectric),
    /// Rough glass.
    RoughDielectric(Box<RoughDielectric>),
    /// A thin pane of glass.
    ThinDielectric(ThinDielectric),
    /// A material with holes: opaque where the opacity is, crossed unchanged elsewhere
    /// (Mitsuba's `mask`).
    Mask(Box<(Bsdf, Param<f32>)>),
    /// Smooth or rough coated diffuse.
    Plastic(Box<Plastic>),
    /// Mitsuba's `principled` (Burley's Disney BSDF).
    Principled(Box<Principled>),
    /// Linear blend of two materials: (1 - weight) · first + weight · second.
    Blend(Box<(Bsdf, Bsdf)>, Param<f32>),
    /// Front material and back material (Mitsuba's `twosided`).
    TwoSided(Box<(Bsdf, Bsdf)>),
    /// No surface at all (Mitsuba's `null`): the boundary of a medium, which rays cross
    /// unchanged.
    Null,
    /// Mitsuba's `polarizer` as its RGB variants render it: no surface, which passes half its
    /// `transmittance` (unpolarized light through a linear polarizer keeps half its power).
    Polarizer(Param<Rgb>),
    /// A material seen through a shading frame tilted by a normal or bump map.
    Perturbed(Box<Perturbed>),
}

impl Bsdf {
    /// Samples `wo` given `wi` at the surface `at`. `u1` chooses a lobe, `u2` the
    /// direction within it.
    pub fn sample(
        &self,
        at: &SurfaceAt,
        wi: Vec3A,
        u1: f32,
        u2: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let uv = &at.tex();
        match self {
            Bsdf::Diffuse(b) => b.sample(uv, wi, u2),
            Bsdf::Conductor(b) => b.sample(uv, wi, u2),
            Bsdf::Dielectric(b) => b.sample(uv, wi, u1, mode),
            Bsdf::RoughDielectric(b) => b.sample(uv, wi, u1, u2, mode),
            Bsdf::ThinDielectric(b) => b.sample(uv, wi, u1),
            Bsdf::Plastic(b) => b.sample(uv, wi, u1, u2),
            Bsdf::Mask(m) => {
                let opacity = m.1.at(uv).clamp(0.0, 1.0);
                if u1 < opacity {
                    let s =
                        m.0.sample(at, wi, (u1 / opacity).min(1.0 - f32::EPSILON), u2, mode)?;
                    // The choice's probability cancels against the opacity in the weight.
                    Some(BsdfSample {
                        pdf: s.pdf * opacity,
                        ..s
                    })
                } else {
                    Some(BsdfSample {
                        wo: -wi,
                        weight: Rgb::ONE,
                        pdf: 1.0 - opacity,
                        delta: true,
                        eta: 1.0,
                    })
                }
            }
            Bsdf::Principled(b) => b.sample(uv, wi, u1, u2, mode),
            Bsdf::Perturbed(b) => b.sample(at, wi, u1, u2, mode),
            Bsdf::Null | Bsdf::Polarizer(_) => Some(BsdfSample {
                wo: -wi,
                weight: self.null_transmission(*uv),
                pdf: 1.0,
                delta: true,
                eta: 1.0,
            }),
            Bsdf::Blend(pair, w) => {
                let w = w.at(uv).clamp(0.0, 1.0);
                let (first, second) = (&pair.0, &pair.1);
                let (chosen, u1) = if u1 >= w {
                    (first, (u1 - w) / (1.0 - w))
                } else {
                    (second, u1 / w)
                };
                let s = chosen.sample(at, wi, u1.min(1.0 - f32::EPSILON), u2, mode)?;
                if s.delta {
                    // The choice probability cancels against the blend weight.
                    return Some(s);
                }
                // A smooth direction could have come from either lobe: use the mixture density.
                let pdf = self.pdf(at, wi, s.wo);
                (pdf > 0.0).then(|| BsdfSample {
                    weight: self.eval_mode(at, wi, s.wo, mode) / pdf,
                    pdf,
                    ..s
                })
            }
            Bsdf::TwoSided(pair) => {
                if wi.z >= 0.0 {
                    pair.0.sample(at, wi, u1, u2, mode)
                } else {
                    let flip = Vec3A::new(1.0, 1.0, -1.0);
                    let s = pair.1.sample(at, wi * flip, u1, u2, mode)?;
                    Some(BsdfSample { wo: s.wo * flip, ..s })
                }
            }
        }
    }

    /// f(wi, wo) · |cos θo| of the non-delta lobes at `at`, for radiance (camera paths, light
    /// sampling and photon gathering): where refraction treats the two transport modes
    /// differently (the principled's transmission), [`Bsdf::sample`] applies the mode it is
    /// given.
    pub fn eval(&self, at: &SurfaceAt, wi: Vec3A, wo: Vec3A) -> Rgb {
        self.eval_mode(at, wi, wo, TransportMode::Radiance)
    }

    /// [`Bsdf::eval`] for either transport mode (a particle tracer's connections to the camera
    /// are importance transport).
    pub fn eval_mode(&self, at: &SurfaceAt, wi: Vec3A, wo: Vec3A, mode: TransportMode) -> Rgb {
        let uv = &at.tex();
        match self {
            Bsdf::Diffuse(b) => b.eval(uv, wi, wo),
            Bsdf::Conductor(b) => b.eval(uv, wi, wo),
            Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) | Bsdf::Null | Bsdf::Polarizer(_) => Rgb::ZERO,
            Bsdf::RoughDielectric(b) => b.eval(uv, wi, wo, mode),
            Bsdf::Plastic(b) => b.eval(uv, wi, wo),
            Bsdf::Mask(m) => m.0.eval_mode(at, wi, wo, mode) * m.1.at(uv).clamp(0.0, 1.0),
            Bsdf::Principled(b) => b.eval(uv, wi, wo, mode),
            Bsdf::Perturbed(b) => b.eval(at, wi, wo, mode),
            Bsdf::Blend(pair, w) => {
                let w = w.at(uv).clamp(0.0, 1.0);
                (1.0 - w) * pair.0.eval_mode(at, wi, wo, mode) + w * pair.1.eval_mode(at, wi, wo, mode)
            }
            Bsdf::TwoSided(pair) => {
                let flip = Vec3A::new(1.0, 1.0, -1.0);
                if wi.z >= 0.0 {
                    pair.0.eval_mode(at, wi, wo, mode)
                } else {
                    pair.1.eval_mode(at, wi * flip, wo * flip, mode)
                }
            }
        }
    }

    /// Density with which [`Bsdf::sample`] returns `wo` from its non-delta lobes at `at`.
    pub fn pdf(&self, at: &SurfaceAt, wi: Vec3A, wo: Vec3A) -> f32 {
        let uv = &at.tex();
        match self {
            Bsdf::Diffuse(b) => b.pdf(wi, wo),
            Bsdf::Conductor(b) => b.pdf(uv, wi, wo),
            Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) | Bsdf::Null | Bsdf::Polarizer(_) => 0.0,
            Bsdf::RoughDielectric(b) => b.pdf(uv, wi, wo),
            Bsdf::Plastic(b) => b.pdf(wi, wo),
            Bsdf::Mask(m) => m.0.pdf(at, wi, wo) * m.1.at(uv).clamp(0.0, 1.0),
            Bsdf::Principled(b) => b.pdf(uv, wi, wo),
            Bsdf::Perturbed(b) => b.pdf(at, wi, wo),
            Bsdf::Blend(pair, w) => {
                let w = w.at(uv).clamp(0.0, 1.0);
                (1.0 - w) * pair.0.pdf(at, wi, wo) + w * pair.1.pdf(at, wi, wo)
            }
            Bsdf::TwoSided(pair) => {
                let flip = Vec3A::new(1.0, 1.0, -1.0);
                if wi.z >= 0.0 {
                    pair.0.pdf(at, wi, wo)
                } else {
                    pair.1.pdf(at, wi * flip, wo * flip)
                }
            }
        }
    }

    /// Whether the material has a diffuse part, where photon density estimation works well.
    /// Purely glossy materials (rough metals) are better sampled by following the BSDF: their
    /// sharp lobes would turn a photon estimate into speckles.
    pub fn gathers_photons(&self) -> bool {
        match self {
            Bsdf::Diffuse(_) | Bsdf::Plastic(_) => true,
            Bsdf::Principled(b) => b.gathers_photons(),
            // Rough glass is followed like rough metal: its lobes are too sharp to gather on.
            Bsdf::Conductor(_)
            | Bsdf::Dielectric(_)
            | Bsdf::RoughDielectric(_)
            | Bsdf::ThinDielectric(_)
            | Bsdf::Null
            | Bsdf::Polarizer(_) => false,
            Bsdf::Blend(pair, _) | Bsdf::TwoSided(pair) => {
                pair.0.gathers_photons() || pair.1.gathers_photons()
            }
            Bsdf::Mask(m) => m.0.gathers_photons(),
            Bsdf::Perturbed(b) => b.nested.gathers_photons(),
        }
    }

    /// Whether the material depends on the orientation of the shading frame about the normal
    /// (anisotropic roughness, a normal map's tangent space): only then is the frame's first
    /// tangent aligned with the surface's ∂p/∂u, as Mitsuba aligns it.
    pub fn needs_tangent_frame(&self) -> bool {
        match self {
            Bsdf::Principled(b) => b.is_anisotropic(),
            Bsdf::Conductor(c) => c.roughness.as_ref().is_some_and(|r| r.anisotropic),
            Bsdf::RoughDielectric(d) => d.roughness.anisotropic,
            Bsdf::Perturbed(_) => true,
            Bsdf::Blend(pair, _) | Bsdf::TwoSided(pair) => {
                pair.0.needs_tangent_frame() || pair.1.needs_tangent_frame()
            }
            Bsdf::Mask(m) => m.0.needs_tangent_frame(),
            _ => false,
        }
    }

    /// Whether any lobe is not a delta: only then do light sampling and photon gathering see it.
    pub fn has_smooth(&self) -> bool {
        match self {
            Bsdf::Diffuse(_) | Bsdf::Plastic(_) | Bsdf::Principled(_) => true,
            Bsdf::Conductor(c) => c.roughness.is_some(),
            Bsdf::RoughDielectric(_) => true,
            Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) | Bsdf::Null | Bsdf::Polarizer(_) => false,
            Bsdf::Blend(pair, _) | Bsdf::TwoSided(pair) => pair.0.has_smooth() || pair.1.has_smooth(),
            Bsdf::Mask(m) => m.0.has_smooth(),
            Bsdf::Perturbed(b) => b.nested.has_smooth(),
        }
    }

    /// Whether a sample can take a delta lobe (a mask's pass-through counts): only then can a
    /// light path bounce specularly off it, which the hybrid method's particle tracer needs.
    pub fn has_delta(&self) -> bool {
        match self {
            Bsdf::Diffuse(_)
            | Bsdf::Principled(_)
            | Bsdf::RoughDielectric(_)
            | Bsdf::Null
            | Bsdf::Polarizer(_) => false,
            Bsdf::Plastic(p) => p.roughness.is_none(),
            Bsdf::Conductor(c) => c.roughness.is_none(),
            Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) | Bsdf::Mask(_) => true,
            Bsdf::Blend(pair, _) | Bsdf::TwoSided(pair) => pair.0.has_delta() || pair.1.has_delta(),
            Bsdf::Perturbed(b) => b.nested.has_delta(),
        }
    }

    /// Whether this is no surface at all: paths and photons cross it without a bounce, scaled
    /// by [`Bsdf::null_transmission`].
    pub fn is_null(&self) -> bool {
        matches!(self, Bsdf::Null | Bsdf::Polarizer(_))
    }

    /// What a surface that [`Bsdf::is_null`] passes at `uv` (Mitsuba's
    /// `eval_null_transmission`).
    pub fn null_transmission(&self, uv: TexAt) -> Rgb {
        match self {
            Bsdf::Polarizer(t) => 0.5 * t.at(uv),
            _ => Rgb::ONE,
        }
    }
}

#[cfg(test)]
mod tests;
