//! Light arriving straight from the light sources, shared by the path tracer and SPPM's camera
//! pass: light sampling at a surface or in a medium, and emission found by BSDF sampling, each
//! weighted against the other by multiple importance sampling. Shadow rays cross media and
//! medium boundaries, and carry their transmittance.

use glam::{Vec2, Vec3A};

use super::mis_weight;
use super::walk::Hit;
use crate::color::Rgb;
use crate::geometry::{Ray, SurfacePoint};
use crate::light::{Light, LightSample};
use crate::medium::Medium;
use crate::sampling::{Sampler, sample_equiangular};
use crate::scene::Scene;

/// Where a path's previous bounce was and how it was sampled.
pub struct PreviousBounce {
    /// Position.
    pub p: Vec3A,
    /// Density of the sampled direction (solid angle).
    pub pdf: f32,
    /// Whether it came from a delta lobe (then light sampling could not have found the path).
    pub delta: bool,
}

/// Radiance emitted by `light` at `sp` towards `wo`, weighted against light sampling at the
/// previous bounce (full weight for camera rays and after specular bounces).
pub fn emitted(
    scene: &Scene,
    light: u32,
    sp: &SurfacePoint,
    wo: Vec3A,
    prev: Option<&PreviousBounce>,
) -> Rgb {
    let Light::Area(area) = &scene.lights[light as usize] else {
        return Rgb::ZERO;
    };
    let le = area.emitted(sp.uv, sp.ns, wo);
    if le == Rgb::ZERO {
        return le;
    }
    match prev {
        Some(p) if !p.delta => le * mis_weight(p.pdf, scene.light_pdf(light, p.p, sp)),
        _ => le,
    }
}

/// One light sample's contribution at surface `hit`, through the media on the way. `medium` is
/// the medium the path arrived in. The sample is weighted by the power heuristic against BSDF
/// sampling that takes `bsdf_share` times as many samples (1 for a path that goes on to sample
/// the BSDF; 0 for none, which gives the full contribution). `sampler` serves the transmittance
/// of heterogeneous media.
pub fn light_sample(
    scene: &Scene,
    hit: &Hit,
    medium: Option<u32>,
    (u_select, u): (f32, Vec2),
    bsdf_share: f32,
    sampler: &mut Sampler,
) -> Rgb {
    let sp = &hit.sp;
    let Some((_, ls)) = scene.sample_light(sp.p, u_select, u) else {
        return Rgb::ZERO;
    };
    let wl = hit.frame.to_local(ls.wi);
    let f = hit.bsdf.eval(&hit.at(), hit.wo_local, wl);
    if f == Rgb::ZERO {
        return Rgb::ZERO;
    }
    // The shadow ray leaves on the light's side of the surface.
    let tr = scene.transmittance(sp, &ls, hit.shape.medium_after(ls.wi, sp.ng, medium), sampler);
    if tr == Rgb::ZERO {
        return Rgb::ZERO;
    }
    let w = if bsdf_share > 0.0 && !ls.delta {
        mis_weight(ls.pdf, bsdf_share * hit.bsdf.pdf(&hit.at(), hit.wo_local, wl))
    } else {
        1.0
    };
    f * tr * ls.radiance * (w / ls.pdf)
}

/// One light sample's contribution at point `p` inside `medium`, scattered back along the
/// path (which travelled along `d`) by the phase function, weighted as [`light_sample`] is
/// against `phase_share` times as many phase function samples. The medium's albedo is not
/// included.
pub fn light_sample_in_medium(
    scene: &Scene,
    p: Vec3A,
    d: Vec3A,
    medium: u32,
    (u_select, u): (f32, Vec2),
    phase_share: f32,
    sampler: &mut Sampler,
) -> Rgb {
    let sample = scene.sample_light(p, u_select, u);
    light_in_medium(scene, p, d, medium, sample, phase_share, sampler)
}

/// [`light_sample_in_medium`] for a light sample already drawn (from
/// [`Scene::sample_light`] or [`Scene::sample_picked_light`]).
pub fn light_in_medium(
    scene: &Scene,
    p: Vec3A,
    d: Vec3A,
    medium: u32,
    sample: Option<(u32, LightSample)>,
    phase_share: f32,
    sampler: &mut Sampler,
) -> Rgb {
    let Some((_, ls)) = sample else {
        return Rgb::ZERO;
    };
    let phase = scene.media[medium as usize].phase.eval(d, ls.wi);
    let tr = scene.transmittance(&SurfacePoint::in_medium(p), &ls, Some(medium), sampler);
    if tr == Rgb::ZERO {
        return Rgb::ZERO;
    }
    let w = if phase_share > 0.0 && !ls.delta {
        mis_weight(ls.pdf, phase_share * phase)
    } else {
        1.0
    };
    tr * ls.radiance * (phase * w / ls.pdf)
}

/// A collision drawn along `ray.at(0..t_max)` in `medium` for sampling point-like `light`:
/// equiangularly about it (Kulla and Fajardo 2012), so that its 1/d² falloff is in the density.
/// Drawn by transmittance instead, a collision near the light gives a sample without bound
/// (infinite variance for a light inside fog). Returns the distance and the weight σt·Tr/pdf;
/// None if the light is not point-like or the ray passes through it.
pub fn equiangular_collision(
    light: &Light,
    medium: &Medium,
    ray: &Ray,
    t_max: f32,
    u: f32,
    sampler: &mut Sampler,
) -> Option<(f32, Rgb)> {
    let c = light.point_position()?;
    let v = c - ray.o;
    let delta = v.dot(ray.d);
    let (t, pdf) = sample_equiangular(delta, (v - ray.d * delta).length(), t_max, u)?;
    Some((t, medium.collision_weight(ray, t, sampler) / pdf))
}

/// Light from light `li` (picked with probability `pmf`) scattered back along `ray` at a
/// collision (`t`, `weight` = σt·Tr/pdf) drawn in medium `m`, per unit throughput at the ray's
/// origin, with the medium's albedo: the light sample is not weighted against phase sampling
/// (collisions drawn along a segment are not where the path scatters).
pub fn scattered_at(
    scene: &Scene,
    ray: &Ray,
    m: u32,
    (li, pmf): (u32, f32),
    (t, weight): (f32, Rgb),
    u: Vec2,
    sampler: &mut Sampler,
) -> Rgb {
    let p = ray.at(t);
    let ls = scene.sample_picked_light(li, pmf, p, u);
    weight * scene.media[m as usize].albedo_at(p) * light_in_medium(scene, p, ray.d, m, ls, 0.0, sampler)
}

/// Point-like lights' share of the light single-scattered back along `ray.at(0..t_max)` in
/// medium `m`, per unit throughput at the ray's origin, from one light picked as light sampling
/// picks (zero if it is not point-like) and one collision drawn equiangularly about it. The
/// path tracer's light sampling at collisions leaves point-like lights to this.
pub fn point_lights_along(scene: &Scene, ray: &Ray, m: u32, t_max: f32, sampler: &mut Sampler) -> Rgb {
    let (u_sel, u_t, u_light) = (sampler.next_1d(), sampler.next_1d(), sampler.next_2d());
    let Some((li, pmf)) = scene.pick_light(u_sel) else {
        return Rgb::ZERO;
    };
    let medium = &scene.media[m as usize];
    match equiangular_collision(&scene.lights[li as usize], medium, ray, t_max, u_t, sampler) {
        Some(collision) => scattered_at(scene, ray, m, (li, pmf), collision, u_light, sampler),
        None => Rgb::ZERO,
    }
}
