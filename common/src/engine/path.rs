//! The lane engine's path tracer: triangles in Lambertian or GGX rough plastic materials
//! ([`super::plastic`]), flat or with vertex normals, path-traced as the scalar path tracer
//! does it (`integrator/path.rs`: the same depth, next event estimation weighted by the power
//! heuristic, Russian roulette and random numbers in the same order), but a film row's paths
//! at once, eight per lane group.
//!
//! Each bounce runs in stages over the row's live paths, which stay packed at the front of
//! structure-of-arrays buffers (so lanes stay full as paths end, and loads are contiguous):
//! closest hits (camera rays in eight-ray packets, bounce rays one at a time), shading in lanes
//! (the surface, emission, the light sample, the BSDF sample, roulette), shadow rays (in
//! packets: they head for one light), then compaction. Random numbers come from each path's
//! own scalar [`Sampler`], so a path's numbers do not depend on its lane.
//!
//! Area lights on triangles are sampled in lanes; other lights (environments, points, spots,
//! the sun) by their scalar code, lane by lane, and paths that leave the scene find the
//! environment as `Walk::escaped` does.
//!
//! A path that meets any other surface (a sphere or other analytic shape, another material:
//! glass, mirrors, metals, Beckmann plastics) bounces there in the scalar tracer's own code,
//! lane by lane ([`shade_scalar`]), and goes on in its lane: so the Cornell box with a glass
//! and a mirror sphere runs on the engine, its walls in lanes.
//!
//! What it leaves out, on purpose: media, null surfaces, instances and emitters that are not
//! triangles it shades. [`LaneScene::new`] refuses such scenes, and those
//! that are mostly other surfaces, which the scalar integrators render.

use pulp::WithSimd;

use super::Backend;
use super::lanes::{F8, LANES, M8, V8};
use super::math::sincos_quarter;
use super::plastic::{LanePlastic, NO_PLASTIC, Plastics};
use glam::Vec2;

use crate::bsdf::{Bsdf, Plastic, TransportMode};
use crate::color::Rgb;
use crate::film::FilmSum;
use crate::geometry::{Primitive, Ray, Rays8, Triangle, gamma};
use crate::integrator::direct;
use crate::integrator::path::PathSettings;
use crate::integrator::walk::{Hit, Walk};
use crate::light::{Light, LightSample};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::texture::Param;

/// Why the prototype cannot render a scene.
#[derive(Debug, thiserror::Error)]
#[error("the lane engine does not model this scene: {0}")]
pub struct Unsupported(String);

/// A triangle as the shading stage reads it.
#[derive(Clone, Copy, Debug)]
struct Tri {
    p: [[f32; 3]; 3],
    /// Unit geometric normal (flipped for `flip_normals`).
    ng: [f32; 3],
    /// Vertex normals, if the mesh has them (the shading normal interpolates them); zeros
    /// otherwise (the shading normal is `ng`).
    n: [[f32; 3]; 3],
    /// Whether `n` holds vertex normals.
    smooth: bool,
    /// -1 for `flip_normals`, else 1.
    flip: f32,
    reflectance: [f32; 3],
    /// A two-sided material's reflectance seen from the back.
    back_reflectance: [f32; 3],
    /// Whether the back scatters too (Mitsuba's `twosided`).
    two_sided: bool,
    /// The (front, back) material's index in [`LaneScene::plastics`] if it is a rough
    /// plastic ([`NO_PLASTIC`] if Lambertian); its diffuse reflectance is `reflectance`'s.
    plastic: [u32; 2],
    /// Its (front, back) reflectances in [`LaneScene::textures`] if either is textured
    /// (then `reflectance` and `back_reflectance` are unused), else [`NO_TEXTURE`].
    texture: u32,
    /// Radiance from its front, if it emits.
    emission: [f32; 3],
    /// Probability of picking its light over the light's area: the light sampling density per
    /// unit area of a point on it (zero if it does not emit).
    light_density: f32,
    /// Whether its bounces are shaded by the scalar path tracer's code, lane by lane
    /// ([`shade_scalar`]): an analytic shape, or a material the lanes do not model. Then only
    /// this field is meaningful, and `plastic`, which names none.
    scalar: bool,
}

/// [`Tri::texture`] of a triangle whose reflectances are fixed.
const NO_TEXTURE: u32 = u32::MAX;

impl Tri {
    /// A primitive the scalar code shades.
    const SCALAR: Tri = Tri {
        p: [[0.0; 3]; 3],
        ng: [0.0; 3],
        n: [[0.0; 3]; 3],
        smooth: false,
        flip: 1.0,
        reflectance: [0.0; 3],
        back_reflectance: [0.0; 3],
        two_sided: false,
        plastic: [NO_PLASTIC; 2],
        texture: NO_TEXTURE,
        emission: [0.0; 3],
        light_density: 0.0,
        scalar: true,
    };
}

/// A scene as the lane engine reads it: its triangles flattened for the shading stage, its
/// plastics and textures, and what the path tracer's settings ask; made once per render.
pub struct LaneScene {
    tris: Vec<Tri>,
    /// Textured (front, back) reflectances, looked up lane by lane.
    textures: Vec<(Param<Rgb>, Param<Rgb>)>,
    /// The rough plastics the lanes shade.
    plastics: Vec<LanePlastic>,
    max_depth: u32,
    rr_depth: u32,
}

impl LaneScene {
    /// The scene's triangles, materials and lights, or why the prototype cannot render it with
    /// `settings`.
    pub fn new(scene: &Scene, settings: &PathSettings) -> Result<LaneScene, Unsupported> {
        let no = |why: &str| Err(Unsupported(why.to_string()));
        if !scene.media.is_empty() || scene.null_shapes > 0 {
            return no("the scene has media or null surfaces");
        }
        let prims = scene.bvh.primitives();
        if prims.iter().any(|p| matches!(p, Primitive::Instance(_))) {
            return no("a shape is an instance");
        }
        // Paths meet surfaces about in proportion to their area. Where the lanes would shade
        // less than 60% of it, their overhead outweighs them: a Cornell box of Beckmann plastic
        // walls ran at 1.15x the scalar tracer's time on the engine, the staircase interior
        // (54% Lambertian) at 1.02x while its GGX plastics were shaded by the scalar code
        // (docs/engine.md). Checked before the triangles are copied:
        // that took 51-57 ms on the staircase, on every renderer made (every worker batch).
        let (mut lanes, mut total) = (0.0f64, 0.0f64);
        for (_, prim) in scene.bvh.distinct() {
            let area = prim.area() as f64;
            total += area;
            if lane_shaded(scene, prim).is_some() {
                lanes += area;
            }
        }
        if lanes < 0.6 * total {
            return no("most of the scene's surface is not Lambertian or GGX-plastic triangles");
        }
        let mut tris = Vec::with_capacity(prims.len());
        let mut textures = Vec::new();
        let mut texture_of = std::collections::HashMap::new();
        let mut plastics = Vec::new();
        let mut plastic_of = std::collections::HashMap::new();
        for prim in prims {
            let shape = &scene.shapes[prim.shape() as usize];
            let Some((t, front, back)) = lane_shaded(scene, prim) else {
                // Shaded by the scalar code; what it would find on its surface the lanes do
                // not carry: emission (its MIS needs the previous bounce's point).
                if shape.light.is_some() {
                    return no("an emitter is not a triangle the lanes shade");
                }
                tris.push(Tri::SCALAR);
                continue;
            };
            let two_sided = back.is_some();
            // One entry per material, whatever its triangles.
            let mut plastic = |side: &LaneSide| match side.plastic {
                None => NO_PLASTIC,
                Some(p) => *plastic_of.entry(p as *const Plastic).or_insert_with(|| {
                    plastics.push(LanePlastic::new(p).expect("lane_shaded checked it"));
                    plastics.len() as u32 - 1
                }),
            };
            let plastic = [plastic(&front), back.as_ref().map_or(NO_PLASTIC, &mut plastic)];
            let (front, back) = (front.reflectance, back.map(|b| b.reflectance));
            let fixed = |p: &Param<Rgb>| match p {
                Param::Fixed(r) => Some(r.to_array()),
                Param::Textured(_) => None,
            };
            let (reflectance, back_reflectance, texture) =
                match (fixed(front), back.map_or(Some([0.0; 3]), fixed)) {
                    (Some(f), Some(b)) => (f, b, NO_TEXTURE),
                    // One entry per material, whatever its triangles.
                    _ => {
                        let k = *texture_of.entry(shape.bsdf).or_insert_with(|| {
                            textures.push((front.clone(), back.unwrap_or(front).clone()));
                            textures.len() as u32 - 1
                        });
                        ([0.0; 3], [0.0; 3], k)
                    }
                };
            let (mut emission, mut light_density) = ([0.0; 3], 0.0);
            if let Some(li) = shape.light {
                let Light::Area(a) = &scene.lights[li as usize] else {
                    return no("a shape's light is not an area light");
                };
                let Param::Fixed(radiance) = &a.radiance else {
                    return no("an area light's radiance is a texture");
                };
                emission = radiance.to_array();
                light_density = scene.light_sampling.pmf(li as usize) / a.area;
            }
            let [p0, p1, p2] = t.p;
            let mut ng = (p1 - p0).cross(p2 - p0).normalize_or_zero();
            if t.flip {
                ng = -ng;
            }
            tris.push(Tri {
                p: t.p.map(|p| p.to_array()),
                ng: ng.to_array(),
                n: t.n.as_ref().map_or([[0.0; 3]; 3], |n| n.map(|v| v.to_array())),
                smooth: t.n.is_some(),
                flip: if t.flip { -1.0 } else { 1.0 },
                reflectance,
                back_reflectance,
                two_sided,
                plastic,
                texture,
                emission,
                light_density,
                scalar: false,
            });
        }
        Ok(LaneScene {
            tris,
            textures,
            plastics,
            max_depth: settings.max_depth.unwrap_or(u32::MAX),
            rr_depth: settings.rr_depth,
        })
    }
}

/// A side of a material the lanes shade: Lambertian, or a rough plastic with this diffuse
/// reflectance.
struct LaneSide<'s> {
    reflectance: &'s Param<Rgb>,
    plastic: Option<&'s Plastic>,
}

/// A triangle the lanes shade, with its front and, if two-sided, its back.
type LaneShaded<'s> = (&'s Triangle, LaneSide<'s>, Option<LaneSide<'s>>);

/// The triangle and its (front, back) materials if the lanes shade `prim`: a triangle in a
/// Lambertian material or a GGX rough plastic ([`LanePlastic::new`]), or a two-sided one of
/// two (whose back is shaded with its second BSDF, as the front); `None` for what the scalar
/// code shades.
fn lane_shaded<'s>(scene: &'s Scene, prim: &'s Primitive) -> Option<LaneShaded<'s>> {
    let Primitive::Triangle(t) = prim else {
        return None;
    };
    let side = |b: &'s Bsdf| match b {
        Bsdf::Diffuse(d) => Some(LaneSide {
            reflectance: &d.reflectance,
            plastic: None,
        }),
        Bsdf::Plastic(p) if LanePlastic::models(p) => Some(LaneSide {
            reflectance: &p.diffuse,
            plastic: Some(p),
        }),
        _ => None,
    };
    match &scene.bsdfs[scene.shapes[prim.shape() as usize].bsdf as usize] {
        Bsdf::TwoSided(pair) => Some((t, side(&pair.0)?, Some(side(&pair.1)?))),
        b => Some((t, side(b)?, None)),
    }
}

/// Adds pass `pass` of the path tracer under `seed` to `film`, computed on `backend`.
pub fn render_pass(
    scene: &Scene,
    ds: &LaneScene,
    seed: u64,
    pass: u64,
    backend: Backend,
    film: &mut FilmSum,
) {
    crate::render::add_rows(scene, film, |y| {
        backend.run(Row {
            scene,
            ds,
            seed,
            pass,
            y,
        })
    });
    film.passes += 1;
}

/// One film row's paths: the unit a lane kernel runs on.
struct Row<'a> {
    scene: &'a Scene,
    ds: &'a LaneScene,
    seed: u64,
    pass: u64,
    y: u32,
}

impl WithSimd for Row<'_> {
    type Output = Vec<(Rgb, Vec2)>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Vec<(Rgb, Vec2)> {
        self.trace()
    }
}

/// The live paths of a row, packed at the front, in structure-of-arrays form; `n` of them, the
/// buffers padded to whole lane groups.
struct Paths {
    n: usize,
    pixel: Vec<u32>,
    sampler: Vec<Sampler>,
    o: [Vec<f32>; 3],
    d: [Vec<f32>; 3],
    beta: [Vec<f32>; 3],
    /// Density of the bounce that made the ray (0 for a camera ray or a specular bounce: no
    /// MIS).
    prev_pdf: Vec<f32>,
    /// Product of the relative indices of refraction crossed (`Walk::eta`, for roulette).
    eta: Vec<f32>,
    /// The closest hit of the ray, from the intersection stage.
    t: Vec<f32>,
    b: [Vec<f32>; 2],
    tri: Vec<u32>,
    /// Whether the path goes on after this bounce (false in padding lanes).
    alive: Vec<bool>,
    /// This bounce's shadow ray (origin, direction to the target) and what it carries if
    /// unoccluded.
    shadow_o: [Vec<f32>; 3],
    shadow_d: [Vec<f32>; 3],
    shadow_l: [Vec<f32>; 3],
}

fn lanes3(len: usize) -> [Vec<f32>; 3] {
    std::array::from_fn(|_| vec![0.0; len])
}

impl Row<'_> {
    /// Each pixel's radiance and its sample's offset within the pixel, for the filter.
    #[inline(always)]
    fn trace(&self) -> Vec<(Rgb, Vec2)> {
        let (scene, ds) = (self.scene, self.ds);
        let w = scene.width() as usize;
        let len = w.div_ceil(LANES) * LANES;
        let mut out = vec![Rgb::ZERO; w];
        let mut paths = Paths {
            n: w,
            pixel: (0..w as u32).collect(),
            sampler: Vec::with_capacity(w),
            o: lanes3(len),
            d: lanes3(len),
            beta: std::array::from_fn(|_| vec![1.0; len]),
            prev_pdf: vec![0.0; len],
            eta: vec![1.0; len],
            t: vec![0.0; len],
            b: [vec![0.0; len], vec![0.0; len]],
            tri: vec![0; len],
            alive: vec![false; len],
            shadow_o: lanes3(len),
            shadow_d: lanes3(len),
            shadow_l: lanes3(len),
        };
        // Camera rays (scalar: the sensor is shared with every integrator).
        let mut at = Vec::with_capacity(w);
        for x in 0..w {
            let (ray, u_pixel, sampler) =
                crate::render::camera_sample(scene, self.seed, self.pass, x as u32, self.y);
            at.push(u_pixel);
            paths.sampler.push(sampler);
            for k in 0..3 {
                paths.o[k][x] = ray.o[k];
                paths.d[k][x] = ray.d[k];
            }
        }
        let mut depth = 0;
        while paths.n > 0 {
            if depth == 0 {
                intersect(scene, &mut paths);
            } else {
                intersect_one_by_one(scene, &mut paths);
            }
            escape(scene, &paths, &mut out);
            for start in (0..paths.n).step_by(LANES) {
                shade(ds, depth, start, &mut paths, &mut out, scene);
            }
            shadow_rays(scene, &paths, &mut out);
            compact(&mut paths);
            depth += 1;
        }
        out.into_iter().zip(at).collect()
    }
}

/// Closest hits of the live rays, eight at a time: for camera rays, whose packets are
/// coherent (2.2× single rays on AVX2); rays that leave the scene end (the prototype's scenes
/// have no environment).
#[inline(always)]
fn intersect(scene: &Scene, paths: &mut Paths) {
    for start in (0..paths.n).step_by(LANES) {
        let hits = scene.bvh.intersect8(&Rays8 {
            o: load3(&paths.o, start),
            d: load3(&paths.d, start),
            t_max: F8::splat(f32::INFINITY),
            active: M8::from_fn(|i| start + i < paths.n),
        });
        hits.t.store(&mut paths.t, start);
        hits.b1.store(&mut paths.b[0], start);
        hits.b2.store(&mut paths.b[1], start);
        paths.tri[start..start + LANES].copy_from_slice(&hits.prim);
        paths.alive[start..start + LANES].copy_from_slice(&hits.found.to_bools());
    }
}

/// Closest hits of the live rays one at a time: for diffuse bounces, whose packets visit the
/// union of their rays' nodes (docs/engine.md: the prototype ran 1.46× the scalar tracer
/// with packets for bounces and 1.68× without, on cbox; 1.01× and 1.33× on 131k triangles).
#[inline(always)]
fn intersect_one_by_one(scene: &Scene, paths: &mut Paths) {
    for i in 0..paths.n {
        let ray = crate::geometry::Ray::new(
            glam::Vec3A::new(paths.o[0][i], paths.o[1][i], paths.o[2][i]),
            glam::Vec3A::new(paths.d[0][i], paths.d[1][i], paths.d[2][i]),
        );
        let hit = scene.bvh.intersect(&ray, f32::INFINITY);
        paths.alive[i] = hit.is_some();
        if let Some(h) = hit {
            (paths.t[i], paths.b[0][i], paths.b[1][i], paths.tri[i]) = (h.t, h.b1, h.b2, h.prim);
        }
    }
}

/// What the paths that left the scene find of the environment, if there is one, weighted as
/// `Walk::escaped` weights it (against light sampling after a bounce that was not specular):
/// eight paths' lookups at once, so that their cache misses overlap
/// (`Scene::environment_at_each`).
#[inline(always)]
fn escape(scene: &Scene, paths: &Paths, out: &mut [Rgb]) {
    if scene.environment.is_none() {
        return;
    }
    let at = |v: &[Vec<f32>; 3], i: usize| glam::Vec3A::new(v[0][i], v[1][i], v[2][i]);
    let mut gone = (0..paths.n).filter(|&i| !paths.alive[i]).peekable();
    while gone.peek().is_some() {
        let group: [Option<usize>; LANES] = std::array::from_fn(|_| gone.next());
        let d = group.map(|i| i.map(|i| at(&paths.d, i)));
        let found = scene.environment_at_each(d);
        for (i, found) in group.into_iter().zip(found) {
            let (Some(i), Some((le, light_pdf))) = (i, found) else {
                continue;
            };
            let prev = paths.prev_pdf[i];
            let w = if prev == 0.0 {
                1.0
            } else {
                crate::integrator::mis_weight(prev, light_pdf)
            };
            out[paths.pixel[i] as usize] += Rgb::from(at(&paths.beta, i)) * le * w;
        }
    }
}

/// Shadow rays of this bounce, eight at a time: what each carries is added to its pixel if
/// nothing blocks it.
#[inline(always)]
fn shadow_rays(scene: &Scene, paths: &Paths, out: &mut [Rgb]) {
    for start in (0..paths.n).step_by(LANES) {
        let l = load3(&paths.shadow_l, start);
        let zero = F8::splat(0.0);
        let carries = !(l.x.eq(zero) & l.y.eq(zero) & l.z.eq(zero));
        if !carries.any() {
            continue;
        }
        let blocked = scene.bvh.occluded8(&Rays8 {
            o: load3(&paths.shadow_o, start),
            d: load3(&paths.shadow_d, start),
            t_max: F8::splat(1.0 - 1e-4),
            active: carries,
        });
        for i in 0..LANES {
            if carries.get(i) && !blocked.get(i) {
                out[paths.pixel[start + i] as usize] += Rgb::from(l.lane(i));
            }
        }
    }
}

/// Moves the paths that go on to the front, in order, and clears the padding's flags.
#[inline(always)]
fn compact(paths: &mut Paths) {
    let mut k = 0;
    for i in 0..paths.n {
        if !paths.alive[i] {
            continue;
        }
        if k != i {
            paths.pixel[k] = paths.pixel[i];
            paths.sampler.swap(k, i);
            for c in 0..3 {
                paths.o[c][k] = paths.o[c][i];
                paths.d[c][k] = paths.d[c][i];
                paths.beta[c][k] = paths.beta[c][i];
            }
            paths.prev_pdf[k] = paths.prev_pdf[i];
            paths.eta[k] = paths.eta[i];
        }
        k += 1;
    }
    paths.n = k;
    paths.sampler.truncate(k);
    paths.alive.iter_mut().for_each(|a| *a = false);
}

/// Loads lanes `start..start + 8` of a three-channel buffer.
#[inline(always)]
fn load3(v: &[Vec<f32>; 3], start: usize) -> V8 {
    V8 {
        x: F8::load(&v[0], start),
        y: F8::load(&v[1], start),
        z: F8::load(&v[2], start),
    }
}

#[inline(always)]
fn store3(v: &mut [Vec<f32>; 3], start: usize, x: V8) {
    x.x.store(&mut v[0], start);
    x.y.store(&mut v[1], start);
    x.z.store(&mut v[2], start);
}

/// A per-triangle field of each lane's triangle.
#[inline(always)]
fn gather3(tris: &[Tri], idx: &[u32; LANES], f: impl Fn(&Tri) -> [f32; 3]) -> V8 {
    V8::from_fn(|i| f(&tris[idx[i] as usize]))
}

/// A point at barycentric coordinates (b1, b2) of each lane's triangle, with its rounding
/// error bound (`Triangle::surface`'s).
#[inline(always)]
fn surface(tris: &[Tri], idx: &[u32; LANES], b1: F8, b2: F8) -> (V8, V8) {
    let p0 = gather3(tris, idx, |t| t.p[0]);
    let p1 = gather3(tris, idx, |t| t.p[1]);
    let p2 = gather3(tris, idx, |t| t.p[2]);
    let b0 = 1.0 - b1 - b2;
    let (a, b, c) = (p0.scale(b0), p1.scale(b1), p2.scale(b2));
    let p = a + b + c;
    let abs = |v: V8| V8 {
        x: v.x.abs(),
        y: v.y.abs(),
        z: v.z.abs(),
    };
    let err = (abs(a) + abs(b) + abs(c)).scale(F8::splat(gamma(7)));
    (p, err)
}

/// Looks up the textured reflectances of the lanes of `mask` (the back's where `back`), one
/// lane at a time, at the (u, v) `Triangle::surface` gives: the mesh's texture coordinates
/// interpolated, or (b1, b2).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn textured_reflectance(
    scene: &Scene,
    ds: &LaneScene,
    idx: &[u32; LANES],
    mask: M8,
    back: M8,
    b1: F8,
    b2: F8,
    refl: &mut V8,
) {
    for (i, &tri) in idx.iter().enumerate() {
        let k = ds.tris[tri as usize].texture;
        if k == NO_TEXTURE || !mask.get(i) {
            continue;
        }
        let Primitive::Triangle(t) = &scene.bvh.primitives()[tri as usize] else {
            continue;
        };
        let (b1, b2) = (b1.0[i], b2.0[i]);
        let (front, behind) = &ds.textures[k as usize];
        let c = if back.get(i) { behind } else { front }.at(t.tex_at(b1, b2));
        (refl.x.0[i], refl.y.0[i], refl.z.0[i]) = (c.x, c.y, c.z);
    }
}

/// The shading normal at (b1, b2) of each lane's triangle, as `Triangle::surface` makes it:
/// the vertex normals interpolated and normalised (by the reciprocal of the length, as glam's
/// `normalize_or_zero`), negated for `flip_normals`; the geometric normal `ng` where the mesh
/// has no vertex normals or they interpolate to zero.
#[inline(always)]
fn shading_normal(tris: &[Tri], idx: &[u32; LANES], b1: F8, b2: F8, ng: V8) -> V8 {
    let smooth = M8::from_fn(|i| tris[idx[i] as usize].smooth);
    if !smooth.any() {
        return ng;
    }
    let n0 = gather3(tris, idx, |t| t.n[0]);
    let n1 = gather3(tris, idx, |t| t.n[1]);
    let n2 = gather3(tris, idx, |t| t.n[2]);
    let b0 = 1.0 - b1 - b2;
    let s = n0.scale(b0) + n1.scale(b1) + n2.scale(b2);
    let rcp = 1.0 / s.dot(s).sqrt();
    let ok = smooth & rcp.lt(F8::splat(f32::INFINITY)) & rcp.gt(F8::splat(0.0));
    let flip = F8::from_fn(|i| tris[idx[i] as usize].flip);
    V8::select(ok, s.scale(rcp * flip), ng)
}

/// `offset_ray_origin` in lanes: `p` moved just outside its error box, on the side of `n`
/// that `w` leaves through, rounded away from `p`.
#[inline(always)]
fn offset(p: V8, err: V8, n: V8, w: V8) -> V8 {
    let d = n.x.abs() * err.x + n.y.abs() * err.y + n.z.abs() * err.z;
    let off = n.scale(d);
    let off = V8::select(w.dot(n).lt(F8::splat(0.0)), off.scale(F8::splat(-1.0)), off);
    V8 {
        x: away(p.x, off.x),
        y: away(p.y, off.y),
        z: away(p.z, off.z),
    }
}

/// `p + o` rounded away from `p`: `next_up` where o > 0, `next_down` where o < 0, as integer
/// arithmetic on the bits without branches. (Written with `if`s, or calling `next_up` lane by
/// lane, LLVM kept it scalar and branchy: the two offsets of a light sample were then 80% of
/// the shading stage.)
#[inline(always)]
fn away(p: F8, o: F8) -> F8 {
    let q = p + o;
    let mut r = [0u32; LANES];
    for (i, r) in r.iter_mut().enumerate() {
        let (x, o) = (q.0[i], o.0[i]);
        let bits = x.to_bits();
        let abs = bits & 0x7fff_ffff;
        let up = u32::from(o > 0.0);
        // 1 where the magnitude grows (x and o of one sign), 0 where it shrinks.
        let grow = u32::from(x > 0.0) ^ up ^ 1;
        let stepped = bits.wrapping_add((2 * grow).wrapping_sub(1));
        // From ±0: the least subnormal of o's sign.
        let from_zero = 1 + (1 - up) * 0x8000_0000;
        // NaN stays, an infinity stays where it would grow, and so does x where o is 0 or NaN.
        let offset = o.abs() > 0.0;
        let keep = (abs > 0x7f80_0000) | (abs == 0x7f80_0000 && grow == 1) | !offset;
        let moved = if abs == 0 { from_zero } else { stepped };
        *r = if keep { bits } else { moved };
    }
    F8(r.map(f32::from_bits))
}

/// The tangents of `Frame::from_normal(n)`: Duff et al.'s basis.
#[inline(always)]
fn frame(n: V8) -> (V8, V8) {
    let sign = n.z.sign_one();
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let fs = V8 {
        x: 1.0 + sign * n.x * n.x * a,
        y: sign * b,
        z: -sign * n.x,
    };
    let ft = V8 {
        x: b,
        y: sign + n.y * n.y * a,
        z: -n.y,
    };
    (fs, ft)
}

/// The power heuristic (`integrator::mis_weight`) in lanes, for finite densities.
#[inline(always)]
fn mis(a: F8, b: F8) -> F8 {
    let (a2, b2) = (a * a, b * b);
    let s = a2 + b2;
    s.gt(F8::splat(0.0)).select(a2 / s, F8::splat(0.0))
}

/// Random numbers of each live lane, `k` of them, drawn in order; zero in other lanes.
#[inline(always)]
fn draw<const K: usize>(paths: &mut Paths, start: usize, live: M8) -> [F8; K] {
    let mut u = [F8::splat(0.0); K];
    for i in 0..LANES {
        if live.get(i) {
            let s = &mut paths.sampler[start + i];
            for v in u.iter_mut() {
                v.0[i] = s.next_1d();
            }
        }
    }
    u
}

/// One bounce of lanes `start..start + 8`: emission found, a light sample (its shadow ray is
/// traced after), the BSDF sample and roulette.
#[inline(always)]
fn shade(ds: &LaneScene, depth: u32, start: usize, paths: &mut Paths, out: &mut [Rgb], scene: &Scene) {
    let zero = F8::splat(0.0);
    let mut live = M8::from_fn(|i| paths.alive[start + i]);
    store3(&mut paths.shadow_l, start, V8::splat([0.0; 3]));
    if !live.any() {
        return;
    }
    let idx: [u32; LANES] = std::array::from_fn(|i| paths.tri[start + i]);
    let d = load3(&paths.d, start);
    let beta = load3(&paths.beta, start);
    let t = F8::load(&paths.t, start);
    let (b1, b2) = (F8::load(&paths.b[0], start), F8::load(&paths.b[1], start));
    let (p, err) = surface(&ds.tris, &idx, b1, b2);
    // Offsets and densities follow the geometric normal, shading the shading normal.
    let ng = gather3(&ds.tris, &idx, |t| t.ng);
    let n = shading_normal(&ds.tris, &idx, b1, b2, ng);
    let cos_o = -d.dot(n);
    // The side an emitter emits from, and the side the material scatters from: a two-sided
    // material's back is shaded as a front with the local z flipped (`Bsdf::TwoSided`, whose
    // front includes z = 0).
    let front = cos_o.gt(zero);
    let back = M8::from_fn(|i| ds.tris[idx[i] as usize].two_sided) & cos_o.lt(zero);
    let side = back.select(F8::splat(-1.0), F8::splat(1.0));
    let scatters = (side * cos_o).gt(zero);
    // The shading frame (`Frame::from_normal`) and, where a lane's material is rough plastic,
    // the plastic and the direction to the viewer in the frame (a back side's z flipped).
    let (fs, ft) = frame(n);
    let plastic_idx: [u32; LANES] = std::array::from_fn(|i| {
        // A primitive the scalar code shades names no plastic (`Tri::SCALAR`).
        if live.get(i) {
            ds.tris[idx[i] as usize].plastic[usize::from(back.get(i))]
        } else {
            NO_PLASTIC
        }
    });
    let coats = Plastics::gather(&ds.plastics, plastic_idx);
    let plastic = M8::from_fn(|i| plastic_idx[i] != NO_PLASTIC);
    let to_viewer = d.scale(F8::splat(-1.0));
    let wv = V8 {
        x: to_viewer.dot(fs),
        y: to_viewer.dot(ft),
        z: side * cos_o,
    };

    // Emission found by the camera ray, or by BSDF sampling weighted against light sampling.
    let le = gather3(&ds.tris, &idx, |t| t.emission);
    let density = F8::from_fn(|i| ds.tris[idx[i] as usize].light_density);
    let prev_pdf = F8::load(&paths.prev_pdf, start);
    let light_pdf = t * t * density / d.dot(ng).abs();
    let w = (prev_pdf.eq(zero)).select(F8::splat(1.0), mis(prev_pdf, light_pdf));
    let found = front & live & (le.x.gt(zero) | le.y.gt(zero) | le.z.gt(zero));
    let add = beta * V8::select(found, le.scale(w), V8::splat([0.0; 3]));
    for i in 0..LANES {
        if found.get(i) {
            out[paths.pixel[start + i] as usize] += Rgb::new(add.x.0[i], add.y.0[i], add.z.0[i]);
        }
    }
    if depth + 1 >= ds.max_depth {
        (start..start + LANES).for_each(|i| paths.alive[i] = false);
        return;
    }

    // The random numbers of this bounce, in the scalar path tracer's order: light pick, light
    // point, BSDF lobe (unused here), BSDF direction; roulette's comes after.
    let [u_sel, u_l0, u_l1, u_lobe, u_b0, u_b1] = draw::<6>(paths, start, live);
    // Lanes on surfaces the lanes do not model bounce in scalar code; what they become is
    // stored after the lanes' results.
    let scalar = live & M8::from_fn(|i| ds.tris[idx[i] as usize].scalar);
    live = live & !scalar;
    let bounced: [Option<Option<Walk>>; LANES] = std::array::from_fn(|i| {
        let u = [u_sel, u_l0, u_l1, u_lobe, u_b0, u_b1].map(|u| u.0[i]);
        scalar
            .get(i)
            .then(|| shade_scalar(scene, ds, depth, start + i, u, paths, out))
    });

    // A light sample: the light and triangle picked in scalar code (binary searches), the
    // point and its weight in lanes for area lights; other lights (the environment, points,
    // spots, the sun) sampled by their scalar code, the lanes that picked one light together
    // (an environment map's samples then overlap their cache misses).
    let mut light_tri = [0u32; LANES];
    let mut u_x = zero;
    let mut area = M8::splat(false);
    let mut picked = [None; LANES];
    for i in 0..LANES {
        let Some((li, pmf)) = live.get(i).then(|| scene.pick_light(u_sel.0[i])).flatten() else {
            continue;
        };
        match &scene.lights[li as usize] {
            Light::Area(a) => {
                let (k, _, ux) = a.area_distribution.sample(u_l0.0[i]);
                light_tri[i] = a.prims[k];
                u_x.0[i] = ux;
                area.set(i, true);
            }
            _ => picked[i] = Some((li, pmf)),
        }
    }
    let mut other: [Option<LightSample>; LANES] = [None; LANES];
    let at: [glam::Vec3A; LANES] = std::array::from_fn(|i| glam::Vec3A::from(p.lane(i)));
    let mut left = picked;
    while let Some((li, pmf)) = left.iter().find_map(|&x| x) {
        let mine = left.map(|x| x.is_some_and(|(l, _)| l == li));
        let u = std::array::from_fn(|i| mine[i].then(|| Vec2::new(u_l0.0[i], u_l1.0[i])));
        let got = scene.sample_picked_light_each(li, pmf, at, u);
        for i in (0..LANES).filter(|&i| mine[i]) {
            (other[i], left[i]) = (got[i], None);
        }
    }
    let root = (1.0 - u_x).sqrt();
    let (lb1, lb2) = (1.0 - root, u_l1 * root);
    let (lp, lerr) = surface(&ds.tris, &light_tri, lb1, lb2);
    let ln = gather3(&ds.tris, &light_tri, |t| t.ng);
    let lns = shading_normal(&ds.tris, &light_tri, lb1, lb2, ln);
    let mut lrad = gather3(&ds.tris, &light_tri, |t| t.emission);
    let ldensity = F8::from_fn(|i| ds.tris[light_tri[i] as usize].light_density);
    let to_light = lp - p;
    let dist2 = to_light.dot(to_light);
    let dist = dist2.sqrt();
    let mut wi = to_light.scale(1.0 / dist);
    // The light emits from the front of its shading normal; its density follows the geometric one.
    let cos_l = ln.dot(wi).abs();
    let mut pdf_l = dist2 * ldensity / cos_l;
    let mut lit = area & dist2.gt(zero) & (-lns.dot(wi)).gt(zero);
    let sampled = M8::from_fn(|i| other[i].is_some());
    let delta = M8::from_fn(|i| other[i].is_some_and(|ls| ls.delta));
    if sampled.any() {
        let ls = |f: fn(&LightSample) -> [f32; 3]| V8::from_fn(|i| other[i].as_ref().map_or([0.0; 3], f));
        wi = V8::select(sampled, ls(|l| l.wi.to_array()), wi);
        lrad = V8::select(sampled, ls(|l| l.radiance.to_array()), lrad);
        pdf_l = sampled.select(F8::from_fn(|i| other[i].map_or(0.0, |l| l.pdf)), pdf_l);
        lit = lit | sampled;
    }
    let cos_i = side * n.dot(wi);
    let lit = lit & live & scatters & cos_i.gt(zero) & pdf_l.gt(zero) & pdf_l.lt(F8::splat(f32::INFINITY));
    // Point-like lights are not weighted against BSDF sampling, which cannot find them.
    let weigh = |bsdf_pdf: F8| delta.select(F8::splat(1.0), mis(pdf_l, bsdf_pdf));
    let mut refl = V8::select(
        back,
        gather3(&ds.tris, &idx, |t| t.back_reflectance),
        gather3(&ds.tris, &idx, |t| t.reflectance),
    );
    textured_reflectance(scene, ds, &idx, live & scatters, back, b1, b2, &mut refl);
    let f_over_pdf = cos_i * std::f32::consts::FRAC_1_PI * weigh(cos_i * std::f32::consts::FRAC_1_PI) / pdf_l;
    let mut carry = (beta * refl * lrad).scale(f_over_pdf);
    if let Some(c) = &coats {
        // As `direct::light_sample`: f · cos from the BSDF, weighted against its density.
        let wl = V8 {
            x: wi.dot(fs),
            y: wi.dot(ft),
            z: cos_i,
        };
        let (f, pdf_b) = c.eval_pdf(refl, wv, wl);
        let coated = beta * (f * lrad).scale(weigh(pdf_b) / pdf_l);
        carry = V8::select(plastic, coated, carry);
    }
    let so = offset(p, err, ng, wi);
    let mut target = offset(lp, lerr, ln, so - lp);
    for (i, ls) in other.iter().enumerate() {
        let Some(ls) = ls else { continue };
        // As `Scene::transmittance`: a point light's own point, else just off the light.
        let t = if ls.n == glam::Vec3A::ZERO {
            ls.p
        } else {
            crate::geometry::offset_ray_origin(ls.p, ls.p_err, ls.n, glam::Vec3A::from(so.lane(i)) - ls.p)
        };
        (target.x.0[i], target.y.0[i], target.z.0[i]) = (t.x, t.y, t.z);
    }
    store3(&mut paths.shadow_o, start, so);
    store3(&mut paths.shadow_d, start, target - so);
    store3(
        &mut paths.shadow_l,
        start,
        V8::select(lit, carry, V8::splat([0.0; 3])),
    );

    // The BSDF sample: a cosine-weighted direction by the concentric map, in the frame of the
    // normal (`Frame::from_normal`).
    let (ox, oy) = (2.0 * u_b0 - 1.0, 2.0 * u_b1 - 1.0);
    let x_major = ox.abs().gt(oy.abs());
    let r = x_major.select(ox, oy);
    let safe_r = r.eq(zero).select(F8::splat(1.0), r);
    let angle = std::f32::consts::FRAC_PI_4 * x_major.select(oy, ox) / safe_r;
    let (s, c) = sincos_quarter(angle);
    let (dx, dy) = (r * x_major.select(c, s), r * x_major.select(s, c));
    let dz = (1.0 - dx * dx - dy * dy).max(zero).sqrt();
    let (mut local, mut pdf, mut weight) =
        (V8 { x: dx, y: dy, z: dz }, dz * std::f32::consts::FRAC_1_PI, refl);
    if let Some(c) = &coats {
        let (wo, w, p) = c.sample(refl, wv, u_lobe, (u_b0, u_b1), local);
        local = V8::select(plastic, wo, local);
        pdf = plastic.select(p, pdf);
        weight = V8::select(plastic, w, weight);
    }
    let wo = fs.scale(local.x) + ft.scale(local.y) + n.scale(local.z * side);
    live = live & scatters & pdf.gt(zero);
    let beta = beta * weight;

    // Roulette from the scalar tracer's depth on (its depth counts this bounce).
    let beta = if depth + 1 > ds.rr_depth {
        let eta = F8::load(&paths.eta, start);
        let q = (beta.x.max(beta.y).max(beta.z) * eta * eta).min(F8::splat(0.95));
        let [u_rr] = draw::<1>(paths, start, live);
        live = live & u_rr.lt(q);
        beta.scale(1.0 / q)
    } else {
        beta
    };
    live = live & (beta.x.gt(zero) | beta.y.gt(zero) | beta.z.gt(zero));
    store3(&mut paths.o, start, offset(p, err, ng, wo));
    store3(&mut paths.d, start, wo);
    store3(&mut paths.beta, start, beta);
    pdf.store(&mut paths.prev_pdf, start);
    for i in 0..LANES {
        paths.alive[start + i] = live.get(i);
    }
    for (lane, walk) in bounced.into_iter().enumerate() {
        let Some(walk) = walk else { continue };
        let i = start + lane;
        paths.alive[i] = walk.is_some();
        let Some(w) = walk else { continue };
        for k in 0..3 {
            paths.o[k][i] = w.ray.o[k];
            paths.d[k][i] = w.ray.d[k];
            paths.beta[k][i] = w.beta[k];
        }
        // A specular bounce's emission is found in full, as after a camera ray.
        paths.prev_pdf[i] = w.prev.filter(|p| !p.delta).map_or(0.0, |p| p.pdf);
        paths.eta[i] = w.eta;
    }
}

/// One bounce of path `i`, on a surface the lanes do not model, by the scalar path tracer's
/// own code (`integrator/path.rs`: the light sample if the material has a smooth part, the
/// BSDF sample, [`Walk::follow`] and [`Walk::survives_roulette`]), with `u`, the numbers the
/// lane group drew for it in the scalar tracer's order. Its light sample's shadow ray is
/// traced here, and its contribution added at once: the pixel sums in the scalar tracer's
/// order all the same, as nothing else of this bounce reaches it. Returns the walk the path
/// goes on as, if it does, for [`shade`] to store after the lanes' results.
fn shade_scalar(
    scene: &Scene,
    ds: &LaneScene,
    depth: u32,
    i: usize,
    u: [f32; 6],
    paths: &mut Paths,
    out: &mut [Rgb],
) -> Option<Walk> {
    let at = |v: &[Vec<f32>; 3]| glam::Vec3A::new(v[0][i], v[1][i], v[2][i]);
    let ray = Ray::new(at(&paths.o), at(&paths.d));
    let hit = crate::geometry::Hit {
        t: paths.t[i],
        prim: paths.tri[i],
        b1: paths.b[0][i],
        b2: paths.b[1][i],
        inner: 0,
    };
    let sp = scene.bvh.primitives()[hit.prim as usize].surface(&ray, &hit);
    let h = Hit::new(scene, sp, -ray.d);
    let mut walk = Walk::new(ray, Rgb::from(at(&paths.beta).to_array()), None);
    (walk.eta, walk.depth) = (paths.eta[i], depth);
    let sampler = &mut paths.sampler[i];
    if h.bsdf.has_smooth() {
        out[paths.pixel[i] as usize] +=
            walk.beta * direct::light_sample(scene, &h, None, (u[0], Vec2::new(u[1], u[2])), 1.0, sampler);
    }
    let bs = h.bsdf.sample(
        &h.at(),
        h.wo_local,
        u[3],
        Vec2::new(u[4], u[5]),
        TransportMode::Radiance,
    )?;
    walk.follow(&h, &bs);
    walk.survives_roulette(ds.rr_depth, sampler).then_some(walk)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::render::{Method, RenderSettings, Renderer};

    fn load(name: &str, res: u32) -> Scene {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/refs")
            .join(name);
        Scene::load(&path, &[("res".to_string(), res.to_string())]).unwrap()
    }

    fn cbox(res: u32) -> Scene {
        load("cbox.xml", res)
    }

    /// cbox's text with its light's material (the white walls') made Lambertian.
    fn lambertian_light(mut t: String) -> String {
        let light = t.find("id=\"light\"").unwrap();
        let at = light + t[light..].find("<ref id=\"white\"/>").unwrap();
        t.replace_range(at..at + "<ref id=\"white\"/>".len(), "<bsdf type=\"diffuse\"/>");
        t
    }

    fn lanes(scene: &Scene, backend: Backend, passes: std::ops::Range<u64>) -> FilmSum {
        let ds = LaneScene::new(scene, &PathSettings::from_scene(scene)).unwrap();
        let mut film = FilmSum::new(scene.width(), scene.height());
        for pass in passes {
            render_pass(scene, &ds, 7, pass, backend, &mut film);
        }
        film
    }

    #[test]
    fn every_backend_and_thread_count_gives_the_same_bytes() {
        let scene = cbox(24);
        let first = lanes(&scene, Backend::Sse2, 0..3);
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for b in Backend::available() {
                let film = pool.install(|| lanes(&scene, b, 0..3));
                assert!(film == first, "{b} on {threads} threads differs from sse2");
            }
        }
    }

    /// The same random numbers in the same order as the scalar tracer: the images agree to
    /// rounding (our sincos against libm's, points rounded in another order), 1e-7 of the
    /// image measured, where one pass at 48² is ~30% noisy per pixel: any sample drawn from
    /// another dimension (a roulette number drawn too early made 16%) shows.
    #[test]
    fn agrees_with_the_scalar_path_tracer_sample_by_sample() {
        // cbox: flat triangles; meshes: a PLY with vertex normals, an OBJ of quads in a
        // two-sided material and a PLY with face normals, its metal made diffuse; cbox with its
        // green wall turned round in a two-sided material with another colour behind, so that
        // the room sees the wall's back.
        let two_sided_back = |t: String| {
            t.replacen(
                "<bsdf type=\"diffuse\" id=\"green\">",
                "<bsdf type=\"twosided\" id=\"green\"><bsdf type=\"diffuse\"/><bsdf type=\"diffuse\">",
                1,
            )
            .replacen(
                "</bsdf>\n    <bsdf type=\"diffuse\" id=\"red\">",
                "</bsdf></bsdf>\n    <bsdf type=\"diffuse\" id=\"red\">",
                1,
            )
            .replacen(
                "<ref id=\"green\"/>",
                "<ref id=\"green\"/><boolean name=\"flip_normals\" value=\"true\"/>",
                1,
            )
        };
        // cbox with textures: a bilinear PNG on the floor (the rectangle's own uv), a
        // checkerboard on the red wall, and an OBJ strip with texture coordinates in a
        // two-sided material with a nearest, mirrored PNG.
        let textured = |t: String| {
            let bitmap = |extra: &str| {
                format!(
                    "<bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">\
                     <string name=\"filename\" value=\"textures/colors.png\"/>{extra}</texture></bsdf>"
                )
            };
            let at = |t: &str, shape: &str| {
                let a = t.find(shape).unwrap();
                a + t[a..].find("<ref id=").unwrap()
            };
            let floor = at(&t, "id=\"floor\"");
            let end = floor + t[floor..].find("/>").unwrap() + 2;
            let t = format!("{}{}{}", &t[..floor], bitmap(""), &t[end..]);
            let wall = at(&t, "id=\"red-wall\"");
            let end = wall + t[wall..].find("/>").unwrap() + 2;
            let checks = "<bsdf type=\"diffuse\"><texture type=\"checkerboard\" name=\"reflectance\">\
                          <transform name=\"to_uv\"><scale x=\"4\" y=\"3\"/></transform></texture></bsdf>";
            let t = format!("{}{}{}", &t[..wall], checks, &t[end..]);
            let strip = format!(
                "<shape type=\"obj\"><string name=\"filename\" value=\"textures/strip.obj\"/>\
                 <transform name=\"to_world\"><scale x=\"0.55\" y=\"0.45\"/><rotate y=\"1\" angle=\"-25\"/>\
                 <translate x=\"0.2\" y=\"0.3\" z=\"-0.5\"/></transform><bsdf type=\"twosided\">{}</bsdf></shape>\n</scene>",
                bitmap(
                    "<string name=\"filter_type\" value=\"nearest\"/><string name=\"wrap_mode\" value=\"mirror\"/>\
                        <transform name=\"to_uv\"><scale x=\"3\" y=\"1.5\"/></transform>"
                )
            );
            t.replacen("</scene>", &strip, 1)
        };
        // cbox in GGX rough plastics: the white one glossy and nonlinear, the red wall's
        // textured with a dimmer coating, the green wall turned round, diffuse in front and
        // plastic behind; the light stays Lambertian.
        let plastics = |t: String| {
            let coat = |alpha: &str, extra: &str| {
                format!(
                    "<bsdf type=\"roughplastic\"><string name=\"distribution\" value=\"ggx\"/>\
                     <float name=\"alpha\" value=\"{alpha}\"/>{extra}</bsdf>"
                )
            };
            let t = t.replacen(
                "<bsdf type=\"diffuse\" id=\"white\">\n        <rgb name=\"reflectance\"",
                "<bsdf type=\"roughplastic\" id=\"white\"><string name=\"distribution\" value=\"ggx\"/>\
                 <float name=\"alpha\" value=\"0.1\"/><boolean name=\"nonlinear\" value=\"true\"/>\
                 <rgb name=\"diffuse_reflectance\"",
                1,
            );
            let t = t.replacen(
                "<bsdf type=\"diffuse\" id=\"red\">\n        <rgb name=\"reflectance\" value=\"0.570068, 0.0430135, 0.0443706\"/>\n    </bsdf>",
                &format!(
                    "<bsdf type=\"twosided\" id=\"red\">{}</bsdf>",
                    coat(
                        "0.3",
                        "<rgb name=\"specular_reflectance\" value=\"0.5\"/><texture type=\"bitmap\" \
                         name=\"diffuse_reflectance\"><string name=\"filename\" value=\"textures/colors.png\"/></texture>"
                    )
                ),
                1,
            );
            let back = coat("0.05", "<float name=\"int_ior\" value=\"1.33\"/>");
            let t = t
                .replacen(
                    "<bsdf type=\"diffuse\" id=\"green\">",
                    "<bsdf type=\"twosided\" id=\"green\"><bsdf type=\"diffuse\">",
                    1,
                )
                .replacen(
                    "</bsdf>\n    <bsdf type=\"twosided\" id=\"red\">",
                    &format!("</bsdf>{back}</bsdf>\n    <bsdf type=\"twosided\" id=\"red\">"),
                    1,
                )
                .replacen(
                    "<ref id=\"green\"/>",
                    "<ref id=\"green\"/><boolean name=\"flip_normals\" value=\"true\"/>",
                    1,
                );
            lambertian_light(t)
        };
        let same = |t: String| t;
        // Each sample splatted over the pixels its filter reaches.
        let tent = |t: String| t.replacen("<rfilter type=\"box\"/>", "<rfilter type=\"tent\"/>", 1);
        let gaussian = |t: String| t.replacen("<rfilter type=\"box\"/>", "<rfilter type=\"gaussian\"/>", 1);
        let scenes: [(&str, &dyn Fn(String) -> String); 12] = [
            ("cbox.xml", &same),
            ("cbox.xml", &tent),
            ("meshes.xml", &gaussian),
            ("meshes.xml", &same),
            ("cbox.xml", &two_sided_back),
            ("cbox.xml", &textured),
            ("cbox.xml", &plastics),
            // Lights other than area lights, sampled by their scalar code lane by lane: an
            // environment map (seen through glass), a point, a spot and an area light, a
            // constant environment with the sun, a projector.
            ("environment.xml", &same),
            ("lights.xml", &same),
            ("sun.xml", &same),
            ("projector.xml", &same),
            // A glass sphere and a mirror one, shaded by the scalar code lane by lane.
            ("cbox-spheres.xml", &same),
        ];
        for (name, edit) in scenes {
            let res = 48;
            let path = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../tests/refs")
                .join(name);
            let text = edit(std::fs::read_to_string(&path).unwrap());
            let text = match text.find("<bsdf type=\"roughconductor\">") {
                Some(a) => {
                    let b = a + text[a..].find("</bsdf>").unwrap() + "</bsdf>".len();
                    format!("{}<bsdf type=\"diffuse\"/>{}", &text[..a], &text[b..])
                }
                None => text,
            };
            let scene = Scene::from_str(&text, &path, &[("res".to_string(), res.to_string())]).unwrap();
            assert!(scene.bvh.primitives().len() > 36 || name != "meshes.xml");
            let ds = LaneScene::new(&scene, &PathSettings::from_scene(&scene)).unwrap();
            assert_eq!(ds.plastics.is_empty(), !text.contains("roughplastic"), "{name}");
            let splats = ["tent", "gaussian"].map(|f| text.contains(&format!("<rfilter type=\"{f}\"/>")));
            assert!(splats == [false; 2] || !scene.filter.is_box(), "{name}");
            let settings = RenderSettings {
                seed: 7,
                method: Method::Path(PathSettings::from_scene(&scene)),
            };
            let scalar = Renderer::on(&scene, &settings, None)
                .passes(0..2)
                .image()
                .unwrap();
            let ours = lanes(&scene, Backend::best(), 0..2).image().unwrap();
            let sum = |c: &Rgb| c.to_array().iter().sum::<f32>() as f64;
            let total: f64 = scalar.iter().map(sum).sum();
            let diff: f64 = scalar
                .iter()
                .zip(&ours)
                .map(|(a, b)| (sum(a) - sum(b)).abs())
                .sum();
            assert!(total > 100.0, "{name}: {total}");
            assert!(
                diff / total < 1e-6,
                "{name}: mean relative difference {}",
                diff / total
            );
        }
    }

    #[test]
    fn refuses_what_it_does_not_model() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/fog.xml");
        let scene = Scene::load(&path, &[("res".to_string(), "16".to_string())]).unwrap();
        let e = LaneScene::new(&scene, &PathSettings::from_scene(&scene))
            .err()
            .expect("media are refused")
            .to_string();
        assert!(e.contains("media"), "{e}");
        // cbox with its walls in rough plastic (Beckmann, Mitsuba's default, which the lanes
        // do not model), the light Lambertian: the scalar code would shade nearly every
        // bounce, so the scalar tracer renders it.
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox.xml");
        let mut text = std::fs::read_to_string(&path).unwrap();
        for c in ["white", "green", "red"] {
            text = text.replacen(
                &format!("<bsdf type=\"diffuse\" id=\"{c}\">\n        <rgb name=\"reflectance\""),
                &format!(
                    "<bsdf type=\"roughplastic\" id=\"{c}\">\n        <rgb name=\"diffuse_reflectance\""
                ),
                1,
            );
        }
        let text = lambertian_light(text);
        let scene = Scene::from_str(&text, &path, &[("res".to_string(), "16".to_string())]).unwrap();
        assert!(
            matches!(&scene.bsdfs[0], Bsdf::Plastic(_)),
            "{:?}",
            scene.bsdfs[0]
        );
        let e = LaneScene::new(&scene, &PathSettings::from_scene(&scene))
            .err()
            .expect("a plastic room is refused")
            .to_string();
        assert!(e.contains("most of the scene's surface"), "{e}");
    }

    #[test]
    fn away_is_next_up_or_next_down() {
        let xs = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            1e-40,
            -1e-40,
            f32::MAX,
            -f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            3.5,
            -2.25e7,
        ];
        for &p in &xs {
            for &o in &[0.0f32, -0.0, 1e-7, -1e-7, 1e-45, -1e-45, f32::NAN] {
                let q = p + o;
                let want = if o > 0.0 {
                    q.next_up()
                } else if o < 0.0 {
                    q.next_down()
                } else {
                    q
                };
                let got = away(F8::splat(p), F8::splat(o)).0[0];
                assert_eq!(
                    got.to_bits(),
                    want.to_bits(),
                    "p {p:e} o {o:e}: {got:e} vs {want:e}"
                );
            }
        }
    }
}
