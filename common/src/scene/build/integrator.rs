//! `<integrator>`: reduced to the method of ours that renders it, with its parameters typed.

use super::Builder;
use crate::job::Integrator;
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;
use crate::scene::{IntegratorDecl, MethodParams, SppmParams};

impl Builder<'_> {
    /// `<integrator>`, reduced to the method of ours that renders it: `path` (Mitsuba's `path`,
    /// `volpath`, `volpathmis`), `direct`, `ptracer` or `sppm` (ours). The wrappers `moment` and
    /// `aov` render their first nested integrator.
    pub(super) fn integrator(&mut self, el: &Element) -> Res<IntegratorDecl> {
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
        let params = match method {
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
                MethodParams::Direct {
                    emitter_samples: e as u32,
                    bsdf_samples: b as u32,
                }
            }
            // Mitsuba's sppm parameters, and ours (k, volume_radius_ratio, iterations); any
            // other is refused by `finish`, as in every other element.
            Integrator::Sppm => MethodParams::Sppm(SppmParams {
                photon_count: match p.int("photon_count")? {
                    Some(n) if n > 0 => Some(n as u64),
                    Some(n) => {
                        return Err(
                            p.err_at("photon_count", format!("photon_count must be positive, not {n}"))
                        );
                    }
                    None => None,
                },
                initial_radius: p.float("initial_radius")?,
                alpha: p.float("alpha")?.map(f64::from),
                k: p.float("k")?,
                volume_radius_ratio: p.float("volume_radius_ratio")?,
                iterations: p.float("iterations")?.map(f64::from),
            }),
            _ => MethodParams::None,
        };
        p.finish()?;
        Ok(IntegratorDecl {
            kind: method,
            max_depth: max_depth as i32,
            rr_depth: rr_depth as u32,
            params,
        })
    }
}
