//! `<bsdf>`: every material plugin, its roughness and index of refraction.

use crate::bsdf::{
    Bsdf, Coating, Conductor, Dielectric, Diffuse, Distribution, Microfacet, Perturbation, Perturbed,
    Plastic, Principled, RoughDielectric, Roughness, ThinDielectric, eta_from_specular,
};
use crate::color::Rgb;
use crate::scene::named;
use crate::scene::props::{Props, Res};
use crate::scene::xml::Element;
use crate::texture::{Param, Texture};

use super::Builder;

impl Builder<'_> {
    /// A `<bsdf>` or `<ref>` to one.
    pub(super) fn bsdf_or_ref(&mut self, el: &Element) -> Res<Bsdf> {
        if el.tag == "ref" {
            let id = el
                .attr("id")
                .ok_or_else(|| self.ctx.err(el, "a <ref> needs an id"))?;
            return self.named_bsdf(el, id);
        }
        // Every named material inside a material or a shape was built when its name was
        // registered (`Builder::scene`), before whatever nests it.
        if let Some(id) = el.attr("id")
            && self.bsdf_ids.contains_key(id)
        {
            return self.named_bsdf(el, id);
        }
        self.bsdf(el)
    }

    /// The material built under `id`, with the mesh attributes it reads.
    fn named_bsdf(&mut self, el: &Element, id: &str) -> Res<Bsdf> {
        let i = *self
            .bsdf_ids
            .get(id)
            .ok_or_else(|| self.ctx.err(el, format!("no <bsdf> with id \"{id}\"")))?;
        if let Some(read) = self.bsdf_attributes.get(&i) {
            self.attributes_read.extend(read.iter().cloned());
        }
        Ok(self.bsdfs[i as usize].clone())
    }

    pub(super) fn nested_bsdfs(&mut self, p: &Props) -> Res<Vec<Bsdf>> {
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

    pub(super) fn bsdf(&mut self, el: &Element) -> Res<Bsdf> {
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
                let diffuse = self.color_param(&p, "diffuse_reflectance", Rgb::splat(0.5))?;
                let specular = self.color_param(&p, "specular_reflectance", Rgb::ONE)?;
                // Plastic weighs its lobes by the textures' means, which Mitsuba does not
                // define for an attribute (it fails to load such a scene).
                for (name, param) in [
                    ("diffuse_reflectance", &diffuse),
                    ("specular_reflectance", &specular),
                ] {
                    if let Param::Textured(t) = param
                        && t.attribute().is_some()
                    {
                        return Err(p.err_at(
                            name,
                            format!("{kind}'s {name} cannot be a mesh_attribute: it needs the texture's mean, which an attribute has not (Mitsuba refuses it too)"),
                        ));
                    }
                }
                let eta = self.relative_ior(&p, "polypropylene")?;
                let key = (
                    roughness.map(|m| (m.distribution, m.alpha_u.to_bits(), m.alpha_v.to_bits())),
                    eta.to_bits(),
                );
                let coating = self
                    .coatings
                    .entry(key)
                    .or_insert_with(|| Coating::new(roughness, eta))
                    .clone();
                Bsdf::Plastic(Box::new(Plastic::with_coating(
                    diffuse,
                    specular,
                    p.boolean("nonlinear")?.unwrap_or(false),
                    coating,
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
            "polarizer" => {
                // Its angle and polarizing switch matter only to polarized light, which Mitsuba's
                // RGB variants do not carry either.
                // Mitsuba reads theta as a texture, so scenes give it as a number, a spectrum or
                // a texture.
                if self.texture_param(&p, "theta")?.is_none() {
                    let _ = p.rgb("theta")?;
                }
                let _ = p.boolean("polarizing")?;
                Bsdf::Polarizer(self.color_param(&p, "transmittance", Rgb::ONE)?)
            }
            kind @ ("normalmap" | "bumpmap") => Bsdf::Perturbed(Box::new(self.perturbed(kind, &p)?)),
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
                         twosided, blendbsdf, mask, normalmap, bumpmap, null, polarizer)"
                    ),
                ));
            }
        };
        p.finish()?;
        Ok(bsdf)
    }

    /// Mitsuba's `normalmap` (a texture named `normalmap`) or `bumpmap` (one nested bitmap of
    /// any name, and its `scale`), each around one nested material.
    fn perturbed(&mut self, kind: &str, p: &Props) -> Res<Perturbed> {
        let by = if kind == "normalmap" {
            let map = self.texture_param(p, "normalmap")?.ok_or_else(|| {
                self.ctx
                    .err(p.el, "normalmap needs a <texture name=\"normalmap\">")
            })?;
            Perturbation::Normal(map)
        } else {
            let mut textures = Vec::new();
            for el in p.objects("texture") {
                textures.push((el, std::sync::Arc::new(self.texture(el)?)));
            }
            for el in p.objects("ref") {
                if let Some(t) = el.attr("id").and_then(|id| self.texture_ids.get(id)) {
                    textures.push((el, t.clone()));
                }
            }
            if textures.len() != 1 {
                return Err(self.ctx.err(
                    p.el,
                    format!("bumpmap needs one nested texture, not {}", textures.len()),
                ));
            }
            let (el, texture) = textures.remove(0);
            let Texture::Bitmap(height) = &*texture else {
                return Err(self.ctx.err(
                    el,
                    "bumpmap needs a bitmap texture: Mitsuba differentiates no other kind",
                ));
            };
            Perturbation::Bump {
                height: Box::new(height.clone()),
                scale: p.float_or("scale", 1.0)?,
            }
        };
        let mut nested = self.nested_bsdfs(p)?;
        if nested.len() != 1 {
            return Err(self.ctx.err(
                p.el,
                format!("{kind} needs one nested bsdf, not {}", nested.len()),
            ));
        }
        Ok(Perturbed {
            nested: nested.remove(0),
            by,
            flip_invalid_normals: p.boolean("flip_invalid_normals")?.unwrap_or(true),
            shadowing: p.boolean("use_shadowing_function")?.unwrap_or(true),
        })
    }

    /// Mitsuba's `principled`: every parameter it reads, with its defaults. Its weights are
    /// numbers in [0, 1] or textures; `eta` and `specular` (one or the other) are numbers.
    pub(super) fn principled(&mut self, p: &Props) -> Res<Principled> {
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

    /// A rough conductor's or dielectric's microfacets, as Mitsuba reads them: `alpha`, or both
    /// `alpha_u` and `alpha_v` (anisotropic), each a number or a texture; 0.1 by default.
    pub(super) fn roughness(&mut self, p: &Props) -> Res<Roughness> {
        let distribution = self.distribution(p)?;
        let given = |name: &str| {
            p.tag_of(name).is_some()
                || p.named_object("texture", name).is_some()
                || p.named_object("ref", name).is_some()
        };
        let mut param = |name: &str| -> Res<Param<f32>> {
            let a = self.float_param(p, name, 0.1)?;
            match a {
                Param::Fixed(x) if x.is_nan() || x < 0.0 => {
                    Err(p.err_at(name, format!("{name} cannot be negative, not {x}")))
                }
                a => Ok(a),
            }
        };
        match (given("alpha"), given("alpha_u"), given("alpha_v")) {
            (_, false, false) => Ok(Roughness::isotropic(distribution, param("alpha")?)),
            (false, true, true) => {
                let (alpha_u, alpha_v) = (param("alpha_u")?, param("alpha_v")?);
                let anisotropic =
                    !matches!((&alpha_u, &alpha_v), (Param::Fixed(u), Param::Fixed(v)) if u == v);
                Ok(Roughness {
                    distribution,
                    alpha_u,
                    alpha_v,
                    anisotropic,
                })
            }
            (true, _, _) => Err(self.ctx.err(p.el, "give alpha, or alpha_u and alpha_v, not both")),
            _ => Err(self.ctx.err(p.el, "give both alpha_u and alpha_v")),
        }
    }

    /// Mitsuba's `distribution` (default Beckmann), sampled by its visible normals.
    fn distribution(&self, p: &Props) -> Res<Distribution> {
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
        if p.boolean("sample_visible")? == Some(false) {
            return Err(p.err_at("sample_visible", "sample_visible=false is not supported".into()));
        }
        Ok(distribution)
    }

    /// A rough plastic's microfacets: Mitsuba's `distribution` and one `alpha` (default 0.1, at
    /// least 1e-4 as Mitsuba clamps it); Mitsuba's roughplastic has no anisotropic form.
    pub(super) fn microfacet(&self, p: &Props) -> Res<Microfacet> {
        let distribution = self.distribution(p)?;
        if p.tag_of("alpha_u").is_some() || p.tag_of("alpha_v").is_some() {
            return Err(self.ctx.err(
                p.el,
                "roughplastic takes one alpha (Mitsuba's has no alpha_u or alpha_v)",
            ));
        }
        let alpha = p.float("alpha")?.unwrap_or(0.1);
        if alpha.is_nan() || alpha < 0.0 {
            return Err(p.err_at("alpha", format!("alpha cannot be negative, not {alpha}")));
        }
        Ok(Microfacet::isotropic(distribution, alpha.max(1e-4)))
    }

    /// int_ior / ext_ior, each a number or one of Mitsuba's names.
    pub(super) fn relative_ior(&self, p: &Props, default_int: &str) -> Res<f32> {
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
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use crate::bsdf::Bsdf;
    use crate::scene::Scene;

    /// Plastics of one roughness and index share their coating's table; another roughness, or
    /// another index, gets its own.
    #[test]
    fn plastics_share_coatings_of_equal_roughness_and_index() {
        let plastic = |alpha: f32, ior: f32, rgb: &str| {
            format!(
                r#"<shape type="sphere"><bsdf type="roughplastic"><float name="alpha" value="{alpha}"/>
                <float name="int_ior" value="{ior}"/><rgb name="diffuse_reflectance" value="{rgb}"/>
                </bsdf></shape>"#
            )
        };
        let text = format!(
            r#"<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm"/></sensor>{}{}{}{}</scene>"#,
            plastic(0.2, 1.5, "0.2, 0.4, 0.6"),
            plastic(0.2, 1.5, "0.7, 0.1, 0.1"),
            plastic(0.3, 1.5, "0.2, 0.4, 0.6"),
            plastic(0.2, 1.6, "0.2, 0.4, 0.6"),
        );
        let scene = Scene::from_str(&text, Path::new("t.xml"), &[]).unwrap();
        let plastics: Vec<_> = scene
            .bsdfs
            .iter()
            .filter_map(|b| match b {
                Bsdf::Plastic(p) => Some(p),
                _ => None,
            })
            .collect();
        assert_eq!(plastics.len(), 4);
        assert!(plastics[0].shares_coating(plastics[1]));
        assert!(!plastics[0].shares_coating(plastics[2]));
        assert!(!plastics[0].shares_coating(plastics[3]));
    }
}
