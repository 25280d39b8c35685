//! Feature buffers for a denoiser: per pixel, the albedo and the normal of the first surface a
//! camera ray reaches past mirrors and glass, as Open Image Denoise wants them.
//!
//! Why exact sums like the image's: the farm adds them from any machine in any order, so a job's
//! features, like its image, depend only on (seed, pass). Why a walk of their own rather than a
//! record kept by each integrator: one definition serves the path tracer, SPPM's camera pass
//! and the particle tracer alike, and a render that does not ask for features pays nothing.
//! The walk starts from each pixel's camera sample of the pass (same ray, same film position,
//! so the features are filtered as the image is) and costs about one ray per pixel.
//!
//! The albedo is the expected weight of a BSDF sample at that surface (its directional
//! albedo): one sample's weight is an unbiased estimate, exact for a Lambertian surface, so no
//! material needs an albedo function of its own. Emitters and the environment take their
//! radiance, clamped to one, as their albedo. Past a purely specular surface the walk goes on
//! and the albedo carries the specular weight (a tinted mirror darkens what it shows). Normals,
//! in world space and facing the ray, are stored as (n + 1) / 2 so that their sums stay
//! non-negative like every other film's; the mean decodes exactly.
//!
//! A third sum, `emitted`, holds the emission the camera ray itself finds (a light or the
//! environment seen directly, with nothing in between): every integrator adds exactly that to
//! the pixel along the same ray, with no noise. The denoiser is given the image without it and
//! it is added back after, so that lights keep their exact values and outlines (OIDN moved a
//! directly seen light's pixels by 3%, which alone made cbox's RMSE three times the raw one's).
//!
//! What is added back is a fourth sum, `emitted_dense`: the same emission, from
//! [`DENSE_SAMPLES`] more camera rays per pixel and pass, all points of one low-discrepancy
//! sequence across passes. Where a light covers a pixel in part, the image's own rays give that
//! coverage with the noise of one sample a pass; it was 91% of the denoised error left on cbox
//! (docs/denoising.md). These rays only look for emission at their first hit, so they cost
//! less than the path's, and only in scenes whose lights or environment can be seen.

use std::path::Path;

use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::engine::lanes::{F8, LANES, M8, V8};
use crate::film::{FilmError, FilmSum, is_exr, write_exr_layers, write_image};
use crate::geometry::{Ray, Rays8};
use crate::integrator::walk::{Event, Walk};
use crate::sampling::Sampler;
use crate::scene::Scene;

/// Camera rays per pixel and pass for [`Features::emitted_dense`] (docs/denoising.md has the
/// measurements behind four).
pub const DENSE_SAMPLES: u32 = 4;

/// Specular bounces a feature walk follows before it gives up (a ray caught between two
/// mirrors): past it the pixel's features are zero, as for a ray that leaves the scene.
const MAX_SPECULAR_BOUNCES: u32 = 16;

/// The summed features of a range of passes.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Features {
    /// Albedo in [0, 1].
    pub albedo: FilmSum,
    /// Normals encoded as (n + 1) / 2.
    pub normal: FilmSum,
    /// Emission seen directly by the image's own camera ray: what the denoiser is not given.
    pub emitted: FilmSum,
    /// The same emission from [`DENSE_SAMPLES`] rays a pass: what is added back after.
    pub emitted_dense: FilmSum,
}

impl Features {
    /// Empty sums.
    pub fn new(width: u32, height: u32) -> Features {
        Features {
            albedo: FilmSum::new(width, height),
            normal: FilmSum::new(width, height),
            emitted: FilmSum::new(width, height),
            emitted_dense: FilmSum::new(width, height),
        }
    }

    /// The names of the sums, in the order of [`Features::sums`].
    pub const NAMES: [&str; 4] = ["albedo", "normal", "emitted", "emitted_dense"];

    /// The sums, named by [`Features::NAMES`] (for files and messages that hold them apart).
    pub fn sums(&self) -> [&FilmSum; 4] {
        [&self.albedo, &self.normal, &self.emitted, &self.emitted_dense]
    }

    /// The sums, mutable, in the order of [`Features::NAMES`].
    pub fn sums_mut(&mut self) -> [&mut FilmSum; 4] {
        [
            &mut self.albedo,
            &mut self.normal,
            &mut self.emitted,
            &mut self.emitted_dense,
        ]
    }

    /// Features from their sums, in the order of [`Features::NAMES`].
    pub fn from_sums([albedo, normal, emitted, emitted_dense]: [FilmSum; 4]) -> Features {
        Features {
            albedo,
            normal,
            emitted,
            emitted_dense,
        }
    }

    /// Adds another range's features: exact, in any order.
    pub fn add(&mut self, other: &Features) -> Result<(), FilmError> {
        for (mine, theirs) in self.sums_mut().into_iter().zip(other.sums()) {
            mine.add(theirs)?;
        }
        Ok(())
    }

    /// The mean albedo per pixel.
    pub fn albedo_image(&self) -> Result<Vec<Rgb>, FilmError> {
        self.albedo.image()
    }

    /// The mean normal per pixel (not normalised: where a pixel sees two surfaces, its normal
    /// is shorter, as a denoiser expects of an antialiased feature).
    pub fn normal_image(&self) -> Result<Vec<Rgb>, FilmError> {
        Ok(self
            .normal
            .image()?
            .into_iter()
            .map(|m| 2.0 * m - Rgb::ONE)
            .collect())
    }
}

/// Writes `image` to `path` as [`write_image`] does, with the features as channels when there
/// are some and the file is an EXR (a PNG has no room for them).
pub fn write_image_with_features(
    image: &[Rgb],
    width: u32,
    height: u32,
    features: Option<&Features>,
    path: &Path,
) -> Result<(), FilmError> {
    match features {
        Some(f) if is_exr(path) => write_exr_with_features(image, f, path),
        _ => write_image(image, width, height, path),
    }
}

/// Writes `image` and its features as one EXR: the image as channels R, G and B, the
/// features as `albedo.R` … `normal.B` ([`write_exr_layers`]).
pub fn write_exr_with_features(image: &[Rgb], features: &Features, path: &Path) -> Result<(), FilmError> {
    let (w, h) = (features.albedo.width, features.albedo.height);
    let (albedo, normal) = (features.albedo_image()?, features.normal_image()?);
    write_exr_layers(
        w,
        h,
        &[("", image), ("albedo.", &albedo), ("normal.", &normal)],
        path,
    )
}

/// One camera ray's sample of each feature.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sample {
    pub albedo: Rgb,
    /// Encoded as (n + 1) / 2.
    pub normal: Rgb,
    pub emitted: Rgb,
}

impl Sample {
    /// What a ray that finds nothing gives.
    const NONE: Sample = Sample {
        albedo: Rgb::ZERO,
        normal: Rgb::splat(0.5),
        emitted: Rgb::ZERO,
    };
}

/// The emission an integrator adds along the camera ray as it is: found before any bounce
/// or medium changed the throughput.
fn direct(walk: &Walk, le: Rgb) -> Rgb {
    if walk.depth == 0 && walk.beta == Rgb::ONE {
        le
    } else {
        Rgb::ZERO
    }
}

/// The emission camera ray `ray` finds directly: a [`Sample`]'s `emitted`, without the rest
/// of the walk (for [`Features::emitted_dense`]).
pub(crate) fn direct_emission(scene: &Scene, ray: Ray, sampler: &mut Sampler) -> Rgb {
    let mut walk = Walk::new(ray, Rgb::ONE, scene.camera_medium);
    match walk.next_event(scene, sampler) {
        Event::Gone => direct(&walk, walk.escaped(scene)),
        Event::Medium { .. } => Rgb::ZERO,
        Event::Surface(hit) => direct(&walk, walk.emission(scene, &hit)),
    }
}

/// [`direct_emission`] of up to [`LANES`] camera rays, traced as one packet (camera rays are
/// coherent: a packet costs less than its rays one by one). Only a lane that meets a light, a
/// medium boundary or an instance, or a scene whose camera sits in a medium, takes the walk:
/// every other lane's answer (nothing, or the environment) is what the walk would give.
#[inline(always)]
pub(crate) fn direct_emission8(scene: &Scene, rays: &[Ray], samplers: &mut [Sampler]) -> [Rgb; LANES] {
    let mut out = [Rgb::ZERO; LANES];
    if scene.camera_medium.is_some() {
        for ((o, ray), sampler) in out.iter_mut().zip(rays).zip(samplers) {
            *o = direct_emission(scene, *ray, sampler);
        }
        return out;
    }
    let lane = |i: usize, f: fn(&Ray) -> glam::Vec3A, c: usize| rays.get(i).map_or(0.0, |r| f(r)[c]);
    let v8 = |f: fn(&Ray) -> glam::Vec3A| V8 {
        x: F8::from_fn(|i| lane(i, f, 0)),
        y: F8::from_fn(|i| lane(i, f, 1)),
        z: F8::from_fn(|i| lane(i, f, 2)),
    };
    let hits = scene.bvh.intersect8(&Rays8 {
        o: v8(|r| r.o),
        d: v8(|r| r.d),
        t_max: F8::splat(f32::INFINITY),
        active: M8::from_fn(|i| i < rays.len()),
    });
    for (i, (ray, sampler)) in rays.iter().zip(samplers).enumerate() {
        out[i] = match hits.hit(i) {
            None => Walk::new(*ray, Rgb::ONE, None).escaped(scene),
            Some(h) => {
                let shape = scene.bvh.primitives()[h.prim as usize].shape();
                let plain = scene
                    .shapes
                    .get(shape as usize)
                    .is_some_and(|s| s.light.is_none() && !scene.bsdfs[s.bsdf as usize].is_null());
                if plain {
                    Rgb::ZERO
                } else {
                    direct_emission(scene, *ray, sampler)
                }
            }
        };
    }
    out
}

/// The features' sample of one camera ray; `sampler` goes on from the camera sample.
pub(crate) fn sample(scene: &Scene, ray: Ray, sampler: &mut Sampler) -> Sample {
    let mut walk = Walk::new(ray, Rgb::ONE, scene.camera_medium);
    for _ in 0..=MAX_SPECULAR_BOUNCES {
        match walk.next_event(scene, sampler) {
            // An environment seen: its radiance, clamped, marks it apart from the surfaces.
            Event::Gone => {
                let le = walk.escaped(scene);
                return Sample {
                    albedo: clamp01(le),
                    emitted: direct(&walk, le),
                    ..Sample::NONE
                };
            }
            // Fog: the medium's albedo, and the normal of a surface facing the ray.
            Event::Medium { p, medium, .. } => {
                return Sample {
                    albedo: clamp01(walk.beta * scene.media[medium as usize].albedo_at(p)),
                    normal: encode(-walk.ray.d),
                    ..Sample::NONE
                };
            }
            Event::Surface(hit) => {
                let n = hit.frame.n;
                let normal = encode(if n.dot(hit.wo) < 0.0 { -n } else { n });
                // An emitter's albedo is its radiance, clamped (as Yocto's and others' are): its
                // outline then stands out from the surface it sits in, which a denoiser keeps
                // sharp.
                let le = walk.emission(scene, &hit);
                if le != Rgb::ZERO {
                    return Sample {
                        albedo: clamp01(le),
                        normal,
                        emitted: direct(&walk, le),
                    };
                }
                let Some(bs) = Walk::sample_bsdf(&hit, sampler, TransportMode::Radiance) else {
                    return Sample {
                        normal,
                        ..Sample::NONE
                    };
                };
                if hit.bsdf.has_smooth() {
                    return Sample {
                        albedo: clamp01(walk.beta * bs.weight),
                        normal,
                        ..Sample::NONE
                    };
                }
                walk.follow(&hit, &bs);
            }
        }
    }
    Sample::NONE
}

fn clamp01(c: Rgb) -> Rgb {
    if c.is_finite() {
        c.clamp(Rgb::ZERO, Rgb::ONE)
    } else {
        Rgb::ZERO
    }
}

fn encode(n: glam::Vec3A) -> Rgb {
    0.5 * (n.normalize_or_zero() + Rgb::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same image and features give the same file, every time: the farm and a local
    /// render compare EXRs byte for byte. (With the crate's unsorted parallel chunks they did
    /// not: about one write in three differed.)
    #[test]
    fn the_exr_with_features_has_the_same_bytes_every_time() {
        let (w, h) = (256u32, 192u32);
        let image: Vec<Rgb> = (0..w * h)
            .map(|i| Rgb::new((i % 7) as f32, (i % 13) as f32 * 0.1, (i % 101) as f32 * 0.37))
            .collect();
        let mut features = Features::new(w, h);
        for s in features.sums_mut() {
            s.passes = 1;
            for (i, p) in s.sums.iter_mut().enumerate() {
                *p = [(i * 31 % 1000) as i64, (i * 17 % 500) as i64, i as i64];
            }
        }
        let dir = std::env::temp_dir().join(format!("pf-features-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bytes: Vec<Vec<u8>> = (0..12)
            .map(|k| {
                let path = dir.join(format!("{k}.exr"));
                write_exr_with_features(&image, &features, &path).unwrap();
                std::fs::read(&path).unwrap()
            })
            .collect();
        let _ = std::fs::remove_dir_all(&dir);
        assert!(bytes.windows(2).all(|p| p[0] == p[1]));
        // And the image reads back as written, through the image crate as any viewer would.
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("back.exr");
        write_exr_with_features(&image, &features, &path).unwrap();
        let (rw, rh, back) = crate::film::read_image(&path).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!((rw, rh), (w, h));
        assert_eq!(back, image);
    }
}
