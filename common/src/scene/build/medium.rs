//! `<medium>`, and the media a shape or sensor lies in.

use crate::color::Rgb;
use crate::medium::{Medium, Phase};
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;

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

    /// `<medium type="homogeneous">` with an optional nested `<phase>`.
    pub(super) fn medium(&mut self, el: &Element) -> Res<u32> {
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
}
