use std::f32::consts::PI;

use glam::{Quat, Vec2, Vec3A};

use super::{Aabb, Ray, SurfacePoint, gamma};

/// Mitsuba's analytic `cylinder`: a tube without caps, of `radius` around its axis from `base`
/// for `length` along `rotation`'s local +z. Its normals point away from the axis (towards it
/// for `flip_normals`), and (u, v) is Mitsuba's: u the angle about the axis from the local +x,
/// over 2π, v the height over the length.
#[derive(Clone, Debug)]
pub struct Cylinder {
    /// The centre of the bottom rim.
    pub base: Vec3A,
    /// World from local rotation; the axis is local +z.
    pub rotation: Quat,
    /// Radius.
    pub radius: f32,
    /// Length along the axis.
    pub length: f32,
    /// Shape index.
    pub shape: u32,
    /// Whether normals point towards the axis (`flip_normals`).
    pub flip: bool,
}

impl Cylinder {
    /// Bounds: the local box's corners carried to the world.
    pub fn bounds(&self) -> Aabb {
        let (r, l) = (self.radius, self.length);
        let mut b = Aabb::EMPTY;
        for corner in [
            Vec3A::new(-r, -r, 0.0),
            Vec3A::new(r, -r, 0.0),
            Vec3A::new(-r, r, 0.0),
            Vec3A::new(r, r, 0.0),
            Vec3A::new(-r, -r, l),
            Vec3A::new(r, -r, l),
            Vec3A::new(-r, r, l),
            Vec3A::new(r, r, l),
        ] {
            b = b.grow(self.base + self.rotation * corner);
        }
        // Rounding of the rotation: the box must hold every hit.
        let pad = Vec3A::splat(gamma(8) * (r + l)) + gamma(4) * self.base.abs();
        Aabb {
            min: b.min - pad,
            max: b.max + pad,
        }
    }

    /// Area of the tube.
    pub fn area(&self) -> f32 {
        2.0 * PI * self.radius * self.length
    }

    /// Nearest root of x² + y² = r² with 0 ≤ z ≤ length, in (0, t_max), solved in f64 in the
    /// local frame as the sphere's is.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<f32> {
        let inv = self.rotation.inverse();
        let o = (inv * (ray.o - self.base)).as_dvec3();
        let d = (inv * ray.d).as_dvec3();
        let r = self.radius as f64;
        let a = d.x * d.x + d.y * d.y;
        if a == 0.0 {
            return None;
        }
        let b = -(o.x * d.x + o.y * d.y);
        // The distance of the axis to the ray's line, as for the sphere.
        let (lx, ly) = (o.x + b / a * d.x, o.y + b / a * d.y);
        let disc = a * (r * r - (lx * lx + ly * ly));
        if disc < 0.0 {
            return None;
        }
        let root = disc.sqrt();
        let q = if b >= 0.0 { b + root } else { b - root };
        let c = o.x * o.x + o.y * o.y - r * r;
        let (mut t0, mut t1) = (c / q, q / a);
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        let (tmax, len) = (t_max as f64, self.length as f64);
        [t0, t1]
            .into_iter()
            .find(|&t| t > 0.0 && t < tmax && (0.0..=len).contains(&(o.z + t * d.z)))
            .map(|t| t as f32)
    }

    /// The surface at a point near the tube: put back on it, so the error bound is tight.
    pub fn surface(&self, p_near: Vec3A) -> SurfacePoint {
        let l = self.rotation.inverse() * (p_near - self.base);
        let rd = (l.x * l.x + l.y * l.y).sqrt();
        let (cx, cy) = if rd > 0.0 {
            (l.x / rd, l.y / rd)
        } else {
            (1.0, 0.0)
        };
        let local = Vec3A::new(cx * self.radius, cy * self.radius, l.z.clamp(0.0, self.length));
        let offset = self.rotation * local;
        let p = self.base + offset;
        let p_err = gamma(6) * offset.abs() + gamma(1) * p.abs() + gamma(1) * self.base.abs();
        let phi = super::azimuth(cy, cx);
        let uv = Vec2::new(phi / (2.0 * PI), local.z / self.length);
        // Mitsuba's ∂p/∂u = 2π (−y, x, 0) and ∂p/∂v = (0, 0, length) in the local frame.
        let dpdu = self.rotation * Vec3A::new(-local.y, local.x, 0.0) * (2.0 * PI);
        let dpdv = self.rotation * Vec3A::new(0.0, 0.0, self.length);
        let n = self.rotation * Vec3A::new(cx, cy, 0.0);
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

    /// A point uniform over the tube.
    pub fn sample_point(&self, u: Vec2) -> SurfacePoint {
        let (sin, cos) = libm::sincosf(2.0 * PI * u.y);
        let local = Vec3A::new(self.radius * cos, self.radius * sin, self.length * u.x);
        self.surface(self.base + self.rotation * local)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tube() -> Cylinder {
        // Axis along world +x from (1, 0, 0), radius 0.5, length 2.
        Cylinder {
            base: Vec3A::new(1.0, 0.0, 0.0),
            rotation: Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            radius: 0.5,
            length: 2.0,
            shape: 0,
            flip: false,
        }
    }

    #[test]
    fn hits_the_tube_within_its_length_and_from_inside() {
        let c = tube();
        let down = Ray::new(Vec3A::new(2.0, 3.0, 0.0), -Vec3A::Y);
        let t = c.intersect(&down, f32::INFINITY).unwrap();
        assert!((t - 2.5).abs() < 1e-5, "{t}");
        let s = c.surface(down.o + down.d * t);
        assert!((s.ng - Vec3A::Y).length() < 1e-5, "{}", s.ng);
        assert!((s.uv.y - 0.5).abs() < 1e-5, "{}", s.uv);
        // Beyond the ends: no cap.
        let past = Ray::new(Vec3A::new(3.5, 3.0, 0.0), -Vec3A::Y);
        assert!(c.intersect(&past, f32::INFINITY).is_none());
        // Along the axis from inside: it leaves through the open end, hitting nothing.
        let along = Ray::new(Vec3A::new(2.0, 0.0, 0.0), Vec3A::X);
        assert!(c.intersect(&along, f32::INFINITY).is_none());
        // From the axis sideways: the wall at the radius.
        let side = Ray::new(Vec3A::new(2.0, 0.0, 0.0), Vec3A::Z);
        assert!((c.intersect(&side, f32::INFINITY).unwrap() - 0.5).abs() < 1e-5);
        let b = c.bounds();
        assert!(s.p.cmpge(b.min).all() && s.p.cmple(b.max).all());
        assert!((c.area() - 2.0 * PI).abs() < 1e-5);
    }

    #[test]
    fn sampled_points_lie_on_the_tube() {
        let c = tube();
        for i in 0..64 {
            let u = Vec2::new((i % 8) as f32 / 8.0 + 0.01, (i / 8) as f32 / 8.0 + 0.02);
            let s = c.sample_point(u);
            let l = c.rotation.inverse() * (s.p - c.base);
            assert!(((l.x * l.x + l.y * l.y).sqrt() - 0.5).abs() < 1e-5);
            assert!(
                (s.uv.x - u.y).abs() < 1e-4 && (s.uv.y - u.x).abs() < 1e-4,
                "{u} {}",
                s.uv
            );
        }
    }
}
