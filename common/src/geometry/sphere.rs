use glam::{Quat, Vec2, Vec3A};

use super::{Aabb, Ray, SurfacePoint, gamma};

/// An analytic sphere.
#[derive(Clone, Debug)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3A,
    /// Radius.
    pub radius: f32,
    /// Shape index.
    pub shape: u32,
    /// Whether normals point inwards (`flip_normals`).
    pub flip: bool,
    /// The rotation of its `to_world`, which orients its texture coordinates.
    pub rotation: Quat,
}

impl Sphere {
    /// Bounds.
    pub fn bounds(&self) -> Aabb {
        Aabb {
            min: self.center - Vec3A::splat(self.radius),
            max: self.center + Vec3A::splat(self.radius),
        }
    }

    /// Area.
    pub fn area(&self) -> f32 {
        4.0 * std::f32::consts::PI * self.radius * self.radius
    }

    /// Nearest root of |o + t d - c|² = r² in (0, t_max).
    ///
    /// The discriminant is computed from the distance of the centre to the ray's line, in
    /// f64, which stays accurate for rays starting far from small spheres and vice versa.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<f32> {
        let f = (ray.o - self.center).as_dvec3();
        let d = ray.d.as_dvec3();
        let r = self.radius as f64;
        let a = d.length_squared();
        let b = -f.dot(d);
        let l = f + (b / a) * d;
        let disc = a * (r * r - l.length_squared());
        if disc < 0.0 {
            return None;
        }
        let root = disc.sqrt();
        let q = if b >= 0.0 { b + root } else { b - root };
        let c = f.length_squared() - r * r;
        let (mut t0, mut t1) = (c / q, q / a);
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        let tmax = t_max as f64;
        if t0 > 0.0 && t0 < tmax {
            Some(t0 as f32)
        } else if t1 > 0.0 && t1 < tmax {
            Some(t1 as f32)
        } else {
            None
        }
    }

    /// The surface at a point near the sphere: re-projected onto it so the error bound is tight.
    pub fn surface(&self, p_near: Vec3A) -> SurfacePoint {
        let local = p_near - self.center;
        let len = local.length();
        let n = if len > 0.0 { local / len } else { Vec3A::Z };
        let local = n * self.radius;
        let p = self.center + local;
        let p_err = gamma(5) * local.abs() + gamma(1) * p.abs() + gamma(1) * self.center.abs();
        // Mitsuba's parameterisation: u the longitude about the local z axis from +x, v the
        // colatitude from +z.
        let l = self.rotation.inverse() * glam::Vec3::from(n);
        let phi = super::azimuth(l.y, l.x);
        let uv = Vec2::new(
            phi * std::f32::consts::FRAC_1_PI * 0.5,
            libm::acosf(l.z.clamp(-1.0, 1.0)) * std::f32::consts::FRAC_1_PI,
        );
        // Mitsuba's ∂p/∂u and ∂p/∂v (sphere.cpp): 2π r (−y, x, 0) and π r (z cos φ, z sin φ,
        // −sin θ) in the sphere's frame, ∂p/∂v along x at the poles.
        let tau_r = 2.0 * std::f32::consts::PI * self.radius;
        let dpdu = Vec3A::from(self.rotation * glam::Vec3::new(-l.y, l.x, 0.0)) * tau_r;
        let rd = (l.x * l.x + l.y * l.y).sqrt();
        let dpdv_local = if rd > 0.0 {
            glam::Vec3::new(l.z * l.x / rd, l.z * l.y / rd, -rd)
        } else {
            glam::Vec3::X
        };
        let dpdv = Vec3A::from(self.rotation * dpdv_local) * (0.5 * tau_r);
        let n = if self.flip { -n } else { n };
        SurfacePoint {
            p,
            p_err,
            ng: n,
            ns: n,
            shape: self.shape,
            uv,
            attr: Vec3A::ZERO,
            dpdu,
            dpdv,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_front_and_from_inside() {
        let s = Sphere {
            center: Vec3A::new(0.0, 0.0, -5.0),
            radius: 1.0,
            shape: 0,
            flip: false,
            rotation: Quat::IDENTITY,
        };
        let r = Ray::new(Vec3A::ZERO, -Vec3A::Z);
        assert!((s.intersect(&r, f32::INFINITY).unwrap() - 4.0).abs() < 1e-5);
        let inside = Ray::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::X);
        assert!((s.intersect(&inside, f32::INFINITY).unwrap() - 1.0).abs() < 1e-5);
        let miss = Ray::new(Vec3A::ZERO, Vec3A::X);
        assert!(s.intersect(&miss, f32::INFINITY).is_none());
    }
}
