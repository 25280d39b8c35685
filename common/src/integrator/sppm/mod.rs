//! Stochastic progressive photon mapping in Knaus and Zwicker's probabilistic form: every
//! iteration is an independent, consistent-in-the-limit estimate of the image with one global
//! radius, and the image is the mean of the iterations.
//!
//! An iteration depends only on (scene, settings, seed, its index, its radius): that is what
//! lets any machine render any batch. Steps of iteration i: [`trace::trace_photons`] (photon
//! pass), [`PhotonMap::build`], then [`gather::camera_path`] for every pixel (camera pass).

mod beam_map;
mod gather;
mod grid;
mod photon;
mod photon_beams;
mod photon_map;
mod radius;
mod ray_transmittance;
mod trace;

pub use beam_map::BeamMap;
pub use gather::{GatherContext, VolumeMap, camera_path};
pub use photon::Photon;
pub use photon_beams::{BeamSegment, PhotonBeamMap};
pub use photon_map::PhotonMap;
pub use radius::RadiusSchedule;
pub use trace::{PhotonBuffers, VolumeRecord, power_unit, trace_photons};

use crate::scene::Scene;

/// How the camera pass estimates light scattered in media from the volume photons.
///
/// (The variants' doc comments are `--volume-estimate`'s help; clap names them as serde does,
/// `photon-beams` included, which a test holds.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum VolumeEstimate {
    /// Jarosz et al.'s beam radiance estimate: every photon sphere the camera ray crosses
    /// counts, and the ray goes on to the surface behind (see docs/volumes.md).
    #[default]
    Beam,
    /// The point estimate at one sampled collision, where the camera path ends.
    Point,
    /// Photon beams: every photon flight that passes the camera ray counts, with a 1D kernel,
    /// and the ray goes on to the surface behind (see docs/volumes.md).
    #[serde(rename = "photon-beams")]
    PhotonBeams,
}

impl VolumeEstimate {
    /// Dimension of the estimate's kernel, which Knaus and Zwicker's schedule shrinks: the
    /// beam's kernel spreads across the ray only (2), the point's in space (3).
    pub fn kernel_dimension(self) -> u32 {
        match self {
            VolumeEstimate::Beam => 2,
            VolumeEstimate::Point => 3,
            VolumeEstimate::PhotonBeams => 1,
        }
    }

    /// The initial volume radius over the surface radius when neither the scene nor the user
    /// gives one. The beam's kernel blurs across the ray as the surface kernel does across the
    /// image, and its cost grows as r² along every ray: half the surface radius had the lowest
    /// equal-time error on fog.xml (of 2, 1, 0.5 and 0.25; docs/volumes.md). The point estimate
    /// gathers in a ball at one point and keeps 2. Photon beams blur across two lines, and so
    /// few are kept that a wider kernel pays: 2 beat 0.5 and 4 on `scenes/volumetric.xml`
    /// (see [`BEAM_SHARE`]).
    pub fn default_radius_ratio(self) -> f32 {
        match self {
            VolumeEstimate::Beam => 0.5,
            VolumeEstimate::Point => 2.0,
            VolumeEstimate::PhotonBeams => 2.0,
        }
    }
}

/// Photons per iteration over the photons whose flights are kept as photon beams. A beam lights
/// every camera ray it passes, so a few hundred per iteration light a whole image, and each
/// costs every ray it passes; more iterations of fewer beams also shrink the surface radius
/// sooner. On `scenes/volumetric.xml` (50,000 photons, 40 s at 240×160, RMSE against a
/// 15-minute render): 1/16 → 0.0239 (radius ratio 0.5), 1/64 → 0.0213 (0.5) and 0.0169 (2),
/// 1/128 → 0.0150 (2), 1/256 → 0.0128 (2) and 0.0147 (4), 1/1024 → 0.0125 (4), within the
/// run-to-run noise of 1/256. On fog.xml (20,000 photons, 20 s) 1/256 and 1/64 both reach the
/// reference's own noise.
pub const BEAM_SHARE: u64 = 256;

/// SPPM's parameters.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SppmSettings {
    /// Photons emitted per iteration.
    pub photons: u64,
    /// Radius of the first iteration, in scene units.
    pub initial_radius: f32,
    /// Knaus and Zwicker's α in (0, 1).
    pub alpha: f64,
    /// Cone filter parameter k ≥ 1.
    pub k: f32,
    /// Initial volume radius over the initial surface radius.
    pub volume_radius_ratio: f32,
    /// The volume estimator.
    #[serde(default)]
    pub volume_estimate: VolumeEstimate,
    /// Longest photon path and longest camera path (None: Russian roulette decides).
    pub max_depth: Option<u32>,
    /// Depth from which the camera path's Russian roulette applies.
    pub rr_depth: u32,
}

/// Why SPPM parameters were refused.
#[derive(Debug, thiserror::Error)]
pub enum SppmError {
    /// α outside (0, 1).
    #[error("alpha must lie strictly between 0 and 1, not {0}")]
    Alpha(f64),
    /// No photons.
    #[error("the photon count per iteration must be at least 1")]
    Photons,
    /// A radius that is not a positive number.
    #[error("the initial radius must be a positive number of scene units, not {0}")]
    Radius(f32),
    /// k below 1.
    #[error("the cone filter's k must be at least 1, not {0}")]
    K(f32),
    /// A volume radius ratio that is not a positive number.
    #[error("the volume radius ratio must be a positive number, not {0}")]
    VolumeRatio(f32),
    /// Photon beams asked for in a scene whose media vary in density.
    #[error(
        "the photon-beams volume estimate follows photon flights in closed form, which needs media of constant density, and this scene has a medium whose density varies: use --volume-estimate beam (the default) or point"
    )]
    VaryingDensity,
}

/// Whether every medium of the scene has the same density everywhere (what photon beams need).
fn densities_are_constant(scene: &Scene) -> bool {
    scene.media.iter().all(|m| m.density().is_none())
}

impl SppmSettings {
    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), SppmError> {
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(SppmError::Alpha(self.alpha));
        }
        if self.photons == 0 {
            return Err(SppmError::Photons);
        }
        if !(self.initial_radius > 0.0 && self.initial_radius.is_finite()) {
            return Err(SppmError::Radius(self.initial_radius));
        }
        if !(self.k >= 1.0 && self.k.is_finite()) {
            return Err(SppmError::K(self.k));
        }
        if !(self.volume_radius_ratio > 0.0 && self.volume_radius_ratio.is_finite()) {
            return Err(SppmError::VolumeRatio(self.volume_radius_ratio));
        }
        Ok(())
    }

    /// Checks the volume estimate against the scene's media: photon beams need media of
    /// constant density.
    pub fn validate_for(&self, scene: &Scene) -> Result<(), SppmError> {
        if self.volume_estimate == VolumeEstimate::PhotonBeams && !densities_are_constant(scene) {
            return Err(SppmError::VaryingDensity);
        }
        Ok(())
    }

    /// Settings from the scene's `<integrator>`: Mitsuba's `photon_count`, `initial_radius` (0 or
    /// absent: [`default_radius`]) and `alpha`, our `k`, and `max_depth` and `rr_depth`.
    pub fn from_scene(scene: &Scene) -> SppmSettings {
        let decl = &scene.integrator;
        let estimate = VolumeEstimate::default();
        let mut s = SppmSettings {
            photons: default_photons(scene),
            initial_radius: 0.0,
            alpha: 2.0 / 3.0,
            k: 1.1,
            volume_radius_ratio: estimate.default_radius_ratio(),
            volume_estimate: estimate,
            max_depth: u32::try_from(decl.max_depth).ok(),
            rr_depth: decl.rr_depth,
        };
        if let crate::scene::MethodParams::Sppm(p) = &decl.params {
            s.photons = p.photon_count.unwrap_or(s.photons);
            s.initial_radius = p.initial_radius.unwrap_or(s.initial_radius);
            s.alpha = p.alpha.unwrap_or(s.alpha);
            s.k = p.k.unwrap_or(s.k);
            s.volume_radius_ratio = p.volume_radius_ratio.unwrap_or(s.volume_radius_ratio);
        }
        if s.initial_radius <= 0.0 {
            s.initial_radius = default_radius(scene);
        }
        s
    }

    /// These settings with volume estimate `estimate`, and its default volume radius ratio
    /// (for a caller that did not choose a ratio).
    pub fn with_volume_estimate(self, estimate: VolumeEstimate) -> SppmSettings {
        SppmSettings {
            volume_estimate: estimate,
            volume_radius_ratio: estimate.default_radius_ratio(),
            ..self
        }
    }

    /// What the photon pass keeps in media for this estimate.
    pub fn volume_record(&self) -> VolumeRecord {
        match self.volume_estimate {
            VolumeEstimate::Beam | VolumeEstimate::Point => VolumeRecord::Points,
            VolumeEstimate::PhotonBeams => VolumeRecord::Beams(self.photons.div_ceil(BEAM_SHARE)),
        }
    }

    /// The surface radius schedule (r² shrinks).
    pub fn schedule(&self) -> RadiusSchedule {
        RadiusSchedule {
            initial: self.initial_radius as f64,
            alpha: self.alpha,
            dimension: 2,
        }
    }

    /// The volume radius schedule, from `volume_radius_ratio` times the surface radius: r² shrinks
    /// for the beam estimate, r³ for the point estimate.
    pub fn volume_schedule(&self) -> RadiusSchedule {
        RadiusSchedule {
            initial: self.initial_radius as f64 * self.volume_radius_ratio as f64,
            alpha: self.alpha,
            dimension: self.volume_estimate.kernel_dimension(),
        }
    }

    /// (surface, volume) radii of iterations `range`.
    pub fn radii(&self, range: std::ops::Range<u64>) -> Vec<[f32; 2]> {
        let surface = self.schedule().radii(range.clone());
        let volume = self.volume_schedule().radii(range);
        surface.into_iter().zip(volume).map(|(s, v)| [s, v]).collect()
    }
}

/// The default photons per iteration: a quarter of the pixel count (16,384 at 256×256), at
/// least [`MIN_PHOTONS`]. An iteration is a photon pass and a camera pass of one path per pixel
/// (direct light, gather); at this share the two cost about the same on a diffuse box, and more
/// photons buy fewer iterations, so fewer direct-light samples and a radius that shrinks
/// later. Equal-time RMSE after 30 s at 256×256 against Mitsuba's references (docs/sppm.md):
/// cbox 0.0089, 0.0063, 0.0065, 0.0065, 0.0105 and cbox-spheres 0.0100, 0.0078, 0.0079,
/// 0.0091, 0.0140 with 3,125, 12,500, 25,000, 50,000 and 200,000 photons (the former default);
/// our path tracer 0.0083 and 0.0192.
pub fn default_photons(scene: &Scene) -> u64 {
    (scene.width() as u64 * scene.height() as u64 / 4).max(MIN_PHOTONS)
}

/// Fewest default photons per iteration (the count at 256×256): below it, what an iteration
/// costs besides tracing photons (the camera pass, building the maps, starting the threads)
/// leaves fewer photons barely more iterations. At 128×128 (30 s, seed 1, docs/sppm.md),
/// 8,192 photons ran 4,801 iterations of the caustic scene where 4,096 ran 4,951, and 16,384
/// lowered the RMSE against 4,096 on every scene tried: caustic 0.00364 against 0.00461,
/// textures (96²) 0.00114 against 0.00124, environment (64²) 0.01113 against 0.01141, lights
/// 0.01220 against 0.01228, fog (64²) 0.00367 against 0.00373 (its reference's noise).
pub const MIN_PHOTONS: u64 = 16_384;

/// The default initial radius: three pixel footprints at the median distance of what the camera
/// sees, so that it follows the scene's scale and the image's resolution but not geometry out
/// of view. Falls back to the scene's size over the resolution if the camera sees nothing.
pub fn default_radius(scene: &Scene) -> f32 {
    let cam = &scene.camera;
    let n = 16u32;
    let mut dists = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let x = (i * cam.width) / n + cam.width / (2 * n);
            let y = (j * cam.height) / n + cam.height / (2 * n);
            let ray = cam.generate_ray(
                x.min(cam.width - 1),
                y.min(cam.height - 1),
                glam::Vec2::splat(0.5),
                glam::Vec2::splat(0.5),
            );
            if let Some((hit, _)) = scene.intersect(&ray) {
                dists.push(hit.t);
            }
        }
    }
    let extent = cam.width.max(cam.height) as f32;
    if dists.is_empty() {
        let diag = scene.bounds().extent().length();
        return if diag > 0.0 && diag.is_finite() {
            3.0 * diag / extent
        } else {
            1.0
        };
    }
    dists.sort_by(f32::total_cmp);
    let median = dists[dists.len() / 2];
    let tan_half = cam.tan_half_x.max(cam.tan_half_y);
    3.0 * 2.0 * median * tan_half / extent
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The names a job's JSON and the docs use.
    #[test]
    fn volume_estimates_have_their_documented_names() {
        for (name, estimate) in [
            ("\"beam\"", VolumeEstimate::Beam),
            ("\"point\"", VolumeEstimate::Point),
            ("\"photon-beams\"", VolumeEstimate::PhotonBeams),
        ] {
            assert_eq!(serde_json::from_str::<VolumeEstimate>(name).unwrap(), estimate);
            assert_eq!(serde_json::to_string(&estimate).unwrap(), name);
            #[cfg(feature = "cli")]
            assert_eq!(
                format!(
                    "\"{}\"",
                    clap::ValueEnum::to_possible_value(&estimate).unwrap().get_name()
                ),
                name
            );
        }
    }
}
