//! The camera pass: one jittered path per pixel through specular and glossy bounces to the first
//! surface with a diffuse part, where direct light is sampled and the photons within the
//! iteration's radius estimate the rest. In media, the volume photons estimate the light
//! scattered towards the camera: along the whole ray (the beam radiance estimate) or at one
//! sampled collision (the point estimate).
//!
//! Specular bounces are followed as photons are. Glossy-only surfaces (rough metals) are
//! followed by BSDF sampling, with light sampling and multiple importance sampling as in the
//! path tracer, because a density estimate through a sharp lobe is speckled.

use std::f32::consts::PI;

use glam::Vec3A;

use super::beam_map::BeamMap;
use super::photon_beams::PhotonBeamMap;
use super::photon_map::PhotonMap;
use super::ray_transmittance::RayTransmittance;
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::integrator::direct;
use crate::integrator::walk::{Event, Hit, Walk};
use crate::medium::Flight;
use crate::sampling::Sampler;
use crate::scene::Scene;

/// What the camera pass needs of the iteration.
pub struct GatherContext<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// This iteration's surface photons.
    pub map: &'a PhotonMap,
    /// This iteration's surface radius.
    pub radius: f32,
    /// This iteration's volume photons, arranged for the estimator in use.
    pub volume_map: VolumeMap<'a>,
    /// This iteration's volume radius.
    pub volume_radius: f32,
    /// Power of a stored photon's unit power.
    pub power_unit: f32,
    /// The cone filter's k (≥ 1): weights fall from 1 at the centre to 1 − 1/k at the radius.
    pub k: f32,
    /// Longest camera path.
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
}

/// The volume photons of an iteration, in the structure their estimator queries.
#[derive(Clone, Copy)]
pub enum VolumeMap<'a> {
    /// For the beam radiance estimate: spheres crossed by a ray.
    Beam(&'a BeamMap),
    /// For the point estimate: photons near a point.
    Point(&'a PhotonMap),
    /// For photon beams: flights passing a ray.
    PhotonBeams(&'a PhotonBeamMap),
}

/// Radiance along the camera ray of one pixel sample.
pub fn camera_path(ctx: &GatherContext, ray: Ray, sampler: &mut Sampler) -> Rgb {
    let scene = ctx.scene;
    let mut l = Rgb::ZERO;
    let mut walk = Walk::new(ray, Rgb::ONE, scene.camera_medium);
    while walk.depth < ctx.max_depth {
        let event = match ctx.volume_map {
            VolumeMap::Beam(_) | VolumeMap::PhotonBeams(_) => walk.next_surface(scene, |w, m, t| {
                let (scattered, transmitted) = beam_estimate(ctx, &w.ray, m, t, sampler);
                // Light scattered in the medium has one bounce more than the camera's, as a
                // surface's reflected light does.
                if w.depth + 1 < ctx.max_depth {
                    l += w.beta * scattered;
                }
                transmitted
            }),
            VolumeMap::Point(_) => walk.next_event(scene, sampler),
        };
        l += walk.take_crossed();
        match event {
            Event::Gone => {
                l += walk.escaped(scene);
                break;
            }
            // The point estimate: the first collision is a gather point, direct light plus
            // volume photons.
            Event::Medium { p, medium, weight } => {
                walk.beta *= weight * scene.media[medium as usize].albedo_at(p);
                let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                l += walk.beta
                    * direct::light_sample_in_medium(
                        scene,
                        p,
                        walk.ray.d,
                        medium,
                        (u_sel, u_light),
                        0.0,
                        sampler,
                    );
                if let VolumeMap::Point(map) = ctx.volume_map {
                    l += walk.beta * volume_estimate(ctx, map, p, walk.ray.d, medium);
                }
                break;
            }
            Event::Surface(hit) => {
                // Emitters seen directly, through specular bounces (full weight: light sampling
                // cannot find these paths) or through glossy ones (weighted against light
                // sampling).
                l += walk.emission(scene, &hit);
                if walk.depth + 1 >= ctx.max_depth {
                    break;
                }
                let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                let gather = hit.bsdf.gathers_photons();
                if gather {
                    l += walk.beta
                        * direct::light_sample(scene, &hit, walk.medium, (u_sel, u_light), 0.0, sampler);
                    l += walk.beta * photon_estimate(ctx, &hit);
                } else if hit.bsdf.has_smooth() {
                    l += walk.beta
                        * direct::light_sample(scene, &hit, walk.medium, (u_sel, u_light), 1.0, sampler);
                }
                // Continue through specular lobes, and through glossy ones where nothing was
                // gathered.
                let Some(bs) = Walk::sample_bsdf(&hit, sampler, TransportMode::Radiance) else {
                    break;
                };
                if gather && !bs.delta {
                    break;
                }
                walk.follow(&hit, &bs);
                if !walk.survives_roulette(ctx.rr_depth, sampler) {
                    break;
                }
            }
        }
    }
    l
}

/// The density estimate: Σ f · Φ · w / (normalisation · π r²), with the cone filter w.
fn photon_estimate(ctx: &GatherContext, hit: &Hit) -> Rgb {
    let (sp, wo) = (&hit.sp, hit.wo);
    let inv_kr = 1.0 / (ctx.k * ctx.radius);
    let side = wo.dot(sp.ng);
    let mut sum = Rgb::ZERO;
    ctx.map.for_each_near(sp.p, |ph, d2| {
        let dir = ph.direction();
        // A photon that arrived on the other side of the surface (through a thin wall) is not
        // light this side receives.
        if dir.dot(sp.ng) * side <= 0.0 {
            return;
        }
        let local = hit.frame.to_local(dir);
        if local.z.abs() < 1e-6 {
            return;
        }
        // eval includes |cos| of the photon's direction; the photon's power already does.
        let f = hit.bsdf.eval(&hit.at(), hit.wo_local, local) / local.z.abs();
        sum += f * ph.power() * (1.0 - d2.sqrt() * inv_kr);
    });
    let norm = 1.0 - 2.0 / (3.0 * ctx.k);
    sum * (ctx.power_unit / (norm * PI * ctx.radius * ctx.radius))
}

/// In-scattered radiance at `p` in medium `m`, for a path that travelled along `d`, from the
/// volume photons within the volume radius: Σ phase · Φ / (σt · (4/3)π r³). Photons are stored
/// at collisions, whose density is σt times the fluence, hence the division by σt.
fn volume_estimate(ctx: &GatherContext, map: &PhotonMap, p: Vec3A, d: Vec3A, m: u32) -> Rgb {
    let med = &ctx.scene.media[m as usize];
    let mut sum = Rgb::ZERO;
    map.for_each_near(p, |ph, _| {
        sum += ph.power() * med.phase.eval(d, ph.direction());
    });
    if sum == Rgb::ZERO {
        return sum;
    }
    let r = ctx.volume_radius;
    let volume = 4.0 / 3.0 * PI * r * r * r;
    let sigma_t = med.sigma_t_at(p);
    let inv_sigma = Rgb::select(sigma_t.cmpgt(Rgb::ZERO), Rgb::ONE / sigma_t, Rgb::ZERO);
    sum * inv_sigma * (ctx.power_unit / volume)
}

/// Light scattered towards the camera along `ray.at(0..t_max)` in medium `m`, per unit
/// throughput at the ray's origin, and the throughput's factor over the stretch: the integral
/// over the segment of what the point estimate gives at each of its points (times
/// transmittance and σs), computed for the volume photons with the transmittance along the ray
/// ([`RayTransmittance`]: exact, or one ratio-tracking pass where the density varies) and by one
/// sampled collision for direct light.
///
/// A photon's sphere adds phase · Φ · albedo · ∫ Tr dt over its chord / ((4/3)π r³): the
/// point estimate's 1/σt cancels the σt of the scattering rate, and the chord's length
/// 2√(r² − d²) over the ball's volume is the projected-sphere kernel across the ray, which
/// integrates to one over the disk of radius r (Jarosz et al. 2008, with this kernel). Where
/// the albedo varies, it is read at the photon.
fn beam_estimate(ctx: &GatherContext, ray: &Ray, m: u32, t_max: f32, sampler: &mut Sampler) -> (Rgb, Rgb) {
    let scene = ctx.scene;
    let med = &scene.media[m as usize];
    // Direct light (which photons do not store) at a collision drawn within the segment:
    // equiangularly about a point light (its 1/d² would give the exponential's samples
    // unbounded variance near the light), else by transmittance within the part the light
    // reaches.
    let (u_channel, u_t, u_sel, u_light) = (
        sampler.next_1d(),
        sampler.next_1d(),
        sampler.next_1d(),
        sampler.next_2d(),
    );
    let mut l = Rgb::ZERO;
    if let Some((li, pmf)) = scene.pick_light(u_sel) {
        let light = &scene.lights[li as usize];
        // Else by transmittance, within the stretch the light reaches (a beam's cylinder):
        // in closed form, or by delta tracking from the stretch's start.
        let collision = direct::equiangular_collision(light, med, ray, t_max, u_t, sampler).or_else(|| {
            let (a, b) = light.lit_span(ray, t_max)?;
            if med.density().is_none() {
                let (t, weight) = med.sample_collision_within(b - a, u_channel, u_t)?;
                return Some((a + t, weight * med.transmittance(a)));
            }
            let to_a = med.transmittance_along(ray, a, sampler);
            match med.sample_flight_along(&Ray::new(ray.at(a), ray.d), b - a, sampler) {
                Flight::Collision { t, weight } => Some((a + t, weight * to_a)),
                Flight::Passed { .. } => None,
            }
        });
        if let Some(collision) = collision {
            l += direct::scattered_at(scene, ray, m, (li, pmf), collision, u_light, sampler);
        }
    }
    let tr = RayTransmittance::new(med, ray, t_max, sampler);
    let t_stop = tr.t_stop();
    // Where the albedo is one for the medium, it is taken out of the sums (ONE multiplies
    // exactly, so uniform media keep their bits).
    let uniform = med.is_uniform();
    let albedo = |p: Vec3A| if uniform { Rgb::ONE } else { med.albedo_at(p) };
    let r = ctx.volume_radius;
    match ctx.volume_map {
        VolumeMap::Beam(spheres) => {
            let mut sum = Rgb::ZERO;
            spheres.for_each_on_segment(ray, t_max, t_stop, |ph, a, b| {
                sum += ph.power * tr.over(a, b) * med.phase.eval(ray.d, ph.direction) * albedo(ph.position);
            });
            if sum != Rgb::ZERO {
                let albedo = if uniform { med.albedo } else { Rgb::ONE };
                l += sum * albedo * (ctx.power_unit / (4.0 / 3.0 * PI * r * r * r));
            }
        }
        // A flight's power at distance s along it is Φ·Tr(s)/P(flight > s) (it was ended at
        // a sampled collision), scattered with σs and the phase function at the ray's point
        // nearest it, through the 1D kernel 1/(2r) across both, over the sine of their angle
        // (Jarosz et al. 2011, "beam × beam 1D"). The job refuses them where density varies.
        VolumeMap::PhotonBeams(flights) => {
            let mut sum = Rgb::ZERO;
            flights.for_each_near_ray(ray, m, t_max, t_stop, |seg, c| {
                let along = med.transmittance(c.s) / med.flight_survival(c.s);
                let scatter = med.phase.eval(ray.d, -seg.direction) / c.sin;
                sum += seg.power * along * tr.at(c.t) * scatter * albedo(ray.at(c.t));
            });
            if sum != Rgb::ZERO {
                let albedo = if uniform { med.albedo } else { Rgb::ONE };
                l += sum * med.sigma_t * albedo * (ctx.power_unit / (2.0 * r));
            }
        }
        VolumeMap::Point(_) => {}
    }
    (l, tr.at_end(t_max))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vertical beam (radius 0.2, irradiance 10) in isotropic haze, crossed side-on by a ray
    /// 5 units below the beam's disc.
    const BEAM_IN_HAZE: &str = r#"<scene version="3.0.0">
        <medium type="homogeneous" id="haze">
            <float name="sigma_t" value="0.3"/>
            <float name="albedo" value="0.8"/>
            <phase type="isotropic"/>
        </medium>
        <sensor type="perspective">
            <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
            <ref id="haze"/>
            <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
        </sensor>
        <emitter type="beam">
            <float name="radius" value="0.2"/>
            <rgb name="irradiance" value="10"/>
            <transform name="to_world"><lookat origin="0, 5, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
            <ref id="haze"/>
        </emitter>
    </scene>"#;

    /// Direct light from a beam, sampled within the stretch of the ray inside the beam's
    /// cylinder, finds the beam on every sample and matches the closed form
    /// L = E σs/(4π) e^(−5σt) ∫ from 4.8 to 5.2 of e^(−σt t) dt. Sampled by transmittance along
    /// the whole ray, 3% of the samples would fall in the beam.
    #[test]
    fn direct_light_from_a_beam_is_found_on_every_sample() {
        let scene = Scene::from_str(BEAM_IN_HAZE, std::path::Path::new("beam-in-haze.xml"), &[]).unwrap();
        let medium = scene.camera_medium.unwrap();
        let (map, beams) = (PhotonMap::new(), BeamMap::new());
        let ctx = GatherContext {
            scene: &scene,
            map: &map,
            radius: 0.01,
            volume_map: VolumeMap::Beam(&beams),
            volume_radius: 0.01,
            power_unit: 1.0,
            k: 1.1,
            max_depth: 10,
            rr_depth: 5,
        };
        let ray = Ray::new(Vec3A::new(0.0, 0.0, 5.0), Vec3A::new(0.0, 0.0, -1.0));
        let (sigma_t, albedo, e) = (0.3f64, 0.8f64, 10.0f64);
        let integral = (libm::exp(-sigma_t * 4.8) - libm::exp(-sigma_t * 5.2)) / sigma_t;
        let expect =
            e * albedo * sigma_t / (4.0 * std::f64::consts::PI) * libm::exp(-sigma_t * 5.0) * integral;
        let n = 4096;
        let (mut sum, mut sum2, mut lit) = (0.0f64, 0.0f64, 0);
        for i in 0..n {
            let mut sampler = Sampler::new(1, crate::sampling::Stream::Camera, 0, i);
            let (l, transmitted) = beam_estimate(&ctx, &ray, medium, f32::INFINITY, &mut sampler);
            assert_eq!(transmitted, Rgb::ZERO);
            let v = l.x as f64;
            sum += v;
            sum2 += v * v;
            lit += (v > 0.0) as usize;
        }
        let mean = sum / n as f64;
        let rel_sd = (sum2 / n as f64 - mean * mean).max(0.0).sqrt() / mean;
        eprintln!(
            "beam in haze: {mean:.6} (closed form {expect:.6}), {lit} of {n} lit, relative sd {rel_sd:.3}"
        );
        assert_eq!(lit, n as usize);
        assert!(rel_sd < 0.05, "{rel_sd}");
        assert!((mean / expect - 1.0).abs() < 0.005, "{mean} against {expect}");
    }
}
