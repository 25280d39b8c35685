//! Light sources, and the choice of one in proportion to its power.
//!
//! The path tracer samples them for next-event estimation; SPPM will emit its photons through
//! the same code, so both see the same lights.

mod area;
mod beam;
mod distant;
mod envmap;
mod point;
mod projector;
mod spot;

pub use area::AreaLight;
pub use beam::BeamLight;
pub use distant::{ConstantLight, DirectionalLight, SceneSphere};
pub use envmap::EnvmapLight;
pub use point::PointLight;
pub use projector::ProjectorLight;
pub use spot::SpotLight;

use glam::Vec3A;

use crate::color::Rgb;

/// A light as sampled from a point that it may illuminate.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// The point on the light.
    pub p: Vec3A,
    /// Its floating-point error bound (zero for point lights).
    pub p_err: Vec3A,
    /// The light's surface normal there (zero for point lights).
    pub n: Vec3A,
    /// Unit direction from the receiver towards the light.
    pub wi: Vec3A,
    /// Radiance (area lights) or intensity over distance squared (delta lights) arriving.
    pub radiance: Rgb,
    /// Density per unit solid angle at the receiver, excluding the light's selection
    /// probability; 1 for delta lights.
    pub pdf: f32,
    /// Whether the light is a point in space (no MIS with BSDF sampling).
    pub delta: bool,
}

/// A photon leaving a light.
#[derive(Clone, Copy, Debug)]
pub struct EmittedPhoton {
    /// Where it starts.
    pub origin: Vec3A,
    /// Floating-point error bound of the origin (zero for point lights).
    pub origin_err: Vec3A,
    /// Surface normal at the origin (zero for point lights).
    pub n: Vec3A,
    /// Unit direction of flight.
    pub dir: Vec3A,
    /// Power carried: emitted radiance or intensity over the sampling densities, excluding the
    /// light's selection probability.
    pub power: Rgb,
}

/// A light source.
#[derive(Clone, Debug)]
pub enum Light {
    /// Emission from a shape's surface.
    Area(AreaLight),
    /// Isotropic point.
    Point(PointLight),
    /// Point with Mitsuba's spot falloff.
    Spot(SpotLight),
    /// Point that throws an image (Mitsuba's projector).
    Projector(ProjectorLight),
    /// Collimated beam from a disc.
    Beam(BeamLight),
    /// The same radiance from every direction, at infinity.
    Constant(ConstantLight),
    /// Radiance from an image around the scene, at infinity.
    Envmap(Box<EnvmapLight>),
    /// Parallel light from one direction (the sun).
    Directional(DirectionalLight),
}

impl Light {
    /// Where a light that is a point (point and spot lights) is: where light in a medium
    /// around it concentrates as 1/distance², which equiangular sampling follows.
    pub fn point_position(&self) -> Option<Vec3A> {
        match self {
            Light::Point(l) => Some(l.position),
            Light::Spot(l) => Some(l.position),
            Light::Projector(l) => Some(l.position),
            _ => None,
        }
    }

    /// The stretch [a, b] of `ray.at(0..t_max)` that this light can reach, or None if it
    /// reaches none of it: a beam lights only its cylinder, so light in a medium sampled within
    /// the stretch finds the beam on every sample instead of on the few that fall in it. Other
    /// lights may reach the whole segment.
    pub fn lit_span(&self, ray: &crate::geometry::Ray, t_max: f32) -> Option<(f32, f32)> {
        match self {
            Light::Beam(l) => l.lit_span(ray, t_max),
            _ => (t_max > 0.0).then_some((0.0, t_max)),
        }
    }

    /// Samples a point on the light as seen from `p`.
    pub fn sample_li(
        &self,
        p: Vec3A,
        prims: &[crate::geometry::Primitive],
        u: glam::Vec2,
    ) -> Option<LightSample> {
        match self {
            Light::Area(l) => l.sample_li(p, prims, u),
            Light::Point(l) => l.sample_li(p),
            Light::Spot(l) => l.sample_li(p),
            Light::Projector(l) => l.sample_li(p),
            Light::Beam(l) => l.sample_li(p),
            Light::Constant(l) => l.sample_li(p, u),
            Light::Envmap(l) => l.sample_li(p, u),
            Light::Directional(l) => l.sample_li(p),
        }
    }

    /// [`Light::sample_li`] from each point `p[l]` with `u[l]`, where given. An environment
    /// map takes them step by step over all the points, so that their cache misses overlap
    /// (`EnvmapLight::sample_each`); other lights one after the other. The same answers.
    pub fn sample_li_each<const N: usize>(
        &self,
        p: [Vec3A; N],
        prims: &[crate::geometry::Primitive],
        u: [Option<glam::Vec2>; N],
    ) -> [Option<LightSample>; N] {
        match self {
            Light::Envmap(l) => l.sample_li_each(p, u),
            _ => std::array::from_fn(|i| self.sample_li(p[i], prims, u[i]?)),
        }
    }

    /// Samples a photon: a position on the light and a direction of flight.
    pub fn sample_emission(
        &self,
        prims: &[crate::geometry::Primitive],
        u_pos: glam::Vec2,
        u_dir: glam::Vec2,
    ) -> Option<EmittedPhoton> {
        match self {
            Light::Area(l) => l.sample_emission(prims, u_pos, u_dir),
            Light::Point(l) => l.sample_emission(u_dir),
            Light::Spot(l) => l.sample_emission(u_dir),
            Light::Projector(l) => l.sample_emission(u_dir),
            Light::Beam(l) => l.sample_emission(u_pos),
            Light::Constant(l) => l.sample_emission(u_pos, u_dir),
            Light::Envmap(l) => l.sample_emission(u_pos, u_dir),
            Light::Directional(l) => l.sample_emission(u_pos),
        }
    }

    /// Emitted power (luminance), for choosing lights in proportion to it.
    pub fn power(&self) -> f32 {
        match self {
            Light::Area(l) => l.power(),
            Light::Point(l) => l.power(),
            Light::Spot(l) => l.power(),
            Light::Projector(l) => l.power(),
            Light::Beam(l) => l.power(),
            Light::Constant(l) => l.power(),
            Light::Envmap(l) => l.power(),
            Light::Directional(l) => l.power(),
        }
    }

    /// Radiance that a ray leaving the scene along `d` finds, from a light around the scene
    /// (zero for the others, and for the directional light, which no ray can hit).
    pub fn environment_radiance(&self, d: Vec3A) -> Rgb {
        match self {
            Light::Constant(l) => l.radiance,
            Light::Envmap(l) => l.eval(d),
            _ => Rgb::ZERO,
        }
    }

    /// Density per unit solid angle with which [`Light::sample_li`] picks direction `d` of a
    /// light around the scene.
    pub fn environment_pdf(&self, d: Vec3A) -> f32 {
        match self {
            Light::Constant(_) => 1.0 / (4.0 * std::f32::consts::PI),
            Light::Envmap(l) => l.pdf(d),
            _ => 0.0,
        }
    }

    /// [`Light::environment_radiance`] and [`Light::environment_pdf`] of each direction
    /// given (zeros for none), an environment map's several at once (`eval_pdf_each`).
    pub fn environment_each<const N: usize>(&self, d: [Option<Vec3A>; N]) -> [(Rgb, f32); N] {
        match self {
            Light::Envmap(l) => l.eval_pdf_each(d),
            _ => d.map(|d| {
                d.map_or((Rgb::ZERO, 0.0), |d| {
                    (self.environment_radiance(d), self.environment_pdf(d))
                })
            }),
        }
    }

    /// Whether rays leaving the scene see this light.
    pub fn is_environment(&self) -> bool {
        matches!(self, Light::Constant(_) | Light::Envmap(_))
    }

    /// Tells a light at infinity the scene's bounding sphere, once the scene is built.
    pub fn fit_scene(&mut self, sphere: SceneSphere) {
        match self {
            Light::Constant(l) => l.sphere = sphere,
            Light::Envmap(l) => l.sphere = sphere,
            Light::Directional(l) => l.sphere = sphere,
            _ => {}
        }
    }
}
