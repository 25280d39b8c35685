//! `<texture>`, and the parameters of other elements that take a texture or a value.

use std::sync::Arc;

use glam::Mat4;

use crate::color::Rgb;
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;
use crate::texture::{Bitmap, Filter as TexFilter, Param, Texture, Wrap};

use super::Builder;

impl Builder<'_> {
    /// A texture given for parameter `name`: nested (`<texture name=...>`) or a `<ref>` to a
    /// top-level one. A mesh attribute's name is noted for the shape that will carry the material.
    pub(super) fn texture_param(&mut self, p: &Props, name: &str) -> Res<Option<Arc<Texture>>> {
        let texture = if let Some(el) = p.named_object("texture", name) {
            Arc::new(self.texture(el)?)
        } else if let Some(el) = p.named_object("ref", name) {
            let id = el
                .attr("id")
                .ok_or_else(|| self.ctx.err(el, "a <ref> needs an id"))?;
            match self.texture_ids.get(id) {
                Some(t) => t.clone(),
                None => return Err(self.ctx.err(el, format!("no <texture> with id \"{id}\""))),
            }
        } else {
            return Ok(None);
        };
        if let Some(attribute) = texture.attribute() {
            self.attributes_read.push(attribute.to_string());
        }
        Ok(Some(texture))
    }

    /// A texture given to a light: never a mesh attribute, as a light has no mesh to read it
    /// from and is chosen by its texture's mean (Mitsuba has none for an attribute either).
    pub(super) fn light_texture(&mut self, p: &Props, name: &str) -> Res<Option<Arc<Texture>>> {
        let texture = self.texture_param(p, name)?;
        if texture.as_ref().is_some_and(|t| t.attribute().is_some()) {
            return Err(p.err_at(name, format!("a light's {name} cannot be a mesh_attribute")));
        }
        Ok(texture)
    }

    /// A colour parameter of a material: a texture, or a reflectance in [0, 1].
    pub(super) fn color_param(&mut self, p: &Props, name: &str, default: Rgb) -> Res<Param<Rgb>> {
        match self.texture_param(p, name)? {
            Some(t) => Ok(Param::Textured(t)),
            None => Ok(Param::Fixed(p.reflectance(name, default)?)),
        }
    }

    /// A number parameter of a material: a texture, or a number (an `<rgb>` is its mean).
    pub(super) fn float_param(&mut self, p: &Props, name: &str, default: f32) -> Res<Param<f32>> {
        match self.texture_param(p, name)? {
            Some(t) => Ok(Param::Textured(t)),
            None => Ok(Param::Fixed(p.float_of_texture(name, default)?)),
        }
    }

    /// A `<texture>`: Mitsuba's `bitmap`, `checkerboard` or `mesh_attribute`.
    pub(super) fn texture(&mut self, el: &Element) -> Res<Texture> {
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
                let wrap = wrap_mode(&p, Wrap::Repeat)?;
                let raw = p.boolean("raw")?.unwrap_or(false);
                // Storage precision and GPU filtering in Mitsuba: no effect on the values.
                let _ = (p.string("format")?, p.boolean("accel")?);
                let bitmap = Bitmap::load(&path, raw, filter, wrap, to_uv)
                    .map_err(|e| p.err_at("filename", format!("{}: {e}", path.display())))?;
                Texture::Bitmap(bitmap)
            }
            "mesh_attribute" => {
                let name = p.string("name")?.ok_or_else(|| {
                    self.ctx
                        .err(el, "missing the name parameter (vertex_… or face_…)")
                })?;
                if !(name.starts_with("vertex_") || name.starts_with("face_")) {
                    return Err(p.err_at(
                        "name",
                        format!("a mesh attribute's name starts with vertex_ or face_, not \"{name}\""),
                    ));
                }
                Texture::Attribute {
                    name: name.to_string(),
                    scale: p.float("scale")?.unwrap_or(1.0),
                }
            }
            "rawconstant" => {
                let value = match p.tag_of("value") {
                    Some("vector" | "point") => p.point("value")?.expect("tagged"),
                    Some(_) => Rgb::splat(p.float("value")?.ok_or_else(|| {
                        p.err_at("value", "a rawconstant's value is a <float> or a <vector>".into())
                    })?),
                    None => {
                        return Err(self
                            .ctx
                            .err(el, "missing the value parameter (a <float> or a <vector>)"));
                    }
                };
                Texture::Constant(value)
            }
            "checkerboard" => Texture::Checkerboard {
                color0: p.reflectance("color0", Rgb::splat(0.4))?,
                color1: p.reflectance("color1", Rgb::splat(0.2))?,
                to_uv,
            },
            other => {
                return Err(self.ctx.err(
                    el,
                    format!(
                        "texture type \"{other}\" is not supported (bitmap, checkerboard, mesh_attribute, rawconstant)"
                    ),
                ));
            }
        };
        p.finish()?;
        Ok(texture)
    }
}

/// A `wrap_mode` parameter (bitmaps default to `repeat`, grid volumes to `clamp`).
pub(super) fn wrap_mode(p: &Props, default: Wrap) -> Res<Wrap> {
    Ok(match p.string("wrap_mode")? {
        None => default,
        Some("repeat") => Wrap::Repeat,
        Some("mirror") => Wrap::Mirror,
        Some("clamp") => Wrap::Clamp,
        Some(w) => {
            return Err(p.err_at(
                "wrap_mode",
                format!("wrap_mode \"{w}\" is not supported (repeat, mirror, clamp)"),
            ));
        }
    })
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
