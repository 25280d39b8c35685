//! Fresnel equations for dielectric and conductor interfaces, in the local shading frame.

use glam::Vec3A;

use crate::color::Rgb;

/// Unpolarised Fresnel reflectance of a dielectric interface with relative index `eta`
/// (inside over outside), as Mitsuba 3 defines it.
///
/// Returns (reflectance, signed cosine of the transmitted direction, eta_it, eta_ti): the
/// cosine carries the opposite sign of `cos_i`, and the two eta ratios are oriented by the side
/// `cos_i` comes from. Total internal reflection gives reflectance 1.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> (f32, f32, f32, f32) {
    let outside = cos_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let cos_t_sqr = 1.0 - eta_ti * eta_ti * (1.0 - cos_i * cos_i);
    let ci = cos_i.abs();
    let ct = cos_t_sqr.max(0.0).sqrt();
    let r = if eta == 1.0 {
        0.0
    } else if ci == 0.0 {
        1.0
    } else {
        let a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
        let a_p = (ct - eta_it * ci) / (ct + eta_it * ci);
        0.5 * (a_s * a_s + a_p * a_p)
    };
    let cos_t = if cos_i >= 0.0 { -ct } else { ct };
    (r.clamp(0.0, 1.0), cos_t, eta_it, eta_ti)
}

/// Unpolarised Fresnel reflectance of a conductor with complex index eta + i k, per channel.
pub fn fresnel_conductor(cos_i: f32, eta: Rgb, k: Rgb) -> Rgb {
    let c2 = cos_i * cos_i;
    let s2 = 1.0 - c2;
    let eta2 = eta * eta;
    let k2 = k * k;
    let t0 = eta2 - k2 - Vec3A::splat(s2);
    let a2b2 = (t0 * t0 + 4.0 * eta2 * k2).max(Vec3A::ZERO).powf(0.5);
    let a = (0.5 * (a2b2 + t0)).max(Vec3A::ZERO).powf(0.5);
    let t1 = a2b2 + Vec3A::splat(c2);
    let t2 = 2.0 * cos_i * a;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = c2 * a2b2 + Vec3A::splat(s2 * s2);
    let t4 = t2 * s2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    (0.5 * (rp + rs)).clamp(Vec3A::ZERO, Vec3A::ONE)
}

/// Hemispherical average of the dielectric Fresnel reflectance for light arriving from the side
/// with relative index `eta`: the fits Mitsuba 3 uses (Egan and Hilgeman 1973 for eta < 1,
/// d'Eon and Irving 2011 otherwise), so that plastic matches it.
pub fn diffuse_fresnel_reflectance(eta: f32) -> f32 {
    if eta < 1.0 {
        -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta
    } else {
        let i = 1.0 / eta;
        let (i2, i3) = (i * i, i * i * i);
        let (i4, i5) = (i2 * i2, i2 * i3);
        0.919_317 - 3.4793 * i + 6.75335 * i2 - 7.80989 * i3 + 4.98554 * i4 - 1.36881 * i5
    }
}

/// Mirror reflection about the local normal.
#[inline]
pub fn reflect(wi: Vec3A) -> Vec3A {
    Vec3A::new(-wi.x, -wi.y, wi.z)
}

/// Mirror reflection about a microfacet normal `m`.
#[inline]
pub fn reflect_about(wi: Vec3A, m: Vec3A) -> Vec3A {
    2.0 * wi.dot(m) * m - wi
}

/// Refraction through the local normal, from [`fresnel_dielectric`]'s outputs.
#[inline]
pub fn refract(wi: Vec3A, cos_t: f32, eta_ti: f32) -> Vec3A {
    Vec3A::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t)
}

/// The generalised half vector from `wi` to `wo` across an interface of relative index `eta`
/// (inside over outside), turned to +z, whether the two are on one side (a reflection), and the
/// relative index seen from `wi`'s side; None when either is grazing or the half vector is
/// undefined. Rough glass and the principled BSDF's transmission share it.
pub fn half_vector(wi: Vec3A, wo: Vec3A, eta: f32) -> Option<(Vec3A, bool, f32)> {
    let reflect = wi.z * wo.z > 0.0;
    if !reflect && wi.z * wo.z == 0.0 {
        return None;
    }
    let eta_path = if wi.z > 0.0 { eta } else { 1.0 / eta };
    let m = (wi + wo * if reflect { 1.0 } else { eta_path }).normalize_or_zero();
    if m == Vec3A::ZERO {
        return None;
    }
    Some((if m.z < 0.0 { -m } else { m }, reflect, eta_path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_limits() {
        let (r, _, _, _) = fresnel_dielectric(1.0, 1.5);
        assert!((r - 0.04).abs() < 1e-6);
        // From inside beyond the critical angle: total internal reflection.
        let (r, ct, _, _) = fresnel_dielectric(-0.1, 1.5);
        assert_eq!(r, 1.0);
        assert_eq!(ct, 0.0);
        assert_eq!(fresnel_dielectric(0.5, 1.0).0, 0.0);
    }

    #[test]
    fn conductor_limits() {
        // Mitsuba's "none" conductor (eta 0, k 1) is a perfect mirror.
        let f = fresnel_conductor(0.3, Rgb::ZERO, Rgb::ONE);
        assert!((f - Rgb::ONE).abs().max_element() < 1e-5);
        // A conductor with k = 0 is a dielectric.
        let f = fresnel_conductor(0.7, Rgb::splat(1.5), Rgb::ZERO);
        assert!((f.x - fresnel_dielectric(0.7, 1.5).0).abs() < 1e-5);
    }

    #[test]
    fn diffuse_reflectance_matches_integral() {
        for eta in [1.33f32, 1.5, 1.0 / 1.5] {
            let n = 20_000;
            let mut sum = 0.0f64;
            for i in 0..n {
                let mu = (i as f64 + 0.5) / n as f64;
                sum += 2.0 * mu * fresnel_dielectric(mu as f32, eta).0 as f64 / n as f64;
            }
            let fit = diffuse_fresnel_reflectance(eta) as f64;
            assert!((fit - sum).abs() < 0.01, "eta {eta}: fit {fit}, integral {sum}");
        }
    }
}
