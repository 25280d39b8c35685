//! Mitsuba's `normalmap` and `bumpmap`: a nested material seen through a shading frame that a
//! texture tilts. Written as Mitsuba 3.9.1 writes them (`src/bsdfs/normalmap.cpp`,
//! `bumpmap.cpp`), since its source defines what scenes exported for it look like: which
//! tangent the tilted frame keeps, the flip of normals that face away from the viewer, the
//! check that a direction lies on the same side of both frames, and Estevez's shadow
//! terminator term that hides the faceting a tilted normal causes at grazing light.
//!
//! Directions come in the local coordinates of the unperturbed shading frame, so the wrapper
//! composes with `twosided` as Mitsuba's does: `twosided` mirrors them through the unperturbed
//! tangent plane, and the map is then read as on the front.

use glam::{Vec2, Vec3A};

use super::{Bsdf, BsdfSample, SurfaceAt, TransportMode};
use crate::color::Rgb;
use crate::geometry::Frame;
use crate::texture::{Bitmap, Texture};

/// What tilts the shading frame.
#[derive(Clone, Debug)]
pub enum Perturbation {
    /// A tangent-space normal map: the texture's colour c gives the normal 2c − 1 in the
    /// shading frame (x along ∂p/∂u).
    Normal(std::sync::Arc<Texture>),
    /// A height map: the surface is displaced along its normal by `scale` times the texture's
    /// luminance, whose slope tilts the normal. Mitsuba differentiates only bitmaps.
    Bump {
        /// The heights.
        height: Box<Bitmap>,
        /// Their scale (Mitsuba's default 1).
        scale: f32,
    },
}

/// A material under a normal or bump map.
#[derive(Clone, Debug)]
pub struct Perturbed {
    /// The material.
    pub nested: Bsdf,
    /// What tilts its frame.
    pub by: Perturbation,
    /// Mitsuba's `flip_invalid_normals` (default on): a tilted normal that faces away from the
    /// viewer is mirrored about the unperturbed normal.
    pub flip_invalid_normals: bool,
    /// Mitsuba's `use_shadowing_function` (default on): the shadow terminator term.
    pub shadowing: bool,
}

impl Perturbed {
    /// The tilted frame, local to `at.frame`, for light leaving towards `wi`.
    fn frame(&self, at: &SurfaceAt, wi: Vec3A) -> Frame {
        let mut n = match &self.by {
            Perturbation::Normal(map) => {
                let c = map.eval(at.tex());
                Vec3A::new(2.0 * c.x - 1.0, 2.0 * c.y - 1.0, 2.0 * c.z - 1.0)
            }
            Perturbation::Bump { height, scale } => {
                let g = height.gradient(at.uv) * *scale;
                let n = at.frame.n;
                let dpdu = at.dpdu + n * (g.x - n.dot(at.dpdu));
                let dpdv = at.dpdv + n * (g.y - n.dot(at.dpdv));
                let mut bumped = dpdu.cross(dpdv).normalize_or_zero();
                if at.ng.dot(bumped) < 0.0 {
                    bumped = -bumped;
                }
                at.frame.to_local(bumped)
            }
        };
        if self.flip_invalid_normals && wi.z * wi.dot(n) <= 0.0 {
            n = Vec3A::new(-n.x, -n.y, n.z);
        }
        // A texel of (0.5, 0.5, 0.5), or a degenerate parameterisation, gives no normal: Mitsuba
        // would make NaNs of it; the unperturbed frame is the continuous choice.
        let n = n.try_normalize().unwrap_or(Vec3A::Z);
        // Mitsuba's tangent: for a normal map the frame's own x axis made orthogonal to n; for
        // a bump map it orthogonalises the *world* ∂p/∂u against the local n (bumpmap.cpp
        // mixes the two spaces). Only anisotropic materials can tell; we follow the source.
        let tangent = match self.by {
            Perturbation::Normal(_) => Vec3A::X,
            Perturbation::Bump { .. } => at.dpdu,
        };
        match (tangent - n * n.dot(tangent)).try_normalize() {
            Some(s) => Frame { s, t: n.cross(s), n },
            None => Frame::from_normal(n),
        }
    }

    /// The tilted frame and `wo` in it, if `wo` lies on the same side of both frames (the check
    /// Mitsuba's eval and pdf both make).
    fn tilted(&self, at: &SurfaceAt, wi: Vec3A, wo: Vec3A) -> Option<(Frame, Vec3A)> {
        let f = self.frame(at, wi);
        let pwo = f.to_local(wo);
        if wo.z * pwo.z <= 0.0 { None } else { Some((f, pwo)) }
    }

    /// The surface as the nested material sees it: the tilted frame, in world space.
    fn nested_at(at: &SurfaceAt, f: &Frame) -> SurfaceAt {
        SurfaceAt {
            frame: Frame {
                s: at.frame.to_world(f.s),
                t: at.frame.to_world(f.t),
                n: at.frame.to_world(f.n),
            },
            ..*at
        }
    }

    /// The shadow terminator term (Estevez et al. 2019, as normalmap_helpers.h has it): light
    /// arriving at grazing angles to the unperturbed surface is dimmed smoothly.
    fn shadowing(&self, n: Vec3A, wo: Vec3A) -> f32 {
        if !self.shadowing {
            return 1.0;
        }
        let tan2 = |v: Vec3A| (1.0 - v.z * v.z).max(0.0) / (v.z * v.z);
        let alpha2 = (0.125 * tan2(n)).min(1.0);
        2.0 / (1.0 + (1.0 + alpha2 * tan2(wo)).sqrt())
    }

    /// f · |cos θo| with the cosine of the tilted frame, zero unless `wo` lies on the same side
    /// of both frames.
    pub fn eval(&self, at: &SurfaceAt, wi: Vec3A, wo: Vec3A, mode: TransportMode) -> Rgb {
        let Some((f, pwo)) = self.tilted(at, wi, wo) else {
            return Rgb::ZERO;
        };
        let value = self
            .nested
            .eval_mode(&Self::nested_at(at, &f), f.to_local(wi), pwo, mode);
        if value == Rgb::ZERO {
            return value;
        }
        value * self.shadowing(f.n, wo)
    }

    /// The nested material's density (a change of frame keeps solid angle).
    pub fn pdf(&self, at: &SurfaceAt, wi: Vec3A, wo: Vec3A) -> f32 {
        let Some((f, pwo)) = self.tilted(at, wi, wo) else {
            return 0.0;
        };
        self.nested.pdf(&Self::nested_at(at, &f), f.to_local(wi), pwo)
    }

    /// Samples the nested material in the tilted frame.
    pub fn sample(
        &self,
        at: &SurfaceAt,
        wi: Vec3A,
        u1: f32,
        u2: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let f = self.frame(at, wi);
        let s = self
            .nested
            .sample(&Self::nested_at(at, &f), f.to_local(wi), u1, u2, mode)?;
        let wo = f.to_world(s.wo);
        if s.weight == Rgb::ZERO || wo.z * s.wo.z <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wo,
            weight: s.weight * self.shadowing(f.n, wo),
            ..s
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Diffuse;
    use crate::texture::{Filter, Wrap};

    fn normal_map(c: Rgb) -> Perturbed {
        let texels = vec![c];
        let map = Bitmap::from_texels(
            1,
            1,
            texels,
            Filter::Nearest,
            Wrap::Repeat,
            glam::Affine2::IDENTITY,
        );
        Perturbed {
            nested: Bsdf::Diffuse(Diffuse {
                reflectance: Rgb::splat(0.5).into(),
            }),
            by: Perturbation::Normal(std::sync::Arc::new(Texture::Bitmap(map))),
            flip_invalid_normals: true,
            shadowing: false,
        }
    }

    /// A flat normal map (0.5, 0.5, 1) leaves the material as it was.
    #[test]
    fn a_flat_normal_map_changes_nothing() {
        let p = normal_map(Rgb::new(0.5, 0.5, 1.0));
        let at = SurfaceAt::flat(Vec2::ZERO);
        let (wi, wo) = (
            Vec3A::new(0.3, 0.1, 0.9).normalize(),
            Vec3A::new(-0.5, 0.2, 0.7).normalize(),
        );
        let plain = p.nested.eval(&at, wi, wo);
        assert!(
            (p.eval(&at, wi, wo, TransportMode::Radiance) - plain)
                .abs()
                .max_element()
                < 1e-6
        );
    }

    /// A tilted normal makes a diffuse surface brightest towards the tilt, and a direction
    /// below the unperturbed surface gets nothing even where the tilted frame would light it.
    #[test]
    fn a_tilted_normal_follows_the_map_and_keeps_the_surface_side() {
        // n = (0.6, 0, 0.8) in the frame.
        let p = normal_map(Rgb::new(0.8, 0.5, 0.9));
        let at = SurfaceAt::flat(Vec2::ZERO);
        let wi = Vec3A::Z;
        let toward = Vec3A::new(0.6, 0.0, 0.8);
        let away = Vec3A::new(-0.6, 0.0, 0.8);
        let f = |wo| p.eval(&at, wi, wo, TransportMode::Radiance).x;
        assert!(
            (f(toward) - 0.5 / std::f32::consts::PI).abs() < 1e-5,
            "{}",
            f(toward)
        );
        assert!(f(toward) > f(away));
        // Grazes below the surface but above the tilted tangent plane.
        let below = Vec3A::new(0.99, 0.0, -0.1).normalize();
        assert_eq!(f(below), 0.0);
        let s = p
            .sample(&at, wi, 0.5, Vec2::new(0.3, 0.6), TransportMode::Radiance)
            .unwrap();
        assert!(s.wo.z > 0.0);
        assert!((p.pdf(&at, wi, s.wo) - s.pdf).abs() < 1e-4 * s.pdf);
    }

    /// The shadow terminator term is 1 at normal incidence and falls towards grazing light.
    #[test]
    fn the_shadow_terminator_dims_grazing_light() {
        let mut p = normal_map(Rgb::new(0.8, 0.5, 0.9));
        p.shadowing = true;
        let n = Vec3A::new(0.6, 0.0, 0.8);
        assert_eq!(p.shadowing(n, Vec3A::Z), 1.0);
        let grazing = p.shadowing(n, Vec3A::new(0.999, 0.0, 0.045).normalize());
        assert!(grazing < 0.6 && grazing > 0.0, "{grazing}");
    }
}
