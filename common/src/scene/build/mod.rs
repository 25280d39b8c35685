//! Builds a [`Scene`] from the parsed XML: the orchestration here, each element kind in its
//! own file (as pbrt keeps a light's `Create` beside the light).

mod bsdf;
mod emitter;
mod integrator;
mod medium;
mod sensor;
mod shape;
mod texture;

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use glam::Vec3A;

use super::props::{Ctx, FileRoot, Res};
use super::xml::{self, Element};
use super::{IntegratorDecl, Scene, SceneError, ShapeInfo};
use crate::bsdf::{Bsdf, Coating, Distribution};
use crate::color::Rgb;
use crate::geometry::{Bvh, Primitive};
use crate::job::Integrator;
use crate::light::{AreaLight, Light, SceneSphere};
use crate::medium::Medium;
use crate::sampling::Distribution1D;
use crate::texture::{Param, Texture};

pub(super) fn load(path: &Path, defines: &[(String, String)], root: FileRoot) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError {
        file: path.to_path_buf(),
        line: 0,
        element: "scene file".into(),
        message: format!("cannot read: {e}"),
    })?;
    from_str(&text, path, defines, root)
}

pub(super) fn from_str(
    text: &str,
    path: &Path,
    defines: &[(String, String)],
    root: FileRoot,
) -> Result<Scene, SceneError> {
    let parsed = xml::parse(path, text, defines)?;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let ctx = Ctx {
        file: path.to_path_buf(),
        dir: dir.to_path_buf(),
        search_dirs: parsed.search_dirs,
        root,
        files: Default::default(),
    };
    let mut builder = Builder::new(&ctx);
    for inc in &parsed.includes {
        if let FileRoot::Inside(r) = &ctx.root
            && !inc
                .canonicalize()
                .is_ok_and(|p| r.canonicalize().is_ok_and(|r| p.starts_with(r)))
        {
            return Err(ctx.err(
                &parsed.root,
                format!("included file {} lies outside the job's bundle", inc.display()),
            ));
        }
        builder
            .files
            .push(inc.canonicalize().unwrap_or_else(|_| inc.clone()));
    }
    builder.scene(&parsed.root)
}

/// Accumulates the scene while the elements are read.
struct Builder<'a> {
    ctx: &'a Ctx,
    bsdfs: Vec<Bsdf>,
    bsdf_ids: HashMap<String, u32>,
    shapes: Vec<ShapeInfo>,
    prims: Vec<Primitive>,
    /// Area emitters, by shape, until the BVH has fixed the primitives' order.
    area_emitters: Vec<(u32, Param<Rgb>)>,
    lights: Vec<Light>,
    light_media: Vec<Option<u32>>,
    media: Vec<Medium>,
    medium_ids: HashMap<String, u32>,
    camera_medium: Option<u32>,
    warnings: Vec<String>,
    files: Vec<std::path::PathBuf>,
    /// The sensor's far clipping distance, checked against the scene's extent.
    far_clip: f32,
    /// Top-level samplers (a sensor may refer to one), by id: their sample counts.
    sampler_ids: HashMap<String, u32>,
    /// Top-level textures, by id.
    texture_ids: HashMap<String, Arc<Texture>>,
    /// Ids of top-level area emitters (shapes refer to them).
    area_ids: std::collections::HashSet<String>,
    /// Those a shape has taken: each belongs to one shape.
    area_taken: std::collections::HashSet<String>,
    /// Shape groups, by id: their trees, which instances place.
    groups: HashMap<String, Arc<Bvh>>,
    /// The mesh attributes (`mesh_attribute` textures) read by the materials built so far and
    /// not yet claimed by a shape, which bakes them into its triangles.
    attributes_read: Vec<String>,
    /// Those each top-level BSDF reads, by index, for the shapes that refer to it.
    bsdf_attributes: HashMap<u32, Vec<String>>,
    /// Plastics' coatings by (distribution, α_u, α_v bits; index bits), computed once each.
    coatings: HashMap<CoatingKey, Coating>,
}

/// A coating's roughness (distribution, α_u and α_v bits) and index bits.
type CoatingKey = (Option<(Distribution, u32, u32)>, u32);

/// Whether `el` is a `<shape type="shapegroup">`.
fn is_shape_group(el: &Element) -> bool {
    el.tag == "shape" && el.attr("type") == Some("shapegroup")
}

impl<'a> Builder<'a> {
    fn new(ctx: &'a Ctx) -> Self {
        Builder {
            ctx,
            bsdfs: Vec::new(),
            bsdf_ids: HashMap::new(),
            shapes: Vec::new(),
            prims: Vec::new(),
            area_emitters: Vec::new(),
            lights: Vec::new(),
            light_media: Vec::new(),
            media: Vec::new(),
            medium_ids: HashMap::new(),
            camera_medium: None,
            warnings: Vec::new(),
            files: Vec::new(),
            far_clip: f32::INFINITY,
            texture_ids: HashMap::new(),
            sampler_ids: HashMap::new(),
            area_ids: Default::default(),
            area_taken: Default::default(),
            groups: HashMap::new(),
            attributes_read: Vec::new(),
            bsdf_attributes: HashMap::new(),
            coatings: HashMap::new(),
        }
    }

    fn scene(mut self, root: &Element) -> Res<Scene> {
        let ctx = self.ctx;
        let mut sensor = None;
        let mut integrator = None;
        // Named media and materials first, so that shapes may refer to them wherever they are
        // declared.
        for el in root.children.iter().filter(|e| e.tag == "medium") {
            let Some(id) = el.attr("id") else {
                return Err(ctx.err(el, "a top-level <medium> needs an id to be referred to"));
            };
            let index = self.medium(el)?;
            if self.medium_ids.insert(id.to_string(), index).is_some() || self.bsdf_ids.contains_key(id) {
                return Err(ctx.err(el, format!("id \"{id}\" is used twice")));
            }
        }
        for el in root.children.iter().filter(|e| e.tag == "sampler") {
            let Some(id) = el.attr("id") else {
                return Err(ctx.err(el, "a top-level <sampler> needs an id to be referred to"));
            };
            let spp = self.sampler(el)?;
            self.sampler_ids.insert(id.to_string(), spp);
        }
        for el in root.children.iter().filter(|e| e.tag == "texture") {
            let Some(id) = el.attr("id") else {
                return Err(ctx.err(el, "a top-level <texture> needs an id to be referred to"));
            };
            let texture = Arc::new(self.texture(el)?);
            if self.texture_ids.insert(id.to_string(), texture).is_some() || self.medium_ids.contains_key(id)
            {
                return Err(ctx.err(el, format!("id \"{id}\" is used twice")));
            }
        }
        // A material nested in another or in a shape may carry an id too, and others may refer
        // to it, wherever either is declared (as in Mitsuba, whose parser names every object
        // with an id): Bitterli's staircase refers to the two-sided metal inside a bump map's
        // `<bsdf>`. Innermost first, so that a parent reuses what was built under the name
        // instead of building it, and its textures, again; and each after the materials it
        // refers to.
        let mut bsdfs = Vec::new();
        for el in root
            .children
            .iter()
            .filter(|e| e.tag == "bsdf" || e.tag == "shape")
        {
            nested_with_id(el, &mut bsdfs);
            if el.tag == "bsdf" {
                bsdfs.push(el);
            }
        }
        for el in in_dependency_order(bsdfs) {
            let bsdf = self.bsdf(el)?;
            let index = self.bsdfs.len() as u32;
            self.bsdfs.push(bsdf);
            let read = std::mem::take(&mut self.attributes_read);
            if !read.is_empty() {
                self.bsdf_attributes.insert(index, read);
            }
            if let Some(id) = el.attr("id")
                && (self.bsdf_ids.insert(id.to_string(), index).is_some()
                    || self.medium_ids.contains_key(id)
                    || self.texture_ids.contains_key(id))
            {
                return Err(ctx.err(el, format!("id \"{id}\" is used twice")));
            }
        }
        // Area emitters declared at the top level shine through the shape that refers to them.
        let mut area_ids: HashMap<String, &Element> = HashMap::new();
        for el in root
            .children
            .iter()
            .filter(|e| e.tag == "emitter" && e.attr("type") == Some("area"))
        {
            if let Some(id) = el.attr("id")
                && (area_ids.insert(id.to_string(), el).is_some() || self.bsdf_ids.contains_key(id))
            {
                return Err(ctx.err(el, format!("id \"{id}\" is used twice")));
            }
        }
        self.area_ids = area_ids.keys().cloned().collect();
        // Shape groups before the shapes, so that an instance may come first in the file.
        for el in root.children.iter().filter(|e| is_shape_group(e)) {
            let Some(id) = el.attr("id") else {
                return Err(ctx.err(el, "a shapegroup needs an id for its instances to refer to"));
            };
            let group = self.shape_group(el, &area_ids)?;
            if self.groups.insert(id.to_string(), group).is_some() {
                return Err(ctx.err(el, format!("id \"{id}\" is used twice")));
            }
        }
        for el in &root.children {
            match el.tag.as_str() {
                "bsdf" | "medium" | "texture" | "sampler" => {}
                "shape" if is_shape_group(el) => {}
                "shape" => self.shape(el, &area_ids)?,
                "emitter" if el.attr("type") == Some("area") && el.attr("id").is_some() => {}
                "emitter" => self.emitter(el)?,
                "sensor" if sensor.is_some() => return Err(ctx.err(el, "only one <sensor> is supported")),
                "sensor" => sensor = Some(el),
                "integrator" if integrator.is_some() => {
                    return Err(ctx.err(el, "only one <integrator> is allowed"));
                }
                "integrator" => integrator = Some(self.integrator(el)?),
                other => {
                    return Err(ctx.err(
                        el,
                        format!("<{other}> is not supported at the top level of a scene"),
                    ));
                }
            }
        }
        let Some(sensor) = sensor else {
            return Err(ctx.err(root, "the scene has no <sensor>"));
        };
        let (camera, spp, filter) = self.sensor(sensor)?;
        for (id, el) in &area_ids {
            if !self.area_taken.contains(id) {
                self.warnings.push(format!(
                    "{}:{}: area emitter \"{id}\" is not referred to by any shape and gives no light",
                    el.file.display(),
                    el.line
                ));
            }
        }
        let integrator = integrator.unwrap_or(IntegratorDecl {
            kind: Integrator::Path,
            max_depth: -1,
            rr_depth: 5,
            params: super::MethodParams::None,
        });

        let bvh = Bvh::build(std::mem::take(&mut self.prims));
        let eye = camera.to_world.transform_point3a(Vec3A::ZERO);
        let b = bvh.bounds();
        let farthest = (0..8)
            .map(|i| {
                let corner = Vec3A::new(
                    if i & 1 == 0 { b.min.x } else { b.max.x },
                    if i & 2 == 0 { b.min.y } else { b.max.y },
                    if i & 4 == 0 { b.min.z } else { b.max.z },
                );
                (corner - eye).length()
            })
            .fold(0.0f32, f32::max);
        if farthest > self.far_clip {
            self.warnings.push(format!(
                "geometry lies up to {farthest} away but the sensor's far_clip is {}: we do not clip \
                 far geometry, Mitsuba hides it",
                self.far_clip
            ));
        }
        self.attach_area_lights(&bvh);
        if self.lights.is_empty() {
            self.warnings
                .push("the scene has no light source: the image will be black".into());
        }
        let null_shapes = self
            .shapes
            .iter()
            .filter(|s| self.bsdfs[s.bsdf as usize].is_null())
            .count();
        // Lights at infinity are sized to the scene; Mitsuba allows one environment.
        let bounds = bvh.bounds();
        let sphere = SceneSphere::around(bounds.min, bounds.max);
        for light in &mut self.lights {
            light.fit_scene(sphere);
        }
        let mut environments = self.lights.iter().enumerate().filter(|(_, l)| l.is_environment());
        let environment = environments.next().map(|(i, _)| i as u32);
        if environments.next().is_some() {
            return Err(ctx.err(
                root,
                "only one environment emitter (constant or envmap) is allowed",
            ));
        }
        let powers: Vec<f32> = self.lights.iter().map(Light::power).collect();
        let light_selection = Distribution1D::new(&powers);
        let emitting: Vec<f32> = powers.iter().map(|&p| if p > 0.0 { 1.0 } else { 0.0 }).collect();
        let light_sampling = Distribution1D::new(&emitting);
        if !self.lights.is_empty() && light_selection.is_empty() {
            self.warnings
                .push("every light has zero power: the image will be black".into());
        }
        Ok(Scene {
            source: ctx.file.clone(),
            bvh,
            shapes: self.shapes,
            bsdfs: self.bsdfs,
            lights: self.lights,
            light_media: self.light_media,
            media: self.media,
            camera_medium: self.camera_medium,
            light_selection,
            light_sampling,
            environment,
            camera,
            filter,
            spp,
            integrator,
            warnings: self.warnings,
            files: self.files.into_iter().chain(ctx.files.take()).collect(),
            null_shapes,
        })
    }

    /// Area lights learn their primitives once the BVH has put them in their final order.
    fn attach_area_lights(&mut self, bvh: &Bvh) {
        let mut by_shape: HashMap<u32, Vec<u32>> = HashMap::new();
        for (slot, p) in bvh.distinct() {
            by_shape.entry(p.shape()).or_default().push(slot);
        }
        for (shape, radiance) in std::mem::take(&mut self.area_emitters) {
            let prims = by_shape.remove(&shape).unwrap_or_default();
            self.shapes[shape as usize].light = Some(self.lights.len() as u32);
            // An area light's photons start in the medium outside its shape.
            self.light_media.push(self.shapes[shape as usize].exterior);
            self.lights
                .push(Light::Area(AreaLight::new(radiance, prims, bvh.primitives())));
        }
    }
}

/// Materials reordered so that each comes after the named ones it refers to or nests, in
/// document order otherwise. Where a name is missing or names form a cycle, the first left
/// comes next, and building it reports the name it lacks.
fn in_dependency_order<'e>(items: Vec<&'e Element>) -> Vec<&'e Element> {
    let declared: std::collections::HashSet<&str> = items.iter().filter_map(|e| e.attr("id")).collect();
    let needs = |el: &'e Element| {
        let mut out = Vec::new();
        names_inside(el, &declared, &mut out);
        out
    };
    let deps: Vec<Vec<&str>> = items.iter().map(|e| needs(e)).collect();
    let mut built = std::collections::HashSet::new();
    let mut placed = vec![false; items.len()];
    let mut out = Vec::with_capacity(items.len());
    // Everything before `first` is placed: in a file without forward references each step
    // takes `first`, so the order costs one pass.
    let mut first = 0;
    while out.len() < items.len() {
        while placed[first] {
            first += 1;
        }
        let ready = (first..items.len()).find(|&i| !placed[i] && deps[i].iter().all(|d| built.contains(d)));
        let next = ready.unwrap_or(first);
        placed[next] = true;
        built.extend(items[next].attr("id"));
        out.push(items[next]);
    }
    out
}

/// The names among `declared` that `el`'s descendants refer to (`<ref id>`) or carry.
fn names_inside<'e>(el: &'e Element, declared: &std::collections::HashSet<&str>, out: &mut Vec<&'e str>) {
    for c in &el.children {
        if let Some(id) = c.attr("id")
            && (c.tag == "ref" || c.tag == "bsdf")
            && declared.contains(id)
        {
            out.push(id);
        }
        names_inside(c, declared, out);
    }
}

/// The `<bsdf>`s with an id anywhere inside `el`, innermost first.
fn nested_with_id<'e>(el: &'e Element, out: &mut Vec<&'e Element>) {
    for c in &el.children {
        nested_with_id(c, out);
        if c.tag == "bsdf" && c.attr("id").is_some() {
            out.push(c);
        }
    }
}
