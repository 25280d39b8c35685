//! `<shape>`: spheres, rectangles, disks, cubes and meshes, with their area emitters.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Mat4, Vec3A};

use crate::bsdf::{Bsdf, Diffuse};
use crate::color::Rgb;
use crate::geometry::{
    Bvh, CurveSegment, Cylinder, Instance, Primitive, SPLINE_PIECES, Sphere, SplineSegment, Triangle,
};
use crate::scene::ShapeInfo;
use crate::scene::mesh::{self, Attribute, Mesh};
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;
use crate::texture::Param;

use super::Builder;

impl Builder<'_> {
    pub(super) fn shape(&mut self, el: &Element, area_ids: &HashMap<String, &Element>) -> Res<()> {
        let p = Props::new(self.ctx, el)?;
        let index = self.shapes.len() as u32;
        let kind = p.kind()?;
        let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        if kind == "instance" {
            return self.instance(&p, &to_world);
        }
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
            "cylinder" => {
                // Mitsuba's: the tube from p0 to p1 of the radius, then to_world, which may
                // scale it but not into an ellipse.
                let p0 = p.point("p0")?.unwrap_or(Vec3A::ZERO);
                let p1 = p.point("p1")?.unwrap_or(Vec3A::Z);
                let radius = p.positive("radius", 1.0)?;
                let axis = p1 - p0;
                let length = axis.length();
                if length.is_nan() || length == 0.0 {
                    return Err(self.ctx.err(el, "a cylinder's p0 and p1 must differ"));
                }
                let f = crate::geometry::Frame::from_normal(axis / length);
                let frame = Mat4::from_cols(f.s.extend(0.0), f.t.extend(0.0), f.n.extend(0.0), glam::Vec4::W);
                let m = to_world
                    * Mat4::from_translation(p0.into())
                    * frame
                    * Mat4::from_scale(glam::Vec3::new(radius, radius, length));
                let (scale, rotation, translation) = m.to_scale_rotation_translation();
                if (scale.x.abs() - scale.y.abs()).abs() > 1e-4 * scale.x.abs() {
                    return Err(self
                        .ctx
                        .err(el, "a cylinder's to_world must scale its cross-section uniformly"));
                }
                if scale.min_element() <= 0.0 {
                    return Err(self
                        .ctx
                        .err(el, "a mirroring to_world on a cylinder is not supported"));
                }
                self.prims.push(Primitive::Cylinder(Box::new(Cylinder {
                    base: translation.into(),
                    rotation,
                    radius: scale.x,
                    length: scale.z,
                    shape: index,
                    flip,
                })));
                None
            }
            "linearcurve" | "bsplinecurve" => {
                if flip {
                    return Err(p.err_at("flip_normals", "a curve's normals cannot be flipped".into()));
                }
                let name = p
                    .string("filename")?
                    .ok_or_else(|| self.ctx.err(el, "missing the filename parameter"))?;
                let path = p.resolve_file("filename", name)?;
                let curves = std::fs::read_to_string(&path)
                    .map_err(|e| e.to_string())
                    .and_then(|text| {
                        crate::scene::curves::parse(&text, if kind == "linearcurve" { 2 } else { 4 })
                    })
                    .map_err(|m| p.err_at("filename", format!("{}: {m}", path.display())))?;
                // A linear segment joins two control points, a cubic one spans four.
                let span = if kind == "linearcurve" { 2 } else { 4 };
                let segments: u32 = curves.iter().map(|c| (c.len() + 1 - span) as u32).sum();
                let mut i = 0;
                for curve in &curves {
                    // Mitsuba moves the control points by to_world and keeps their radii.
                    let points: Vec<(Vec3A, f32)> = curve
                        .iter()
                        .map(|(q, r)| (to_world.transform_point3(glam::Vec3::from(*q)).into(), *r))
                        .collect();
                    let last = points.len() - span;
                    for (j, w) in points.windows(span).enumerate() {
                        let segment = |p: [Vec3A; 2], r: [f32; 2], caps, spline| {
                            Primitive::Curve(Box::new(CurveSegment {
                                p,
                                r,
                                shape: index,
                                index: i,
                                segments,
                                caps,
                                spline,
                            }))
                        };
                        if span == 2 {
                            self.prims
                                .push(segment([w[0].0, w[1].0], [w[0].1, w[1].1], [true; 2], None));
                        } else {
                            let spline = Arc::new(SplineSegment {
                                p: [w[0].0, w[1].0, w[2].0, w[3].0],
                                r: [w[0].1, w[1].1, w[2].1, w[3].1],
                            });
                            for k in 0..SPLINE_PIECES {
                                let v = [
                                    k as f32 / SPLINE_PIECES as f32,
                                    (k + 1) as f32 / SPLINE_PIECES as f32,
                                ];
                                let (a, b) = (spline.point(v[0]), spline.point(v[1]));
                                // Mitsuba's B-spline curves are open: no caps at their ends.
                                let caps = [j > 0 || k > 0, j < last || k + 1 < SPLINE_PIECES];
                                self.prims.push(segment(
                                    [a.0, b.0],
                                    [a.1, b.1],
                                    caps,
                                    Some((spline.clone(), v)),
                                ));
                            }
                        }
                        i += 1;
                    }
                }
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
            "shapegroup" => {
                return Err(self.ctx.err(
                    el,
                    "a shapegroup belongs at the top level of the scene (Mitsuba nests no groups)",
                ));
            }
            other => {
                return Err(self.ctx.err(
                    el,
                    format!(
                        "shape type \"{other}\" is not supported (sphere, cylinder, rectangle, cube, disk, obj, ply, \
                         serialized, linearcurve, bsplinecurve, shapegroup, instance)"
                    ),
                ));
            }
        };
        let mesh = mesh.map(|mesh| {
            let mut mesh = mesh.transformed(&to_world);
            // Mitsuba's rectangle and disk are analytic: their front is the transformed normal
            // (the inverse transpose of to_world applied to +z), not the transformed edges'
            // cross product, and the two disagree under a mirroring to_world (negative
            // determinant). Such lights used to face away, leaving an interior 30% too dark.
            // Mitsuba's cube is a mesh whose vertex normals (transformed the same way) decide
            // its front, so it too faces out.
            let mirrored = glam::Mat3::from_mat4(to_world).determinant() < 0.0;
            if matches!(kind, "rectangle" | "disk" | "cube") && mirrored {
                mesh.reverse_winding();
            }
            // Mitsuba smooths a mesh file that has no normals, unless told to use face normals.
            if is_file && mesh.normals.is_none() && !face_normals {
                mesh.recompute_vertex_normals();
            }
            mesh
        });

        let (interior, exterior, _) = self.media_of(&p, true)?;
        let read_before = self.attributes_read.len();
        let nested = self.nested_bsdfs(&p)?;
        let mut read: Vec<String> = self.attributes_read.drain(read_before..).collect();
        read.sort();
        read.dedup();
        let attribute_index = match (read.as_slice(), &mesh) {
            ([], _) => None,
            ([name], Some(mesh)) => Some(
                mesh.attributes
                    .iter()
                    .position(|a| a.name == *name)
                    .ok_or_else(|| {
                        let has: Vec<&str> = mesh.attributes.iter().map(|a| a.name.as_str()).collect();
                        self.ctx.err(
                            el,
                            format!(
                                "its material reads mesh attribute \"{name}\", which the mesh has not (it has: {})",
                                if has.is_empty() { "none".to_string() } else { has.join(", ") }
                            ),
                        )
                    })?,
            ),
            ([name], None) => {
                return Err(self.ctx.err(
                    el,
                    format!("its material reads mesh attribute \"{name}\", and a {kind} is not a mesh with attributes"),
                ));
            }
            _ => {
                return Err(self.ctx.err(
                    el,
                    format!("its material reads mesh attributes {}: one per shape is supported", read.join(", ")),
                ));
            }
        };
        if let Some(mut mesh) = mesh {
            // Taken out of the mesh, not copied: the triangles keep their own corners of it.
            let attribute = attribute_index.map(|i| mesh.attributes.swap_remove(i));
            self.push_mesh(mesh, index, flip, attribute.as_ref());
        }
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
            if kind.ends_with("curve") {
                return Err(self.ctx.err(
                    em,
                    "a curve cannot be an emitter (Mitsuba cannot sample points on one)",
                ));
            }
            let radiance = match self.light_texture(&ep, "radiance")? {
                Some(t) => Param::Textured(t),
                None => Param::Fixed(ep.emission("radiance", Rgb::ONE)?),
            };
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

    /// A `<shape type="shapegroup">`: its shapes, in a tree of their own for instances to
    /// place. They keep their materials; emitters cannot be instanced (nor can they in Mitsuba).
    pub(super) fn shape_group(
        &mut self,
        el: &Element,
        area_ids: &HashMap<String, &Element>,
    ) -> Res<Arc<Bvh>> {
        let p = Props::new(self.ctx, el)?;
        let _ = p.kind()?;
        // The group's shapes go to a list of their own. An error ends the whole load, so the
        // scene's list needs restoring only on success.
        let outer = std::mem::take(&mut self.prims);
        let lights = self.area_emitters.len();
        for child in p.objects("shape") {
            if child.attr("type") == Some("instance") {
                return Err(self.ctx.err(child, "a shapegroup cannot hold an instance"));
            }
            self.shape(child, area_ids)?;
            if self.area_emitters.len() != lights {
                return Err(self.ctx.err(
                    child,
                    "an emitter cannot be part of a shapegroup (Mitsuba does not instance emitters)",
                ));
            }
        }
        p.finish()?;
        let prims = std::mem::replace(&mut self.prims, outer);
        if prims.is_empty() {
            return Err(self.ctx.err(el, "a shapegroup needs at least one shape"));
        }
        Ok(Arc::new(Bvh::build(prims)))
    }

    /// A `<shape type="instance">`: a `<ref>` to a shape group, placed by `to_world`.
    fn instance(&mut self, p: &Props, to_world: &Mat4) -> Res<()> {
        let refs = p.objects("ref");
        let [r] = refs.as_slice() else {
            return Err(self.ctx.err(p.el, "an instance needs one <ref> to a shapegroup"));
        };
        let id = r
            .attr("id")
            .ok_or_else(|| self.ctx.err(r, "a <ref> needs an id"))?;
        let group = self
            .groups
            .get(id)
            .ok_or_else(|| self.ctx.err(r, format!("no shapegroup with id \"{id}\"")))?
            .clone();
        p.finish()?;
        let instance = Instance::new(group, glam::Affine3A::from_mat4(*to_world))
            .ok_or_else(|| self.ctx.err(p.el, "an instance's to_world cannot be inverted"))?;
        self.prims.push(Primitive::Instance(Box::new(instance)));
        Ok(())
    }

    /// Adds a mesh's triangles, with the values of `attribute` (the one its material reads).
    pub(super) fn push_mesh(&mut self, mesh: Mesh, shape: u32, flip: bool, attribute: Option<&Attribute>) {
        for (i, t) in mesh.triangles.iter().enumerate() {
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
            let attr = attribute.map(|a| Box::new(a.corners(i, t)));
            self.prims.push(Primitive::Triangle(Triangle {
                p,
                n,
                uv,
                attr,
                shape,
                flip,
            }));
        }
    }
}
