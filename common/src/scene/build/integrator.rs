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
            // Mitsuba's differentiable direct illumination: its primal image is one emitter
            // sample and one BSDF sample weighted by MIS (direct_projective.py), which our
            // path tracer computes at max_depth 2.
            "direct_projective" => Integrator::Path,
            "stokes" => {
                return Err(self.ctx.err(
                    el,
                    "the stokes integrator needs polarized rendering, which we do not do; Mitsuba \
                     refuses it outside its polarized variants too (\"This integrator should only be \
                     used in polarized mode!\")",
                ));
            }
            other => {
                return Err(self.ctx.err(
                    el,
                    format!(
                        "integrator type \"{other}\" is not supported (path, volpath, volpathmis, direct, ptracer, \
                         sppm, direct_projective, and moment or aov around one of them)"
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
        let projective = kind == "direct_projective";
        if projective {
            self.projective_params(&p)?;
            self.warnings.push(format!(
                "{}:{}: <integrator type=\"direct_projective\">: rendering its primal image (direct \
                 illumination, as path with max_depth 2); its gradients are Mitsuba's alone",
                el.file.display(),
                el.line
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
            // direct_projective sets its own depths, whatever the scene says.
            max_depth: if projective { 2 } else { max_depth as i32 },
            rr_depth: if projective { 2 } else { rr_depth as u32 },
            params,
        })
    }

    /// The parameters of Mitsuba's projective-sampling integrators, which steer only how its
    /// gradients are sampled: read (so a typo is still an error) and checked as Mitsuba checks
    /// them.
    fn projective_params(&self, p: &Props) -> Res<()> {
        for name in ["sppc", "sppp", "sppi", "guiding_rounds"] {
            if let Some(v) = p.int(name)?
                && v < 0
            {
                return Err(p.err_at(name, format!("{name} cannot be negative, not {v}")));
            }
        }
        let _ = p.boolean("guiding_proj")?;
        if let Some(g) = p.string("guiding")?
            && !matches!(g, "none" | "grid" | "octree")
        {
            return Err(p.err_at(
                "guiding",
                format!("guiding must be one of none, grid or octree, not \"{g}\""),
            ));
        }
        if let Some(s) = p.string("project_seed")?
            && !matches!(s, "both" | "bsdf" | "emitter")
        {
            return Err(p.err_at(
                "project_seed",
                format!("project_seed must be one of both, bsdf or emitter, not \"{s}\""),
            ));
        }
        Ok(())
    }
}
