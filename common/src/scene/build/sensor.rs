//! `<sensor>` with its `<film>`, `<rfilter>` and `<sampler>`.

use glam::Mat4;

use crate::camera::Camera;
use crate::filter::Filter;
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;

use super::Builder;

/// The widest reconstruction filter, in pixels on each side of a sample's own.
const MAX_FILTER_REACH: u32 = 8;

impl Builder<'_> {
    pub(super) fn sensor(&mut self, el: &Element) -> Res<(Camera, u32, Filter)> {
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
            "perspective" | "orthographic" => {
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
                    format!("sensor type \"{other}\" is not supported (perspective, thinlens, orthographic)"),
                ));
            }
        };
        for name in ["principal_point_offset_x", "principal_point_offset_y"] {
            if p.float(name)?.is_some_and(|v| v != 0.0) {
                return Err(p.err_at(name, format!("a nonzero {name} is not supported")));
            }
        }
        let orthographic = kind == "orthographic";
        let (fov, fov_axis) = self.field_of_view(&p, el, orthographic)?;

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

        let aspect = width as f64 / height as f64;
        let tan_half_x = if orthographic {
            1.0
        } else {
            tan_half_x(&p, fov, fov_axis, aspect)?
        };
        let camera = Camera {
            to_world,
            tan_half_x: tan_half_x as f32,
            tan_half_y: (tan_half_x / aspect) as f32,
            orthographic,
            width,
            height,
            aperture_radius,
            focus_distance,
            near_clip,
        };
        Ok((camera, spp, filter))
    }

    /// Mitsuba's field of view of a perspective camera or projector: `fov` along `fov_axis`
    /// (default x), or `focal_length` (default 50 mm) along the 35 mm film's diagonal. In
    /// degrees, with its axis.
    pub(super) fn field_of_view<'a>(
        &self,
        p: &Props<'a>,
        el: &Element,
        orthographic: bool,
    ) -> Res<(f32, &'a str)> {
        let (fov, fov_axis) = match (p.float("fov")?, p.string("focal_length")?) {
            // Mitsuba's orthographic camera has no field of view: its to_world's scale sets
            // the extent it sees.
            (None, None) if orthographic => (90.0, "x"),
            _ if orthographic => {
                return Err(self.ctx.err(
                    el,
                    "an orthographic sensor takes no fov or focal_length: scale its to_world",
                ));
            }
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
                    (2.0 * libm::atan(diagonal / (2.0 * mm as f64)).to_degrees()) as f32,
                    "diagonal",
                )
            }
        };
        if !(fov > 0.0 && fov < 180.0) {
            return Err(p.err_at("fov", format!("fov must lie in (0, 180) degrees, not {fov}")));
        }

        Ok((fov, fov_axis))
    }

    pub(super) fn film(&mut self, el: &Element) -> Res<(u32, u32, Filter)> {
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
    pub(super) fn rfilter(&self, el: &Element) -> Res<Filter> {
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

    pub(super) fn sampler(&mut self, el: &Element) -> Res<u32> {
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
}

/// tan(fov_x / 2) of a field of view `fov` (degrees) along `fov_axis` on an image of width over
/// height `aspect`: Mitsuba converts every fov_axis to the x axis's field of view.
pub(super) fn tan_half_x(p: &Props, fov: f32, fov_axis: &str, aspect: f64) -> Res<f64> {
    let tan_half = libm::tan((fov as f64).to_radians() * 0.5);
    Ok(match fov_axis {
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
    })
}
