//! The scene: what the Mitsuba 3 XML describes, ready to render.
//!
//! Loading happens in named steps: read the XML with its parameters ([`xml`]), check and read
//! each element's parameters ([`props`]), and build shapes, materials, lights and the camera
//! ([`build`]). Anything outside the supported subset is an error that names the file, line and
//! element.

mod build;
mod curves;
mod error;
mod mesh;
mod named;
mod props;
mod spectrum;
mod transform;
mod xml;

pub use error::SceneError;
pub use props::FileRoot;

use std::path::{Path, PathBuf};

use glam::Vec3A;

use crate::bsdf::Bsdf;
use crate::camera::Camera;
use crate::geometry::{Aabb, Bvh, Hit, Ray, SurfacePoint, offset_ray_origin};
use crate::light::{Light, LightSample};
use crate::sampling::Distribution1D;

/// What a shape is made of.
#[derive(Clone, Debug)]
pub struct ShapeInfo {
    /// The shape's id, or its type and position in the file.
    pub name: String,
    /// Index into [`Scene::bsdfs`].
    pub bsdf: u32,
    /// Index into [`Scene::lights`] if the shape emits.
    pub light: Option<u32>,
    /// Medium inside the shape (index into [`Scene::media`]).
    pub interior: Option<u32>,
    /// Medium outside the shape.
    pub exterior: Option<u32>,
}

impl ShapeInfo {
    /// The medium a ray is in after leaving this surface in direction `d` (geometric normal
    /// `ng`), coming from `current`. As in Mitsuba, only shapes that declare a medium change it.
    pub fn medium_after(&self, d: Vec3A, ng: Vec3A, current: Option<u32>) -> Option<u32> {
        if self.interior.is_none() && self.exterior.is_none() {
            return current;
        }
        if d.dot(ng) < 0.0 {
            self.interior
        } else {
            self.exterior
        }
    }
}

/// The `<integrator>` element: the method is chosen on the command line, but its parameters
/// are read here.
#[derive(Clone, Debug)]
pub struct IntegratorDecl {
    /// The method of ours that renders the declared type (`volpath` renders with `path`).
    pub kind: crate::job::Integrator,
    /// Longest path, in Mitsuba's meaning (1: emitters seen directly; -1: unlimited).
    pub max_depth: i32,
    /// Depth from which Russian roulette may end paths.
    pub rr_depth: u32,
    /// The parameters only the declared method reads.
    pub params: MethodParams,
}

/// The parameters of an `<integrator>` that only its method reads, typed from the XML on: an
/// unknown one is an error at load, as everywhere else in a scene (they used to travel as
/// name-value pairs, read by name in four places, so a typo was only a warning).
#[derive(Clone, Debug, Default, PartialEq)]
pub enum MethodParams {
    /// The method has none.
    #[default]
    None,
    /// `direct`: samples of each strategy per hit (Mitsuba's `emitter_samples` and
    /// `bsdf_samples`, or `shading_samples` for both).
    Direct {
        /// Emitter samples.
        emitter_samples: u32,
        /// BSDF samples.
        bsdf_samples: u32,
    },
    /// `sppm`.
    Sppm(SppmParams),
}

/// An `sppm` integrator's parameters, each None where the scene does not give it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SppmParams {
    /// Photons per iteration (Mitsuba's `photon_count`).
    pub photon_count: Option<u64>,
    /// The first iteration's gather radius (`initial_radius`; 0: from the scene's size).
    pub initial_radius: Option<f32>,
    /// How fast the radius shrinks (`alpha`).
    pub alpha: Option<f64>,
    /// Ours: the radius schedule's `k`.
    pub k: Option<f32>,
    /// Ours: the volume radius over the surface radius.
    pub volume_radius_ratio: Option<f32>,
    /// Ours: the iterations to render when the command line does not say.
    pub iterations: Option<f64>,
}

/// A loaded scene.
#[derive(Debug)]
pub struct Scene {
    /// The file it came from.
    pub source: PathBuf,
    /// Geometry.
    pub bvh: Bvh,
    /// Per-shape materials and emitters.
    pub shapes: Vec<ShapeInfo>,
    /// Materials.
    pub bsdfs: Vec<Bsdf>,
    /// Lights.
    pub lights: Vec<Light>,
    /// The medium each light emits into (photons start there), by light index.
    pub light_media: Vec<Option<u32>>,
    /// Participating media.
    pub media: Vec<crate::medium::Medium>,
    /// The medium the camera is in.
    pub camera_medium: Option<u32>,
    /// Chooses a light in proportion to its power: where photons start.
    pub light_selection: Distribution1D,
    /// Chooses a light for next-event estimation: uniformly among those that emit, as Mitsuba
    /// does. (By power, a bright light outside the view would take nearly every sample from the
    /// dim ones that light what is seen, as in Veach's scene of four lights.)
    pub light_sampling: Distribution1D,
    /// The sensor.
    pub camera: Camera,
    /// The film's reconstruction filter.
    pub filter: crate::filter::Filter,
    /// The sampler's `sample_count`: default samples per pixel.
    pub spp: u32,
    /// The integrator's parameters.
    pub integrator: IntegratorDecl,
    /// Things the user should know that do not stop the render.
    pub warnings: Vec<String>,
    /// Files the scene reads besides itself (included XML, meshes), resolved and absolute:
    /// what a job bundle must carry.
    pub files: Vec<PathBuf>,
    /// How many shapes have a null BSDF (shadow rays must look past them).
    pub null_shapes: usize,
    /// The light that rays leaving the scene see (`constant` or `envmap`), if any.
    pub environment: Option<u32>,
}

impl Scene {
    /// Loads a Mitsuba 3 XML scene; `defines` are `-D name=value` overrides. Files resolve as
    /// in Mitsuba, wherever they are: for the user's own scenes on their own machine.
    pub fn load(path: &Path, defines: &[(String, String)]) -> Result<Scene, SceneError> {
        build::load(path, defines, FileRoot::Anywhere)
    }

    /// Loads a scene whose every file must lie inside `root`: a job bundle's folder.
    pub fn load_inside(path: &Path, defines: &[(String, String)], root: &Path) -> Result<Scene, SceneError> {
        build::load(path, defines, FileRoot::Inside(root.to_path_buf()))
    }

    /// Loads a scene from text, with `path` naming it in errors and anchoring file names.
    pub fn from_str(text: &str, path: &Path, defines: &[(String, String)]) -> Result<Scene, SceneError> {
        build::from_str(text, path, defines, FileRoot::Anywhere)
    }

    /// Image width.
    pub fn width(&self) -> u32 {
        self.camera.width
    }

    /// Image height.
    pub fn height(&self) -> u32 {
        self.camera.height
    }

    /// Bounds of all geometry.
    pub fn bounds(&self) -> Aabb {
        self.bvh.bounds()
    }

    /// The first surface along the ray.
    pub fn intersect(&self, ray: &Ray) -> Option<(Hit, SurfacePoint)> {
        let hit = self.bvh.intersect(ray, f32::INFINITY)?;
        let sp = self.bvh.primitives()[hit.prim as usize].surface(ray, &hit);
        Some((hit, sp))
    }

    /// A ray leaving surface point `sp` in direction `w`.
    pub fn spawn_ray(sp: &SurfacePoint, w: Vec3A) -> Ray {
        Ray::new(offset_ray_origin(sp.p, sp.p_err, sp.ng, w), w)
    }

    /// Continues a path across a null surface (a medium boundary) at `sp`: the ray beyond it and
    /// the medium it enters. `crossings` counts the path's crossings; None once there have been
    /// too many (a path trapped between coincident boundaries), which ends the path.
    pub fn cross_boundary(
        &self,
        sp: &SurfacePoint,
        d: Vec3A,
        medium: Option<u32>,
        crossings: &mut u32,
    ) -> Option<(Ray, Option<u32>)> {
        /// Boundaries one path may cross: far more than any scene nests, bounded all the same.
        const MAX_CROSSINGS: u32 = 1024;
        *crossings += 1;
        if *crossings > MAX_CROSSINGS {
            return None;
        }
        let shape = &self.shapes[sp.shape as usize];
        Some((Self::spawn_ray(sp, d), shape.medium_after(d, sp.ng, medium)))
    }

    /// The fraction of light that travels from the sampled light point to `sp` (a surface, or
    /// a point in a medium with zero error and normal), starting in `medium` at `sp`: zero if a
    /// surface blocks it, the media's transmittance otherwise. Null surfaces (medium
    /// boundaries) are crossed, changing the medium. Heterogeneous media estimate their
    /// transmittance with random numbers from `sampler`; nothing else draws any.
    pub fn transmittance(
        &self,
        sp: &SurfacePoint,
        ls: &LightSample,
        mut medium: Option<u32>,
        sampler: &mut crate::sampling::Sampler,
    ) -> crate::color::Rgb {
        use crate::color::Rgb;
        let mut o = offset_ray_origin(sp.p, sp.p_err, sp.ng, ls.wi);
        let target = if ls.n == Vec3A::ZERO {
            ls.p
        } else {
            offset_ray_origin(ls.p, ls.p_err, ls.n, o - ls.p)
        };
        let mut tr = Rgb::ONE;
        // Bounded, in case of pathological geometry: 64 boundaries between a point and a light.
        for _ in 0..64 {
            let d = target - o;
            let len = d.length();
            // Stop just short of the target so the light's own surface does not count.
            let hit = if self.media.is_empty() && self.null_shapes == 0 {
                if self.bvh.occluded(&Ray::new(o, d), 1.0 - 1e-4) {
                    return Rgb::ZERO;
                }
                None
            } else {
                self.bvh.intersect(&Ray::new(o, d), 1.0 - 1e-4)
            };
            // The medium's stretch, with a unit direction.
            let unit = Ray::new(o, d / len);
            let Some(hit) = hit else {
                if let Some(m) = medium {
                    tr *= self.media[m as usize].transmittance_along(&unit, len, sampler);
                }
                return tr;
            };
            let prim = &self.bvh.primitives()[hit.prim as usize];
            let surface = prim.surface(&Ray::new(o, d), &hit);
            let shape = &self.shapes[surface.shape as usize];
            let bsdf = &self.bsdfs[shape.bsdf as usize];
            if !bsdf.is_null() {
                return Rgb::ZERO;
            }
            tr *= bsdf.null_transmission(surface.tex());
            if let Some(m) = medium {
                tr *= self.media[m as usize].transmittance_along(&unit, hit.t * len, sampler);
            }
            medium = shape.medium_after(d, surface.ng, medium);
            o = offset_ray_origin(surface.p, surface.p_err, surface.ng, d);
        }
        Rgb::ZERO
    }

    /// Picks a light by power and samples it from `p`; the pdf includes the choice.
    pub fn sample_light(&self, p: Vec3A, u_select: f32, u: glam::Vec2) -> Option<(u32, LightSample)> {
        let (i, pmf) = self.pick_light(u_select)?;
        self.sample_picked_light(i, pmf, p, u)
    }

    /// Picks a light by power, as [`Scene::sample_light`] does: its index and probability. For
    /// callers that choose where to sample it from after knowing which light it is.
    pub fn pick_light(&self, u_select: f32) -> Option<(u32, f32)> {
        if self.light_sampling.is_empty() {
            return None;
        }
        let (i, pmf, _) = self.light_sampling.sample(u_select);
        Some((i as u32, pmf))
    }

    /// Samples light `i`, picked with probability `pmf`, from `p`; the pdf includes the choice.
    pub fn sample_picked_light(
        &self,
        i: u32,
        pmf: f32,
        p: Vec3A,
        u: glam::Vec2,
    ) -> Option<(u32, LightSample)> {
        let mut ls = self.lights[i as usize].sample_li(p, self.bvh.primitives(), u)?;
        ls.pdf *= pmf;
        Some((i, ls))
    }

    /// [`Scene::sample_picked_light`] from each point `p[l]` with `u[l]`, where given, several
    /// at once ([`Light::sample_li_each`]).
    pub fn sample_picked_light_each<const N: usize>(
        &self,
        i: u32,
        pmf: f32,
        p: [Vec3A; N],
        u: [Option<glam::Vec2>; N],
    ) -> [Option<LightSample>; N] {
        self.lights[i as usize]
            .sample_li_each(p, self.bvh.primitives(), u)
            .map(|ls| {
                ls.map(|mut ls| {
                    ls.pdf *= pmf;
                    ls
                })
            })
    }

    /// Radiance that a ray leaving the scene along `d` finds, and the density with which
    /// [`Scene::sample_light`] would have chosen that direction.
    pub fn environment_at(&self, d: Vec3A) -> Option<(crate::color::Rgb, f32)> {
        self.environment_at_each([Some(d)])[0]
    }

    /// [`Scene::environment_at`] of each direction given, several at once
    /// ([`Light::environment_each`]); none where no direction is given or there is no
    /// environment.
    pub fn environment_at_each<const N: usize>(
        &self,
        d: [Option<Vec3A>; N],
    ) -> [Option<(crate::color::Rgb, f32)>; N] {
        let Some(i) = self.environment else {
            return [None; N];
        };
        let pmf = self.light_sampling.pmf(i as usize);
        let found = self.lights[i as usize].environment_each(d);
        std::array::from_fn(|l| d[l].map(|_| (found[l].0, pmf * found[l].1)))
    }

    /// Whether a camera ray can see a light (an area light or an environment): points, spots,
    /// beams and the sun cannot be seen, only their light.
    pub fn has_visible_lights(&self) -> bool {
        self.environment.is_some() || self.lights.iter().any(|l| matches!(l, Light::Area(_)))
    }

    /// Whether any material can reflect or refract specularly (see [`Bsdf::has_delta`]).
    pub fn has_specular_surfaces(&self) -> bool {
        self.bsdfs.iter().any(Bsdf::has_delta)
    }

    /// Density of [`Scene::sample_light`] returning point `sp` on area light `light`, from `p`.
    pub fn light_pdf(&self, light: u32, p: Vec3A, sp: &SurfacePoint) -> f32 {
        match &self.lights[light as usize] {
            Light::Area(a) => self.light_sampling.pmf(light as usize) * a.pdf_li(p, sp.p, sp.ng),
            _ => 0.0,
        }
    }
}
