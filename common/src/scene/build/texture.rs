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
    /// top-level one.
    pub(super) fn texture_param(&mut self, p: &Props, name: &str) -> Res<Option<Arc<Texture>>> {
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

    /// A `<texture>`: Mitsuba's `bitmap` or `checkerboard`.
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
