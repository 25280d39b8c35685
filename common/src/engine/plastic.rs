//! Rough plastic in lanes: Mitsuba's `roughplastic` with the GGX distribution (`bsdf/plastic.rs`
//! is the scalar definition, followed operation by operation), so that interiors, whose
//! furniture and floors are mostly rough plastic (44-46% of both interiors' area), shade in
//! the lanes. Beckmann's visible normals need erf and its inverse in f64; those plastics stay
//! with the scalar code, as do smooth coatings (a delta lobe).

use std::f32::consts::{FRAC_1_PI, PI};
use std::sync::Arc;

use super::lanes::{F8, LANES, M8, V8};
use super::math::sincos_turn;
use crate::bsdf::Plastic;
use crate::bsdf::microfacet::Distribution;
use crate::texture::Param;

/// What the lanes need of one rough plastic; its diffuse reflectance is the triangle's.
#[derive(Clone, Debug)]
pub(super) struct LanePlastic {
    alpha_u: f32,
    alpha_v: f32,
    eta: f32,
    internal_reflectance: f32,
    nonlinear: bool,
    specular_weight: f32,
    specular: [f32; 3],
    table: Arc<[f32]>,
}

impl LanePlastic {
    /// Whether the lanes model `p`: a GGX coating with a fixed specular tint.
    pub(super) fn models(p: &Plastic) -> bool {
        p.roughness.is_some_and(|m| m.distribution == Distribution::Ggx)
            && matches!(p.specular, Param::Fixed(_))
    }

    /// What the lanes need of `p`, if they model it (its diffuse reflectance is the
    /// triangle's).
    pub(super) fn new(p: &Plastic) -> Option<LanePlastic> {
        let (Some(mf), Param::Fixed(specular)) = (p.roughness, &p.specular) else {
            return None;
        };
        if !Self::models(p) {
            return None;
        }
        let (specular_weight, internal_reflectance, table) = p.coating_parts();
        Some(LanePlastic {
            alpha_u: mf.alpha_u,
            alpha_v: mf.alpha_v,
            eta: p.eta,
            internal_reflectance,
            nonlinear: p.nonlinear,
            specular_weight,
            specular: specular.to_array(),
            table: table.clone(),
        })
    }
}

/// Eight lanes' plastics (those of lanes that are not plastic are a copy of another's).
pub(super) struct Plastics<'a> {
    alpha_u: F8,
    alpha_v: F8,
    eta: F8,
    internal_reflectance: F8,
    nonlinear: M8,
    specular_weight: F8,
    specular: V8,
    tables: [&'a [f32]; LANES],
}

/// Marks a lane whose triangle is not plastic in [`Plastics::gather`]'s indices.
pub(super) const NO_PLASTIC: u32 = u32::MAX;

impl<'a> Plastics<'a> {
    /// The plastics `idx` names, if any lane names one.
    #[inline(always)]
    pub(super) fn gather(all: &'a [LanePlastic], idx: [u32; LANES]) -> Option<Plastics<'a>> {
        let any = *idx.iter().find(|&&k| k != NO_PLASTIC)?;
        let p: [&LanePlastic; LANES] =
            std::array::from_fn(|i| &all[if idx[i] == NO_PLASTIC { any } else { idx[i] } as usize]);
        let f = |g: fn(&LanePlastic) -> f32| F8::from_fn(|i| g(p[i]));
        Some(Plastics {
            alpha_u: f(|p| p.alpha_u),
            alpha_v: f(|p| p.alpha_v),
            eta: f(|p| p.eta),
            internal_reflectance: f(|p| p.internal_reflectance),
            nonlinear: M8::from_fn(|i| p[i].nonlinear),
            specular_weight: f(|p| p.specular_weight),
            specular: V8::from_fn(|i| p[i].specular),
            tables: std::array::from_fn(|i| &*p[i].table),
        })
    }

    /// The fraction of light at cos θ that passes the coating: `Plastic::transmittance`'s
    /// table, interpolated lane by lane.
    #[inline(always)]
    fn transmittance(&self, cos: F8) -> F8 {
        let n = self.tables[0].len();
        F8::from_fn(|i| {
            let x = cos.0[i].clamp(0.0, 1.0) * (n - 1) as f32;
            let k = (x as usize).min(n - 2);
            let f = x - k as f32;
            let t = self.tables[i];
            t[k] * (1.0 - f) + t[k + 1] * f
        })
    }

    /// The probabilities of sampling the coating and the base from `wi`, given the coating's
    /// transmittance `t` there.
    #[inline(always)]
    fn lobes(&self, t: F8) -> (F8, F8) {
        let ps = (1.0 - t) * self.specular_weight;
        let pd = t * (1.0 - self.specular_weight);
        let sum = ps + pd;
        let none = sum.le(F8::splat(0.0));
        (
            none.select(F8::splat(0.0), ps / sum),
            none.select(F8::splat(1.0), pd / sum),
        )
    }

    /// GGX's D(m).
    #[inline(always)]
    fn d(&self, m: V8) -> F8 {
        let (x, y) = (m.x / self.alpha_u, m.y / self.alpha_v);
        let c2 = m.z * m.z;
        let s = x * x + y * y + c2;
        let d = 1.0 / (PI * self.alpha_u * self.alpha_v * s * s);
        (d * m.z).gt(F8::splat(1e-20)).select(d, F8::splat(0.0))
    }

    /// Smith's masking for GGX, of direction `v` against microfacet `m`.
    #[inline(always)]
    fn g1(&self, v: V8, m: V8) -> F8 {
        let (x, y) = (self.alpha_u * v.x, self.alpha_v * v.y);
        let xy = x * x + y * y;
        let tan2 = xy / (v.z * v.z);
        let g = 2.0 / (1.0 + (1.0 + tan2).sqrt());
        let g = xy.eq(F8::splat(0.0)).select(F8::splat(1.0), g);
        (v.dot(m) * v.z).le(F8::splat(0.0)).select(F8::splat(0.0), g)
    }

    /// f · cos θo for light from `wo` seen from `wi` (local frames), with the base's
    /// reflectance `diffuse`, and the density of sampling `wo` from `wi`.
    #[inline(always)]
    pub(super) fn eval_pdf(&self, diffuse: V8, wi: V8, wo: V8) -> (V8, F8) {
        let zero = F8::splat(0.0);
        let (t_in, t_out) = (self.transmittance(wi.z), self.transmittance(wo.z));
        let ir = self.internal_reflectance;
        let linear = 1.0 - ir;
        let base = V8::select(
            self.nonlinear,
            div(diffuse, V8::splat([1.0; 3]) - diffuse.scale(ir)),
            div(
                diffuse,
                V8 {
                    x: linear,
                    y: linear,
                    z: linear,
                },
            ),
        );
        let inv_eta2 = 1.0 / (self.eta * self.eta);
        let mut value = base.scale(t_in * t_out * FRAC_1_PI * inv_eta2 * wo.z);
        let m = normalize(wi + wo);
        let g = self.g1(wi, m);
        let d = self.d(m);
        let f = fresnel_dielectric(wi.dot(m), self.eta);
        value = value + self.specular.scale(f * d * (g * self.g1(wo, m)) / (4.0 * wi.z));
        let above = wi.z.gt(zero) & wo.z.gt(zero);
        let value = V8::select(above, value, V8::splat([0.0; 3]));

        let (ps, pd) = self.lobes(t_in);
        let mut pdf = pd * (FRAC_1_PI * wo.z.max(zero));
        let wo_m = wo.dot(m);
        let visible = g * wi.dot(m).max(zero) * d / wi.z;
        let visible = wi.z.le(zero).select(zero, visible);
        pdf = wo_m.gt(zero).select(pdf + ps * visible / (4.0 * wo_m), pdf);
        (value, above.select(pdf, zero))
    }

    /// A direction sampled from `wi` (wi.z > 0): the coating's visible normals where `u_lobe`
    /// picks it, else `cosine`, the cosine-weighted direction the base samples with `u`.
    /// Returns it, its weight (f · cos θ over the density) and the density; where the density
    /// is zero, so is the weight.
    #[inline(always)]
    pub(super) fn sample(&self, diffuse: V8, wi: V8, u_lobe: F8, u: (F8, F8), cosine: V8) -> (V8, V8, F8) {
        let (ps, _) = self.lobes(self.transmittance(wi.z));
        let coating = u_lobe.lt(ps);
        let wo = if coating.any() {
            V8::select(coating, reflect_about(wi, self.sample_visible(wi, u)), cosine)
        } else {
            cosine
        };
        let (f, pdf) = self.eval_pdf(diffuse, wi, wo);
        let ok = wo.z.gt(F8::splat(0.0)) & pdf.gt(F8::splat(0.0));
        let pdf = ok.select(pdf, F8::splat(0.0));
        let weight = V8::select(
            ok,
            div(
                f,
                V8 {
                    x: pdf,
                    y: pdf,
                    z: pdf,
                },
            ),
            V8::splat([0.0; 3]),
        );
        (wo, weight, pdf)
    }

    /// Heitz's sampling of GGX's visible normals (`Microfacet::sample_visible_ggx`).
    #[inline(always)]
    fn sample_visible(&self, wi: V8, (u0, u1): (F8, F8)) -> V8 {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let vh = normalize(V8 {
            x: au * wi.x,
            y: av * wi.y,
            z: wi.z,
        });
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let len = len2.sqrt();
        let tilted = len2.gt(F8::splat(0.0));
        let t1 = V8 {
            x: tilted.select(-vh.y / len, F8::splat(1.0)),
            y: tilted.select(vh.x / len, F8::splat(0.0)),
            z: F8::splat(0.0),
        };
        let t2 = vh.cross(t1);
        let r = u0.sqrt();
        let (sin_phi, cos_phi) = sincos_turn(u1);
        let p1 = r * cos_phi;
        let s = 0.5 * (1.0 + vh.z);
        let zero = F8::splat(0.0);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(zero).sqrt() + s * r * sin_phi;
        let nz = (1.0 - p1 * p1 - p2 * p2).max(zero).sqrt();
        let nh = t1.scale(p1) + t2.scale(p2) + vh.scale(nz);
        normalize(V8 {
            x: au * nh.x,
            y: av * nh.y,
            z: nh.z.max(F8::splat(1e-7)),
        })
    }
}

/// `Vec3A::normalize`: times the reciprocal of the length.
#[inline(always)]
fn normalize(v: V8) -> V8 {
    v.scale(1.0 / v.dot(v).sqrt())
}

#[inline(always)]
fn div(a: V8, b: V8) -> V8 {
    V8 {
        x: a.x / b.x,
        y: a.y / b.y,
        z: a.z / b.z,
    }
}

/// `fresnel::reflect_about`.
#[inline(always)]
fn reflect_about(wi: V8, m: V8) -> V8 {
    m.scale(2.0 * wi.dot(m)) - wi
}

/// `fresnel::fresnel_dielectric`'s reflectance, in lanes.
#[inline(always)]
fn fresnel_dielectric(cos_i: F8, eta: F8) -> F8 {
    let zero = F8::splat(0.0);
    let outside = cos_i.ge(zero);
    let eta_it = outside.select(eta, 1.0 / eta);
    let eta_ti = outside.select(1.0 / eta, eta);
    let cos_t_sqr = 1.0 - eta_ti * eta_ti * (1.0 - cos_i * cos_i);
    let ci = cos_i.abs();
    let ct = cos_t_sqr.max(zero).sqrt();
    let a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    let a_p = (ct - eta_it * ci) / (ct + eta_it * ci);
    let r = 0.5 * (a_s * a_s + a_p * a_p);
    let r = ci.eq(zero).select(F8::splat(1.0), r);
    let r = eta.eq(F8::splat(1.0)).select(zero, r);
    r.max(zero).min(F8::splat(1.0))
}
