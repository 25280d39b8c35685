//! `<medium>`, and the media a shape or sensor lies in.

use glam::{Affine3A, Mat4};

use crate::color::Rgb;
use crate::medium::{Density, Grids, Medium, Phase};
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;
use crate::texture::Wrap;
use crate::volume::{GridVolume, VolumeData, VolumeFilter};

use super::Builder;

impl Builder<'_> {
    /// The media an element declares: `interior`, `exterior` (shapes) or an unnamed one
    /// (sensors, emitters), each as a nested `<medium>` or a `<ref>`.
    pub(super) fn media_of(
        &mut self,
        p: &Props,
        named: bool,
    ) -> Res<(Option<u32>, Option<u32>, Option<u32>)> {
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

    /// `<medium type="homogeneous">` or `"heterogeneous"`, with an optional nested `<phase>`.
    /// A homogeneous medium's albedo may come from a `<volume>`; a heterogeneous one's σt and
    /// albedo may both.
    pub(super) fn medium(&mut self, el: &Element) -> Res<u32> {
        let p = Props::new(self.ctx, el)?;
        let kind = p.kind()?;
        if kind != "homogeneous" && kind != "heterogeneous" {
            return Err(self.ctx.err(
                el,
                format!("medium type \"{kind}\" is not supported (homogeneous, heterogeneous)"),
            ));
        }
        let scale = p.float_or("scale", 1.0)?;
        if scale < 0.0 {
            return Err(p.err_at("scale", "scale cannot be negative".into()));
        }
        let (sigma_t, density) = match (kind, p.named_object("volume", "sigma_t")) {
            ("homogeneous", Some(v)) => {
                return Err(self.ctx.err(
                    v,
                    "a homogeneous medium's sigma_t is a constant; a medium whose density varies is type=\"heterogeneous\"",
                ));
            }
            ("homogeneous", None) => (p.non_negative_rgb("sigma_t", Rgb::ONE)? * scale, None),
            (_, v) => {
                let grid = match v {
                    Some(v) => self.volume(v)?,
                    // Mitsuba's constvolume, which like every volume covers the unit cube.
                    None => constant_volume(p.non_negative_rgb("sigma_t", Rgb::ONE)?, Mat4::IDENTITY),
                };
                if grid.min() < 0.0 {
                    return Err(p.err_at(
                        "sigma_t",
                        format!("sigma_t cannot be negative: the grid holds {}", grid.min()),
                    ));
                }
                let majorant = scale * grid.max();
                let density = Density {
                    grid,
                    scale,
                    majorant,
                };
                (Rgb::splat(majorant), Some(density))
            }
        };
        let (albedo, albedo_grid) = match p.named_object("volume", "albedo") {
            Some(v) => (Rgb::splat(0.75), Some(self.volume(v)?)),
            None => (p.reflectance("albedo", Rgb::splat(0.75))?, None),
        };
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
        let grids = (density.is_some() || albedo_grid.is_some()).then(|| {
            Box::new(Grids {
                density,
                albedo: albedo_grid,
            })
        });
        self.media.push(Medium {
            grids,
            ..Medium::homogeneous(sigma_t, albedo, phase)
        });
        Ok(self.media.len() as u32 - 1)
    }

    /// A `<volume>`: Mitsuba's `gridvolume` (a `.vol` file) or `constvolume`.
    fn volume(&mut self, el: &Element) -> Res<GridVolume> {
        let p = Props::new(self.ctx, el)?;
        let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        let volume = match p.kind()? {
            "gridvolume" => {
                let name = p
                    .string("filename")?
                    .ok_or_else(|| self.ctx.err(el, "missing the filename parameter"))?;
                let path = p.resolve_file("filename", name)?;
                let data = std::fs::read(&path)
                    .map_err(crate::volume::VolumeError::from)
                    .and_then(|bytes| VolumeData::parse(&bytes))
                    .map_err(|e| p.err_at("filename", format!("{}: {e}", path.display())))?;
                let filter = match p.string("filter_type")? {
                    None | Some("trilinear") => VolumeFilter::Trilinear,
                    Some("nearest") => VolumeFilter::Nearest,
                    Some(f) => {
                        return Err(p.err_at(
                            "filter_type",
                            format!("filter_type \"{f}\" is not supported (trilinear, nearest)"),
                        ));
                    }
                };
                let wrap = super::texture::wrap_mode(&p, Wrap::Clamp)?;
                let use_grid_bbox = p.boolean("use_grid_bbox")?.unwrap_or(false);
                // Spectral upsampling and GPU textures in Mitsuba: no effect on RGB values.
                let _ = (p.boolean("raw")?, p.boolean("accel")?);
                GridVolume::new(data, affine(&to_world), use_grid_bbox, filter, wrap)
            }
            "constvolume" => constant_volume(p.non_negative_rgb("value", Rgb::ONE)?, to_world),
            other => {
                return Err(self.ctx.err(
                    el,
                    format!("volume type \"{other}\" is not supported (gridvolume, constvolume)"),
                ));
            }
        };
        p.finish()?;
        Ok(volume)
    }
}

/// A constant as a one-voxel grid over the unit cube under `to_world`, the box Mitsuba gives
/// every volume.
fn constant_volume(value: Rgb, to_world: Mat4) -> GridVolume {
    let data = VolumeData {
        res: [1, 1, 1],
        channels: 3,
        values: Box::new([value.x, value.y, value.z]),
        bbox: crate::geometry::Aabb {
            min: glam::Vec3A::ZERO,
            max: glam::Vec3A::ONE,
        },
    };
    GridVolume::new(data, affine(&to_world), false, VolumeFilter::Nearest, Wrap::Clamp)
}

/// The affine part of a transform (Mitsuba's volumes take no projection).
fn affine(m: &Mat4) -> Affine3A {
    Affine3A::from_mat4(*m)
}
