//! `<emitter>`: every light that is not a shape's.

use glam::{Mat3A, Mat4, Vec3A};

use crate::color::Rgb;
use crate::geometry::Frame;
use crate::light::{
    BeamLight, ConstantLight, DirectionalLight, EnvmapLight, Light, PointLight, ProjectorLight, SceneSphere,
    SpotLight,
};
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;
use crate::texture::{Bitmap, Filter as TexFilter, Param, Texture, Wrap};

use super::Builder;

impl Builder<'_> {
    pub(super) fn emitter(&mut self, el: &Element) -> Res<()> {
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
                    texture: self.light_texture(&p, "texture")?,
                })
            }
            "projector" => {
                let (rotation, translation) = placement(
                    &p,
                    "a projector's to_world places and turns it; set its spread with fov",
                )?;
                let irradiance = match self.light_texture(&p, "irradiance")? {
                    Some(t) => Param::Textured(t),
                    None => match p.tag_of("irradiance") {
                        Some(_) => Param::Fixed(p.emission("irradiance", Rgb::ONE)?),
                        None => return Err(self.ctx.err(el, "a projector needs an irradiance")),
                    },
                };
                // Mitsuba sizes the virtual image by the texture's resolution (1 x 1 for
                // anything but a bitmap).
                let (w, h) = match &irradiance {
                    Param::Textured(t) => match t.as_ref() {
                        Texture::Bitmap(b) => b.size(),
                        _ => (1, 1),
                    },
                    Param::Fixed(_) => (1, 1),
                };
                let aspect = w as f64 / h as f64;
                let (fov, fov_axis) = self.field_of_view(&p, el, false)?;
                Light::Projector(ProjectorLight {
                    position: translation.into(),
                    to_local: Mat3A::from_quat(rotation).transpose(),
                    tan_half_x: super::sensor::tan_half_x(&p, fov, fov_axis, aspect)? as f32,
                    aspect: aspect as f32,
                    irradiance,
                    scale: p.float_or("scale", 1.0)?,
                })
            }
            "beam" => {
                let (rotation, translation) = placement(
                    &p,
                    "a beam's to_world places and turns it; set its size with radius",
                )?;
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
                    bitmap.texels(),
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
                        "emitter type \"{other}\" is not supported (point, spot, projector, area, beam, constant, envmap, directional)"
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

/// The rotation and translation of a light's `to_world`, which must not scale (`refusal` says
/// what to set instead).
fn placement(p: &Props, refusal: &str) -> Res<(glam::Quat, glam::Vec3)> {
    let m = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
    let (scale, rotation, translation) = m.to_scale_rotation_translation();
    if (scale - glam::Vec3::ONE).abs().max_element() > 1e-4 {
        return Err(p.err_at("to_world", refusal.into()));
    }
    Ok((rotation, translation))
}
