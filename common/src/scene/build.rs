//! Builds a [`Scene`] from the parsed XML: one function per element kind.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use glam::{Mat3A, Mat4, Vec3A};

use super::mesh::{self, Mesh};
use super::named;
use super::props::{Ctx, FileRoot, Props, Res};
use super::xml::{self, Element};
use super::{IntegratorDecl, Scene, SceneError, ShapeInfo};
use crate::bsdf::{
    Bsdf, Conductor, Dielectric, Diffuse, Distribution, Microfacet, Plastic, Principled, RoughDielectric,
    Roughness, ThinDielectric, eta_from_specular,
};
use crate::camera::Camera;
use crate::color::Rgb;
use crate::filter::Filter;
use crate::geometry::Frame;
use crate::geometry::{Bvh, Primitive, Sphere, Triangle};
use crate::job::Integrator;
use crate::light::{
    AreaLight, BeamLight, ConstantLight, DirectionalLight, EnvmapLight, Light, PointLight, SceneSphere,
    SpotLight,
};
use crate::medium::{Medium, Phase};
use crate::sampling::Distribution1D;
use crate::texture::{Bitmap, Filter as TexFilter, Param, Texture, Wrap};

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

/// The widest reconstruction filter, in pixels on each side of a sample's own.
const MAX_FILTER_REACH: u32 = 8;

/// Accumulates the scene while the elements are read.
struct Builder<'a> {
    ctx: &'a Ctx,
    bsdfs: Vec<Bsdf>,
    bsdf_ids: HashMap<String, u32>,
    shapes: Vec<ShapeInfo>,
    prims: Vec<Primitive>,
    /// Area emitters, by shape, until the BVH has fixed the primitives' order.
    area_emitters: Vec<(u32, Rgb)>,
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
        for el in root.children.iter().filter(|e| e.tag == "bsdf") {
            let bsdf = self.bsdf(el)?;
            let index = self.bsdfs.len() as u32;
            self.bsdfs.push(bsdf);
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
        for el in &root.children {
            match el.tag.as_str() {
                "bsdf" | "medium" | "texture" | "sampler" => {}
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
            params: Vec::new(),
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
        for (i, p) in bvh.primitives().iter().enumerate() {
            by_shape.entry(p.shape()).or_default().push(i as u32);
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

    /// `<integrator>`, reduced to the method of ours that renders it: `path` (Mitsuba's `path`,
    /// `volpath`, `volpathmis`), `direct`, `ptracer` or `sppm` (ours). The wrappers `moment` and
    /// `aov` render their first nested integrator.
    fn integrator(&mut self, el: &Element) -> Res<IntegratorDecl> {
        let p = Props::new(self.ctx, el)?;
        let kind = p.kind()?;
        if matches!(kind, "moment" | "aov") {
            let _ = p.string("aovs")?;
            let nested = p.objects("integrator");
            let Some(inner) = nested.first() else {
                return Err(self.ctx.err(
                    el,
                    format!("a {kind} integrator without a nested integrator renders only AOVs, which we do not write"),
                ));
            };
            p.finish()?;
            let decl = self.integrator(inner)?;
            self.warnings.push(format!(
                "{}:{}: <integrator type=\"{kind}\">: rendering its nested {} integrator; the {kind} outputs are not written",
                el.file.display(),
                el.line,
                decl.kind.name()
            ));
            return Ok(decl);
        }
        let method = match kind {
            "path" | "volpath" | "volpathmis" => Integrator::Path,
            "ptracer" => Integrator::Ptracer,
            "direct" => Integrator::Direct,
            "sppm" => Integrator::Sppm,
            other => {
                return Err(self.ctx.err(
                    el,
                    format!(
                        "integrator type \"{other}\" is not supported (path, volpath, volpathmis, direct, ptracer, \
                         sppm, and moment or aov around one of them)"
                    ),
                ));
            }
        };
        let max_depth = p.int("max_depth")?.unwrap_or(-1);
        if max_depth < -1 || max_depth == 0 || max_depth > i32::MAX as i64 {
            return Err(p.err_at(
                "max_depth",
                format!("max_depth must be -1 (unlimited) or positive, not {max_depth}"),
            ));
        }
        let rr_depth = p.int("rr_depth")?.unwrap_or(5);
        if !(1..=u32::MAX as i64).contains(&rr_depth) {
            return Err(p.err_at("rr_depth", format!("rr_depth must be positive, not {rr_depth}")));
        }
        if p.boolean("hide_emitters")?.unwrap_or(false) {
            return Err(p.err_at("hide_emitters", "hide_emitters=true is not supported".into()));
        }
        // How Mitsuba splits its work, which does not change the image.
        let _ = p.int("samples_per_pass")?;
        let _ = p.int("block_size")?;
        if kind == "volpathmis" {
            let _ = p.boolean("use_spectral_mis")?;
        }
        if p.float("timeout")?.is_some_and(|t| t > 0.0) {
            return Err(p.err_at(
                "timeout",
                "a render timeout is set on the command line (--time-limit), not in the scene".into(),
            ));
        }
        let mut params = Vec::new();
        match method {
            Integrator::Direct => {
                let shading = p.int("shading_samples")?;
                let (e, b) = (p.int("emitter_samples")?, p.int("bsdf_samples")?);
                if shading.is_some() && (e.is_some() || b.is_some()) {
                    return Err(self.ctx.err(
                        el,
                        "give shading_samples, or emitter_samples and bsdf_samples, not both",
                    ));
                }
                let e = e.or(shading).unwrap_or(1);
                let b = b.or(shading).unwrap_or(1);
                for (name, v) in [("emitter_samples", e), ("bsdf_samples", b)] {
                    if !(0..=1024).contains(&v) {
                        return Err(p.err_at(name, format!("{name} must lie in [0, 1024], not {v}")));
                    }
                }
                if e + b == 0 {
                    return Err(self
                        .ctx
                        .err(el, "emitter_samples and bsdf_samples cannot both be 0"));
                }
                params.push(("emitter_samples".to_string(), e as f64));
                params.push(("bsdf_samples".to_string(), b as f64));
            }
            // The remaining numbers are SPPM's (photon count, radius, ...).
            Integrator::Sppm => {
                for c in &el.children {
                    if let (Some(name), "float" | "integer") = (c.attr("name"), c.tag.as_str())
                        && !matches!(name, "max_depth" | "rr_depth" | "samples_per_pass" | "block_size")
                        && let Some(v) = p.float(name)?
                    {
                        params.push((name.to_string(), v as f64));
                    }
                }
            }
            _ => {}
        }
        p.finish()?;
        Ok(IntegratorDecl {
            kind: method,
            max_depth: max_depth as i32,
            rr_depth: rr_depth as u32,
            params,
        })
    }

    fn sensor(&mut self, el: &Element) -> Res<(Camera, u32, Filter)> {
        let p = Props::new(self.ctx, el)?;
        let kind = p.kind()?;
        let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        let near_clip = p.positive("near_clip", 0.01)?;
        let far_clip = p.positive("far_clip", 10000.0)?;
        if far_clip <= near_clip {
            return Err(p.err_at("far_clip", "far_clip must exceed near_clip".into()));
        }
        self.far_clip = far_clip;
        let (aperture_radius, focus_distance) = match kind {
            "perspective" => {
                // Mitsuba's RGB variants accept and ignore it on a pinhole.
                let _ = p.float("focus_distance")?;
                (0.0, 1.0)
            }
            "thinlens" => {
                let Some(r) = p.float("aperture_radius")? else {
                    return Err(self.ctx.err(el, "a thinlens sensor needs an aperture_radius"));
                };
                if r < 0.0 {
                    return Err(p.err_at("aperture_radius", "aperture_radius cannot be negative".into()));
                }
                // Mitsuba focuses at the far clipping plane unless told otherwise.
                (r, p.positive("focus_distance", far_clip)?)
            }
            other => {
                return Err(self.ctx.err(
                    el,
                    format!("sensor type \"{other}\" is not supported (perspective, thinlens)"),
                ));
            }
        };
        for name in ["principal_point_offset_x", "principal_point_offset_y"] {
            if p.float(name)?.is_some_and(|v| v != 0.0) {
                return Err(p.err_at(name, format!("a nonzero {name} is not supported")));
            }
        }
        let (fov, fov_axis) = match (p.float("fov")?, p.string("focal_length")?) {
            (Some(_), Some(_)) => return Err(self.ctx.err(el, "give fov or focal_length, not both")),
            (Some(f), None) => (f, p.string("fov_axis")?.unwrap_or("x")),
            (None, focal) => {
                if p.string("fov_axis")?.is_some() {
                    return Err(p.err_at(
                        "fov_axis",
                        "fov_axis goes with fov; a focal_length is measured along the film's diagonal".into(),
                    ));
                }
                let focal = focal.unwrap_or("50mm");
                let mm = focal.strip_suffix("mm").unwrap_or(focal);
                let mm = p.parse_f32(el, mm)?;
                if mm <= 0.0 {
                    return Err(p.err_at("focal_length", "focal_length must be positive".into()));
                }
                // Mitsuba measures a focal length against the diagonal of 35 mm film (36 x 24 mm).
                let diagonal = (36.0f64 * 36.0 + 24.0 * 24.0).sqrt();
                (
                    (2.0 * (diagonal / (2.0 * mm as f64)).atan().to_degrees()) as f32,
                    "diagonal",
                )
            }
        };
        if !(fov > 0.0 && fov < 180.0) {
            return Err(p.err_at("fov", format!("fov must lie in (0, 180) degrees, not {fov}")));
        }

        let (_, _, medium) = self.media_of(&p, false)?;
        self.camera_medium = medium;
        let film = p
            .object("film")?
            .ok_or_else(|| self.ctx.err(el, "the sensor has no <film>"))?;
        let (width, height, filter) = self.film(film)?;
        let referred = p
            .objects("ref")
            .into_iter()
            .find_map(|r| self.sampler_ids.get(r.attr("id")?).copied());
        let spp = match (p.object("sampler")?, referred) {
            (Some(s), _) => self.sampler(s)?,
            (None, Some(spp)) => spp,
            (None, None) => 4,
        };
        p.finish()?;

        // Mitsuba converts every fov_axis to the x axis's field of view.
        let aspect = width as f64 / height as f64;
        let tan_half = ((fov as f64).to_radians() * 0.5).tan();
        let tan_half_x = match fov_axis {
            "x" => tan_half,
            "y" => tan_half * aspect,
            "diagonal" => tan_half * aspect / (aspect * aspect + 1.0).sqrt(),
            "smaller" if aspect > 1.0 => tan_half * aspect,
            "smaller" => tan_half,
            "larger" if aspect > 1.0 => tan_half,
            "larger" => tan_half * aspect,
            other => {
                return Err(p.err_at(
                    "fov_axis",
                    format!("fov_axis \"{other}\" is not supported (x, y, diagonal, smaller, larger)"),
                ));
            }
        };
        let camera = Camera {
            to_world,
            tan_half_x: tan_half_x as f32,
            tan_half_y: (tan_half_x / aspect) as f32,
            width,
            height,
            aperture_radius,
            focus_distance,
            near_clip,
        };
        Ok((camera, spp, filter))
    }

    fn film(&mut self, el: &Element) -> Res<(u32, u32, Filter)> {
        let p = Props::new(self.ctx, el)?;
        if p.kind()? != "hdrfilm" {
            return Err(self.ctx.err(el, "only hdrfilm is supported"));
        }
        let dim = |name: &str, default: i64| -> Res<u32> {
            let v = p.int(name)?.unwrap_or(default);
            if !(1..=65536).contains(&v) {
                return Err(p.err_at(name, format!("film {name} must be between 1 and 65536, not {v}")));
            }
            Ok(v as u32)
        };
        let (w, h) = (dim("width", 768)?, dim("height", 576)?);
        // Output-format parameters do not change the rendered radiance.
        for name in ["file_format", "component_format", "banner"] {
            let _ = p.string(name).ok();
            let _ = p.boolean(name).ok();
        }
        if let Some(f) = p.string("pixel_format")?
            && !matches!(f, "rgb" | "rgba")
        {
            return Err(p.err_at(
                "pixel_format",
                format!("pixel_format \"{f}\" is not supported (rgb, rgba)"),
            ));
        }
        let filter = match p.object("rfilter")? {
            Some(f) => self.rfilter(f)?,
            None => Filter::DEFAULT,
        };
        p.finish()?;
        Ok((w, h, filter))
    }

    /// `<rfilter>`: Mitsuba's `box`, `tent` and `gaussian`, with their defaults.
    fn rfilter(&self, el: &Element) -> Res<Filter> {
        let p = Props::new(self.ctx, el)?;
        let filter = match p.kind()? {
            "box" => Filter::Box,
            "tent" => Filter::Tent {
                radius: p.positive("radius", 1.0)?,
            },
            "gaussian" => Filter::Gaussian {
                stddev: p.positive("stddev", 0.5)?,
            },
            other => {
                return Err(self.ctx.err(
                    el,
                    format!("rfilter type \"{other}\" is not supported (box, tent, gaussian)"),
                ));
            }
        };
        // A sample reaches (2 reach + 1)^2 pixels: wider filters are blurs, not pixel filters.
        if filter.reach() > MAX_FILTER_REACH {
            return Err(self.ctx.err(
                el,
                format!(
                    "a filter of radius {} pixels is too wide (at most {} pixels)",
                    filter.radius(),
                    MAX_FILTER_REACH as f32 + 0.5
                ),
            ));
        }
        p.finish()?;
        Ok(filter)
    }

    fn sampler(&mut self, el: &Element) -> Res<u32> {
        let p = Props::new(self.ctx, el)?;
        let kind = p.kind()?;
        if !matches!(
            kind,
            "independent" | "stratified" | "multijitter" | "orthogonal" | "ldsampler"
        ) {
            return Err(self
                .ctx
                .err(el, format!("sampler type \"{kind}\" is not supported")));
        }
        let spp = p.int("sample_count")?.unwrap_or(4);
        if !(1..=u32::MAX as i64).contains(&spp) {
            return Err(p.err_at(
                "sample_count",
                format!("sample_count must be positive, not {spp}"),
            ));
        }
        // Our samples are independent and keyed by (seed, pass, pixel); these do not apply.
        let _ = p.int("seed")?;
        let _ = p.boolean("jitter")?;
        p.finish()?;
        Ok(spp as u32)
    }

    /// A `<bsdf>` or `<ref>` to one.
    fn bsdf_or_ref(&mut self, el: &Element) -> Res<Bsdf> {
        if el.tag == "ref" {
            let id = el
                .attr("id")
                .ok_or_else(|| self.ctx.err(el, "a <ref> needs an id"))?;
            let i = *self
                .bsdf_ids
                .get(id)
                .ok_or_else(|| self.ctx.err(el, format!("no <bsdf> with id \"{id}\"")))?;
            return Ok(self.bsdfs[i as usize].clone());
        }
        self.bsdf(el)
    }

    fn nested_bsdfs(&mut self, p: &Props) -> Res<Vec<Bsdf>> {
        let mut out = Vec::new();
        let refs: Vec<&Element> = p
            .objects("ref")
            .into_iter()
            .filter(|c| {
                !c.attr("id").is_some_and(|id| {
                    self.medium_ids.contains_key(id)
                        || self.area_ids.contains(id)
                        || self.texture_ids.contains_key(id)
                })
            })
            .collect();
        for c in p.objects("bsdf").into_iter().chain(refs) {
            out.push(self.bsdf_or_ref(c)?);
        }
        Ok(out)
    }

    /// The media an element declares: `interior`, `exterior` (shapes) or an unnamed one
    /// (sensors, emitters), each as a nested `<medium>` or a `<ref>`.
    fn media_of(&mut self, p: &Props, named: bool) -> Res<(Option<u32>, Option<u32>, Option<u32>)> {
        let mut out = (None, None, None);
        let refs: Vec<&Element> = p
            .objects("ref")
            .into_iter()
            .filter(|c| c.attr("id").is_some_and(|id| self.medium_ids.contains_key(id)))
            .collect();
        for c in p.objects("medium").into_iter().chain(refs) {
            let index = if c.tag == "ref" {
                self.medium_ids[c.attr("id").expect("filtered")]
            } else {
                self.medium(c)?
            };
            let slot = match (named, c.attr("name")) {
                (true, Some("interior")) => &mut out.0,
                (true, Some("exterior")) => &mut out.1,
                (true, _) => {
                    return Err(self
                        .ctx
                        .err(c, "a shape's medium needs name=\"interior\" or name=\"exterior\""));
                }
                (false, _) => &mut out.2,
            };
            if slot.replace(index).is_some() {
                return Err(self.ctx.err(c, "this medium is given twice"));
            }
        }
        Ok(out)
    }

    /// `<medium type="homogeneous">` with an optional nested `<phase>`.
    fn medium(&mut self, el: &Element) -> Res<u32> {
        let p = Props::new(self.ctx, el)?;
        if p.kind()? != "homogeneous" {
            return Err(self.ctx.err(el, "only homogeneous media are supported"));
        }
        let scale = p.float_or("scale", 1.0)?;
        if scale < 0.0 {
            return Err(p.err_at("scale", "scale cannot be negative".into()));
        }
        let sigma_t = p.non_negative_rgb("sigma_t", Rgb::ONE)? * scale;
        let albedo = p.reflectance("albedo", Rgb::splat(0.75))?;
        let _ = p.boolean("sample_emitters")?;
        // Only spectral variants read it.
        let _ = p.boolean("has_spectral_extinction")?;
        let phase = match p.object("phase")? {
            None => Phase::Isotropic,
            Some(ph) => {
                let pp = Props::new(self.ctx, ph)?;
                let phase = match pp.kind()? {
                    "isotropic" => Phase::Isotropic,
                    "hg" => {
                        let g = pp.float_or("g", 0.8)?;
                        if !(g > -1.0 && g < 1.0) {
                            return Err(
                                pp.err_at("g", format!("g must lie strictly between -1 and 1, not {g}"))
                            );
                        }
                        Phase::HenyeyGreenstein(g)
                    }
                    other => {
                        return Err(self.ctx.err(
                            ph,
                            format!("phase type \"{other}\" is not supported (isotropic, hg)"),
                        ));
                    }
                };
                pp.finish()?;
                phase
            }
        };
        p.finish()?;
        self.media.push(Medium {
            sigma_t,
            albedo,
            phase,
        });
        Ok(self.media.len() as u32 - 1)
    }

    fn bsdf(&mut self, el: &Element) -> Res<Bsdf> {
        let p = Props::new(self.ctx, el)?;
        let bsdf = match p.kind()? {
            "diffuse" => Bsdf::Diffuse(Diffuse {
                reflectance: self.color_param(&p, "reflectance", Rgb::splat(0.5))?,
            }),
            kind @ ("conductor" | "roughconductor") => {
                let (eta, k) = match (p.rgb("eta")?, p.rgb("k")?, p.string("material")?) {
                    (Some(eta), Some(k), None) => (eta, k),
                    (None, None, material) => {
                        named::conductor(material.unwrap_or("none")).map_err(|m| p.err_at("material", m))?
                    }
                    _ => return Err(self.ctx.err(el, "give both eta and k, or a material, not a mix")),
                };
                if eta.min_element() < 0.0 || k.min_element() < 0.0 {
                    return Err(self.ctx.err(el, "eta and k cannot be negative"));
                }
                Bsdf::Conductor(Conductor {
                    eta,
                    k,
                    specular: self.color_param(&p, "specular_reflectance", Rgb::ONE)?,
                    roughness: if kind == "roughconductor" {
                        Some(self.roughness(&p)?)
                    } else {
                        None
                    },
                })
            }
            "dielectric" => Bsdf::Dielectric(Dielectric {
                eta: self.relative_ior(&p, "bk7")?,
                specular_reflectance: self.color_param(&p, "specular_reflectance", Rgb::ONE)?,
                specular_transmittance: self.color_param(&p, "specular_transmittance", Rgb::ONE)?,
            }),
            "roughdielectric" => Bsdf::RoughDielectric(Box::new(RoughDielectric {
                eta: self.relative_ior(&p, "bk7")?,
                roughness: self.roughness(&p)?,
                specular_reflectance: self.color_param(&p, "specular_reflectance", Rgb::ONE)?,
                specular_transmittance: self.color_param(&p, "specular_transmittance", Rgb::ONE)?,
            })),
            "thindielectric" => Bsdf::ThinDielectric(ThinDielectric {
                eta: self.relative_ior(&p, "bk7")?,
                specular_reflectance: self.color_param(&p, "specular_reflectance", Rgb::ONE)?,
                specular_transmittance: self.color_param(&p, "specular_transmittance", Rgb::ONE)?,
            }),
            "mask" => {
                let opacity = self.float_param(&p, "opacity", 0.5)?;
                let mut nested = self.nested_bsdfs(&p)?;
                if nested.len() != 1 {
                    return Err(self
                        .ctx
                        .err(el, format!("mask needs one nested bsdf, not {}", nested.len())));
                }
                Bsdf::Mask(Box::new((nested.remove(0), opacity)))
            }
            kind @ ("plastic" | "roughplastic") => {
                let roughness = if kind == "roughplastic" {
                    Some(self.microfacet(&p)?)
                } else {
                    None
                };
                Bsdf::Plastic(Box::new(Plastic::new(
                    self.color_param(&p, "diffuse_reflectance", Rgb::splat(0.5))?,
                    self.color_param(&p, "specular_reflectance", Rgb::ONE)?,
                    self.relative_ior(&p, "polypropylene")?,
                    p.boolean("nonlinear")?.unwrap_or(false),
                    roughness,
                )))
            }
            "principled" => Bsdf::Principled(Box::new(self.principled(&p)?)),
            "twosided" => {
                let mut nested = self.nested_bsdfs(&p)?;
                match nested.len() {
                    1 => {
                        let b = nested.remove(0);
                        Bsdf::TwoSided(Box::new((b.clone(), b)))
                    }
                    2 => {
                        let back = nested.remove(1);
                        Bsdf::TwoSided(Box::new((nested.remove(0), back)))
                    }
                    n => {
                        return Err(self
                            .ctx
                            .err(el, format!("twosided needs one or two nested bsdfs, not {n}")));
                    }
                }
            }
            "null" => Bsdf::Null,
            "blendbsdf" => {
                let w = self.float_param(&p, "weight", 0.5)?;
                if let Param::Fixed(w) = w
                    && !(0.0..=1.0).contains(&w)
                {
                    return Err(p.err_at("weight", format!("weight must lie in [0, 1], not {w}")));
                }
                let mut nested = self.nested_bsdfs(&p)?;
                if nested.len() != 2 {
                    return Err(self.ctx.err(
                        el,
                        format!("blendbsdf needs two nested bsdfs, not {}", nested.len()),
                    ));
                }
                let second = nested.remove(1);
                Bsdf::Blend(Box::new((nested.remove(0), second)), w)
            }
            other => {
                return Err(self.ctx.err(
                    el,
                    format!(
                        "bsdf type \"{other}\" is not supported (diffuse, conductor, roughconductor, \
                         dielectric, roughdielectric, thindielectric, plastic, roughplastic, principled, \
                         twosided, blendbsdf, mask, null)"
                    ),
                ));
            }
        };
        p.finish()?;
        Ok(bsdf)
    }

    /// Mitsuba's `principled`: every parameter it reads, with its defaults. Its weights are
    /// numbers in [0, 1] or textures; `eta` and `specular` (one or the other) are numbers.
    fn principled(&mut self, p: &Props) -> Res<Principled> {
        let mut weight = |name: &str, default: f32| -> Res<Param<f32>> {
            let v = self.float_param(p, name, default)?;
            if let Param::Fixed(x) = v
                && !(0.0..=1.0).contains(&x)
            {
                return Err(p.err_at(name, format!("'{name}' must lie in [0, 1], not {x}")));
            }
            Ok(v)
        };
        let roughness = weight("roughness", 0.5)?;
        let anisotropic = weight("anisotropic", 0.0)?;
        let metallic = weight("metallic", 0.0)?;
        let spec_trans = weight("spec_trans", 0.0)?;
        let spec_tint = weight("spec_tint", 0.0)?;
        let sheen = weight("sheen", 0.0)?;
        let sheen_tint = weight("sheen_tint", 0.0)?;
        let flatness = weight("flatness", 0.0)?;
        let clearcoat = weight("clearcoat", 0.0)?;
        let clearcoat_gloss = weight("clearcoat_gloss", 0.0)?;
        // Mitsuba's get_flag: a transmission lobe exists when spec_trans is given and is not
        // the number 0; then eta = 1 (or specular = 0) is nudged off the index-matched case.
        let transmits = !matches!(spec_trans, Param::Fixed(t) if t == 0.0);
        let eta = match (p.float("eta")?, p.float("specular")?) {
            (Some(_), Some(_)) => {
                return Err(self
                    .ctx
                    .err(p.el, "give either eta or specular (which sets eta), not both"));
            }
            (Some(eta), None) => {
                if eta <= 0.0 {
                    return Err(p.err_at("eta", format!("eta must be positive, not {eta}")));
                }
                if transmits && eta == 1.0 { 1.001 } else { eta }
            }
            (None, specular) => {
                let specular = specular.unwrap_or(0.5);
                if !(0.0..12.5).contains(&specular) {
                    return Err(p.err_at(
                        "specular",
                        format!("specular must lie in [0, 12.5), not {specular}"),
                    ));
                }
                eta_from_specular(if transmits && specular == 0.0 {
                    1e-3
                } else {
                    specular
                })
            }
        };
        let rate = |name: &str| -> Res<f32> {
            let v = p.float_or(name, 1.0)?;
            if v < 0.0 {
                return Err(p.err_at(name, format!("'{name}' cannot be negative, not {v}")));
            }
            Ok(v)
        };
        Ok(Principled {
            base_color: self.color_param(p, "base_color", Rgb::splat(0.5))?,
            roughness,
            anisotropic,
            metallic,
            spec_trans,
            spec_tint,
            sheen,
            sheen_tint,
            flatness,
            clearcoat,
            clearcoat_gloss,
            eta,
            diffuse_sampling_rate: rate("diffuse_reflectance_sampling_rate")?,
            specular_sampling_rate: rate("main_specular_sampling_rate")?,
            clearcoat_sampling_rate: rate("clearcoat_sampling_rate")?,
        })
    }

    /// A rough conductor's microfacets, whose `alpha` may be a texture.
    fn roughness(&mut self, p: &Props) -> Res<Roughness> {
        let textured = ["alpha", "alpha_u", "alpha_v"]
            .into_iter()
            .find_map(|name| self.texture_param(p, name).transpose().map(|t| (name, t)));
        match textured {
            Some((name, texture)) => {
                if name != "alpha" {
                    return Err(p.err_at(
                        name,
                        "a texture for alpha_u or alpha_v (anisotropic roughness) is not supported".into(),
                    ));
                }
                let mf = self.microfacet(p)?;
                Ok(Roughness {
                    distribution: mf.distribution,
                    alpha: Param::Textured(texture?),
                })
            }
            None => {
                let mf = self.microfacet(p)?;
                Ok(Roughness {
                    distribution: mf.distribution,
                    alpha: Param::Fixed(mf.alpha),
                })
            }
        }
    }

    /// A texture given for parameter `name`: nested (`<texture name=...>`) or a `<ref>` to a
    /// top-level one.
    fn texture_param(&mut self, p: &Props, name: &str) -> Res<Option<Arc<Texture>>> {
        if let Some(el) = p.named_object("texture", name) {
            return Ok(Some(Arc::new(self.texture(el)?)));
        }
        if let Some(el) = p.named_object("ref", name) {
            let id = el
                .attr("id")
                .ok_or_else(|| self.ctx.err(el, "a <ref> needs an id"))?;
            return match self.texture_ids.get(id) {
                Some(t) => Ok(Some(t.clone())),
                None => Err(self.ctx.err(el, format!("no <texture> with id \"{id}\""))),
            };
        }
        Ok(None)
    }

    /// A colour parameter of a material: a texture, or a reflectance in [0, 1].
    fn color_param(&mut self, p: &Props, name: &str, default: Rgb) -> Res<Param<Rgb>> {
        match self.texture_param(p, name)? {
            Some(t) => Ok(Param::Textured(t)),
            None => Ok(Param::Fixed(p.reflectance(name, default)?)),
        }
    }

    /// A number parameter of a material: a texture, or a number (an `<rgb>` is its mean).
    fn float_param(&mut self, p: &Props, name: &str, default: f32) -> Res<Param<f32>> {
        match self.texture_param(p, name)? {
            Some(t) => Ok(Param::Textured(t)),
            None => Ok(Param::Fixed(p.float_of_texture(name, default)?)),
        }
    }

    /// A `<texture>`: Mitsuba's `bitmap` or `checkerboard`.
    fn texture(&mut self, el: &Element) -> Res<Texture> {
        let p = Props::new(self.ctx, el)?;
        let to_uv = match p.transform("to_uv")? {
            Some(m) => uv_transform(&m),
            None => glam::Affine2::IDENTITY,
        };
        let texture = match p.kind()? {
            "bitmap" => {
                let name = p
                    .string("filename")?
                    .ok_or_else(|| self.ctx.err(el, "missing the filename parameter"))?;
                let path = p.resolve_file("filename", name)?;
                let filter = match p.string("filter_type")? {
                    None | Some("bilinear") => TexFilter::Bilinear,
                    Some("nearest") => TexFilter::Nearest,
                    Some(f) => {
                        return Err(p.err_at(
                            "filter_type",
                            format!("filter_type \"{f}\" is not supported (bilinear, nearest)"),
                        ));
                    }
                };
                let wrap = match p.string("wrap_mode")? {
                    None | Some("repeat") => Wrap::Repeat,
                    Some("mirror") => Wrap::Mirror,
                    Some("clamp") => Wrap::Clamp,
                    Some(w) => {
                        return Err(p.err_at(
                            "wrap_mode",
                            format!("wrap_mode \"{w}\" is not supported (repeat, mirror, clamp)"),
                        ));
                    }
                };
                let raw = p.boolean("raw")?.unwrap_or(false);
                // Storage precision and GPU filtering in Mitsuba: no effect on the values.
                let _ = (p.string("format")?, p.boolean("accel")?);
                let bitmap = Bitmap::load(&path, raw, filter, wrap, to_uv)
                    .map_err(|e| p.err_at("filename", format!("{}: {e}", path.display())))?;
                Texture::Bitmap(bitmap)
            }
            "checkerboard" => Texture::Checkerboard {
                color0: p.reflectance("color0", Rgb::splat(0.4))?,
                color1: p.reflectance("color1", Rgb::splat(0.2))?,
                to_uv,
            },
            other => {
                return Err(self.ctx.err(
                    el,
                    format!("texture type \"{other}\" is not supported (bitmap, checkerboard)"),
                ));
            }
        };
        p.finish()?;
        Ok(texture)
    }

    /// A rough material's microfacets: Mitsuba's `distribution` (default Beckmann) and `alpha`
    /// (default 0.1, at least 1e-4 as Mitsuba clamps it).
    fn microfacet(&self, p: &Props) -> Res<Microfacet> {
        let distribution = match p.string("distribution")?.map(str::to_ascii_lowercase).as_deref() {
            None | Some("beckmann") => Distribution::Beckmann,
            Some("ggx") => Distribution::Ggx,
            Some(d) => {
                return Err(p.err_at(
                    "distribution",
                    format!("distribution \"{d}\" is not supported (beckmann, ggx)"),
                ));
            }
        };
        let alpha = match (p.float("alpha")?, p.float("alpha_u")?, p.float("alpha_v")?) {
            (Some(a), None, None) => a,
            (None, None, None) => 0.1,
            (None, Some(u), Some(v)) if u == v => u,
            (None, Some(_), Some(_)) => {
                return Err(self.ctx.err(
                    p.el,
                    "anisotropic roughness (alpha_u different from alpha_v) is not supported",
                ));
            }
            _ => return Err(self.ctx.err(p.el, "give alpha, or both alpha_u and alpha_v")),
        };
        if alpha.is_nan() || alpha < 0.0 {
            return Err(p.err_at("alpha", format!("alpha cannot be negative, not {alpha}")));
        }
        if p.boolean("sample_visible")? == Some(false) {
            return Err(p.err_at("sample_visible", "sample_visible=false is not supported".into()));
        }
        Ok(Microfacet {
            distribution,
            alpha: alpha.max(1e-4),
        })
    }

    /// int_ior / ext_ior, each a number or one of Mitsuba's names.
    fn relative_ior(&self, p: &Props, default_int: &str) -> Res<f32> {
        let read = |name: &str, default: &str| -> Res<f32> {
            let v = match p.tag_of(name) {
                Some("string") => {
                    let s = p.string(name)?.unwrap_or(default);
                    named::ior(s).map_err(|m| p.err_at(name, m))?
                }
                Some(_) => p.float(name)?.unwrap_or(1.0),
                None => named::ior(default).expect("default names are in the table"),
            };
            if v < 1.0 {
                return Err(p.err_at(name, format!("{name} must be at least 1, not {v}")));
            }
            Ok(v)
        };
        Ok(read("int_ior", default_int)? / read("ext_ior", "air")?)
    }

    fn shape(&mut self, el: &Element, area_ids: &HashMap<String, &Element>) -> Res<()> {
        let p = Props::new(self.ctx, el)?;
        let index = self.shapes.len() as u32;
        let kind = p.kind()?;
        let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        let flip = p.boolean("flip_normals")?.unwrap_or(false);
        let is_file = matches!(kind, "obj" | "ply" | "serialized");
        let mut face_normals = false;
        let mesh = match kind {
            "sphere" => {
                let center = p.point("center")?.unwrap_or(Vec3A::ZERO);
                let radius = p.positive("radius", 1.0)?;
                let m = to_world
                    * Mat4::from_translation(center.into())
                    * Mat4::from_scale(glam::Vec3::splat(radius));
                let (scale, rotation, translation) = m.to_scale_rotation_translation();
                if (scale.x - scale.y).abs() > 1e-4 * scale.x || (scale.x - scale.z).abs() > 1e-4 * scale.x {
                    return Err(self.ctx.err(el, "a sphere's to_world must scale uniformly"));
                }
                self.prims.push(Primitive::Sphere(Sphere {
                    center: translation.into(),
                    radius: scale.x.abs(),
                    shape: index,
                    flip,
                    rotation,
                }));
                None
            }
            "rectangle" => Some(mesh::rectangle()),
            "cube" => Some(mesh::cube()),
            "disk" => Some(mesh::disk()),
            "obj" | "ply" | "serialized" => {
                let name = p
                    .string("filename")?
                    .ok_or_else(|| self.ctx.err(el, "missing the filename parameter"))?;
                let path = p.resolve_file("filename", name)?;
                let mut m = match kind {
                    "obj" => mesh::load_obj(&path),
                    "ply" => mesh::load_ply(&path),
                    _ => {
                        let index = p.int("shape_index")?.unwrap_or(0);
                        if !(0..=u32::MAX as i64).contains(&index) {
                            return Err(p.err_at("shape_index", format!("shape_index cannot be {index}")));
                        }
                        mesh::load_serialized(&path, index as u32)
                    }
                }
                .map_err(|m| p.err_at("filename", format!("{}: {m}", path.display())))?;
                // Mitsuba mirrors v on OBJ files unless told not to, and on PLY files if told.
                if kind != "serialized" && p.boolean("flip_tex_coords")?.unwrap_or(kind == "obj") {
                    m.flip_tex_coords();
                }
                face_normals = p.boolean("face_normals")?.unwrap_or(false);
                if face_normals {
                    m.normals = None;
                }
                m.validate()
                    .map_err(|m| p.err_at("filename", format!("{}: {m}", path.display())))?;
                if m.triangles.is_empty() {
                    return Err(p.err_at("filename", format!("{} has no faces", path.display())));
                }
                Some(m)
            }
            other => {
                return Err(self.ctx.err(
                    el,
                    format!(
                        "shape type \"{other}\" is not supported (sphere, rectangle, cube, disk, obj, ply, serialized)"
                    ),
                ));
            }
        };
        if let Some(mesh) = mesh {
            let mut mesh = mesh.transformed(&to_world);
            // Mitsuba smooths a mesh file that has no normals, unless told to use face normals.
            if is_file && mesh.normals.is_none() && !face_normals {
                mesh.recompute_vertex_normals();
            }
            self.push_mesh(mesh, index, flip);
        }

        let (interior, exterior, _) = self.media_of(&p, true)?;
        let nested = self.nested_bsdfs(&p)?;
        let referred: Vec<&Element> = p
            .objects("ref")
            .into_iter()
            .filter_map(|r| r.attr("id").and_then(|id| area_ids.get(id)).copied())
            .collect();
        let emitter = match (p.object("emitter")?, referred.as_slice()) {
            (None, []) => None,
            (Some(e), []) => Some(e),
            (None, [e]) => {
                let id = e.attr("id").expect("referred to by id");
                if !self.area_taken.insert(id.to_string()) {
                    return Err(self.ctx.err(
                        el,
                        format!("area emitter \"{id}\" already belongs to another shape"),
                    ));
                }
                Some(*e)
            }
            _ => return Err(self.ctx.err(el, "a shape takes one emitter")),
        };
        let bsdf = match nested.len() {
            // Mitsuba's defaults: an emitter absorbs what reaches it; anything else, a medium's
            // boundary included, is grey (a boundary must say <bsdf type="null"/>).
            0 if emitter.is_some() => Bsdf::Diffuse(Diffuse {
                reflectance: Param::Fixed(Rgb::ZERO),
            }),
            0 => Bsdf::Diffuse(Diffuse {
                reflectance: Param::Fixed(Rgb::splat(0.5)),
            }),
            1 => nested.into_iter().next().expect("one element"),
            _ => return Err(self.ctx.err(el, "a shape takes one bsdf")),
        };
        if let Some(em) = emitter {
            let ep = Props::new(self.ctx, em)?;
            if ep.kind()? != "area" {
                return Err(self.ctx.err(em, "a shape can only carry an area emitter"));
            }
            let radiance = ep.emission("radiance", Rgb::ONE)?;
            ep.finish()?;
            self.area_emitters.push((index, radiance));
        }
        p.finish()?;
        self.bsdfs.push(bsdf);
        self.shapes.push(ShapeInfo {
            name: el
                .attr("id")
                .map(str::to_string)
                .unwrap_or_else(|| format!("{kind} at line {}", el.line)),
            bsdf: self.bsdfs.len() as u32 - 1,
            light: None,
            interior,
            exterior,
        });
        Ok(())
    }

    fn push_mesh(&mut self, mesh: Mesh, shape: u32, flip: bool) {
        for t in &mesh.triangles {
            let p = t.map(|i| mesh.positions[i as usize]);
            // Degenerate triangles can never be hit and would only divide by zero elsewhere.
            if (p[1] - p[0]).cross(p[2] - p[0]).length_squared() == 0.0 {
                continue;
            }
            let n = mesh
                .normals
                .as_ref()
                .map(|ns| Box::new(t.map(|i| ns[i as usize])));
            let uv = mesh.uvs.as_ref().map(|uvs| Box::new(t.map(|i| uvs[i as usize])));
            self.prims.push(Primitive::Triangle(Triangle {
                p,
                n,
                uv,
                shape,
                flip,
            }));
        }
    }

    fn emitter(&mut self, el: &Element) -> Res<()> {
        let p = Props::new(self.ctx, el)?;
        let (_, _, medium) = self.media_of(&p, false)?;
        let light = match p.kind()? {
            "point" => {
                let position = match (p.point("position")?, p.transform("to_world")?) {
                    (Some(_), Some(_)) => {
                        return Err(self.ctx.err(el, "give position or to_world, not both"));
                    }
                    (Some(pos), None) => pos,
                    (None, m) => m.unwrap_or(Mat4::IDENTITY).transform_point3a(Vec3A::ZERO),
                };
                Light::Point(PointLight {
                    position,
                    intensity: p.emission("intensity", Rgb::ONE)?,
                })
            }
            "spot" => {
                let m = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
                let cutoff = p.positive("cutoff_angle", 20.0)?;
                let beam = p.float_or("beam_width", cutoff * 0.75)?;
                if !(cutoff <= 90.0 && beam > 0.0 && beam < cutoff) {
                    return Err(self.ctx.err(
                        el,
                        format!("need 0 < beam_width < cutoff_angle <= 90 degrees (got {beam} and {cutoff})"),
                    ));
                }
                let (_, rotation, translation) = m.to_scale_rotation_translation();
                Light::Spot(SpotLight {
                    position: translation.into(),
                    to_local: Mat3A::from_quat(rotation).transpose(),
                    intensity: p.emission("intensity", Rgb::ONE)?,
                    cutoff: cutoff.to_radians(),
                    beam_width: beam.to_radians(),
                })
            }
            "beam" => {
                let m = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
                let (scale, rotation, translation) = m.to_scale_rotation_translation();
                if (scale - glam::Vec3::ONE).abs().max_element() > 1e-4 {
                    return Err(p.err_at(
                        "to_world",
                        "a beam's to_world places and turns it; set its size with radius".into(),
                    ));
                }
                let radius = p.positive("radius", 1.0)?;
                let area = std::f32::consts::PI * radius * radius;
                let irradiance = match (p.rgb("irradiance")?, p.rgb("power")?) {
                    (Some(_), Some(_)) => return Err(self.ctx.err(el, "give irradiance or power, not both")),
                    (Some(e), None) => e,
                    (None, Some(w)) => w / area,
                    (None, None) => Rgb::ONE,
                };
                if irradiance.min_element() < 0.0 {
                    return Err(self
                        .ctx
                        .err(el, "a beam's irradiance or power cannot be negative"));
                }
                let rot = Mat3A::from_quat(rotation);
                Light::Beam(BeamLight {
                    origin: translation.into(),
                    frame: Frame {
                        s: rot.x_axis,
                        t: rot.y_axis,
                        n: rot.z_axis,
                    },
                    radius,
                    irradiance,
                })
            }
            "constant" => Light::Constant(ConstantLight {
                radiance: p.emission("radiance", Rgb::ONE)?,
                sphere: SceneSphere::default(),
            }),
            "envmap" => {
                let name = p
                    .string("filename")?
                    .ok_or_else(|| self.ctx.err(el, "missing the filename parameter"))?;
                let path = p.resolve_file("filename", name)?;
                let scale = p.float_or("scale", 1.0)?;
                if !(scale >= 0.0 && scale.is_finite()) {
                    return Err(p.err_at(
                        "scale",
                        format!("scale must be a non-negative number, not {scale}"),
                    ));
                }
                // Changes how the map is sampled, not what it renders to.
                let _ = p.boolean("mis_compensation")?;
                let m = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
                // Mitsuba decodes 8-bit images from sRGB and ignores alpha, as for textures.
                let bitmap = Bitmap::load(
                    &path,
                    false,
                    TexFilter::Bilinear,
                    Wrap::Repeat,
                    glam::Affine2::IDENTITY,
                )
                .map_err(|e| p.err_at("filename", format!("{}: {e}", path.display())))?;
                let (w, h) = bitmap.size();
                Light::Envmap(Box::new(EnvmapLight::new(
                    w as usize,
                    h as usize,
                    bitmap.texels().to_vec(),
                    scale,
                    Mat3A::from_mat4(m),
                )))
            }
            "directional" => {
                let direction = match (p.point("direction")?, p.transform("to_world")?) {
                    (Some(_), Some(_)) => {
                        return Err(self.ctx.err(el, "give direction or to_world, not both"));
                    }
                    (Some(d), None) => d,
                    (None, m) => m.unwrap_or(Mat4::IDENTITY).transform_vector3a(Vec3A::Z),
                };
                let Some(direction) = direction.try_normalize() else {
                    return Err(self
                        .ctx
                        .err(el, "a directional emitter needs a non-zero direction"));
                };
                Light::Directional(DirectionalLight {
                    direction,
                    irradiance: p.emission("irradiance", Rgb::ONE)?,
                    sphere: SceneSphere::default(),
                })
            }
            "area" => {
                return Err(self
                    .ctx
                    .err(el, "an area emitter must be nested inside a <shape>"));
            }
            other => {
                return Err(self.ctx.err(
                    el,
                    format!(
                        "emitter type \"{other}\" is not supported (point, spot, area, beam, constant, envmap, directional)"
                    ),
                ));
            }
        };
        p.finish()?;
        self.lights.push(light);
        self.light_media.push(medium);
        Ok(())
    }
}

/// The 2D part of a `to_uv` transform (Mitsuba applies the 4x4 matrix to (u, v, 0, 1) and keeps
/// (x, y)).
fn uv_transform(m: &Mat4) -> glam::Affine2 {
    glam::Affine2::from_cols(
        glam::Vec2::new(m.x_axis.x, m.x_axis.y),
        glam::Vec2::new(m.y_axis.x, m.y_axis.y),
        glam::Vec2::new(m.w_axis.x, m.w_axis.y),
    )
}
