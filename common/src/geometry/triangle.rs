use glam::{Vec2, Vec3A};

use super::{Aabb, Ray, SurfacePoint, gamma};
use crate::texture::TexAt;

/// A triangle with its vertices in world space.
#[derive(Clone, Debug)]
pub struct Triangle {
    /// Vertices, counter-clockwise around the geometric normal.
    pub p: [Vec3A; 3],
    /// Vertex normals for smooth shading, if the mesh has them.
    pub n: Option<Box<[Vec3A; 3]>>,
    /// Vertex texture coordinates, if the mesh has them (otherwise (u, v) is the barycentric
    /// position (b1, b2), as in Mitsuba).
    pub uv: Option<Box<[Vec2; 3]>>,
    /// The mesh attribute its material reads (`mesh_attribute`), at its vertices (a face
    /// attribute three times), if it reads one.
    pub attr: Option<Box<[Vec3A; 3]>>,
    /// Shape index.
    pub shape: u32,
    /// Whether the shape's normals are flipped (`flip_normals`).
    pub flip: bool,
}

impl Triangle {
    /// A triangle of shape 0 with no normals, texture coordinates or attribute: the tests'.
    #[cfg(test)]
    pub(crate) fn bare(p: [Vec3A; 3]) -> Triangle {
        Triangle {
            p,
            n: None,
            uv: None,
            attr: None,
            shape: 0,
            flip: false,
        }
    }

    /// Bounds.
    pub fn bounds(&self) -> Aabb {
        Aabb::point(self.p[0]).grow(self.p[1]).grow(self.p[2])
    }

    /// Area.
    pub fn area(&self) -> f32 {
        0.5 * (self.p[1] - self.p[0]).cross(self.p[2] - self.p[0]).length()
    }

    /// Möller–Trumbore: (t, b1, b2) for a hit in (0, t_max).
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<(f32, f32, f32)> {
        let e1 = self.p[1] - self.p[0];
        let e2 = self.p[2] - self.p[0];
        let pv = ray.d.cross(e2);
        let det = e1.dot(pv);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let tv = ray.o - self.p[0];
        let b1 = tv.dot(pv) * inv;
        if !(0.0..=1.0).contains(&b1) {
            return None;
        }
        let qv = tv.cross(e1);
        let b2 = ray.d.dot(qv) * inv;
        if b2 < 0.0 || b1 + b2 > 1.0 {
            return None;
        }
        let t = e2.dot(qv) * inv;
        (t > 0.0 && t < t_max).then_some((t, b1, b2))
    }

    /// Where textures are looked up at barycentric coordinates (b1, b2): the interpolated
    /// texture coordinates (or (b1, b2) without them) and mesh attribute (zero without one).
    /// The lane engine reads its textures here too.
    #[inline]
    pub fn tex_at(&self, b1: f32, b2: f32) -> TexAt {
        let b0 = 1.0 - b1 - b2;
        TexAt {
            uv: self
                .uv
                .as_ref()
                .map_or(Vec2::new(b1, b2), |t| b0 * t[0] + b1 * t[1] + b2 * t[2]),
            attr: self
                .attr
                .as_ref()
                .map_or(Vec3A::ZERO, |a| b0 * a[0] + b1 * a[1] + b2 * a[2]),
        }
    }

    /// The surface at barycentric coordinates (b1, b2).
    pub fn surface(&self, b1: f32, b2: f32) -> SurfacePoint {
        let b0 = 1.0 - b1 - b2;
        let [p0, p1, p2] = self.p;
        let p = b0 * p0 + b1 * p1 + b2 * p2;
        let p_err = gamma(7) * ((b0 * p0).abs() + (b1 * p1).abs() + (b2 * p2).abs());
        let mut ng = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        if self.flip {
            ng = -ng;
        }
        // As in Mitsuba, the interpolated normal alone decides which side is the front, even
        // where it disagrees with the winding.
        let ns = match &self.n {
            Some(n) => {
                let s = (b0 * n[0] + b1 * n[1] + b2 * n[2]).normalize_or_zero();
                match (s == Vec3A::ZERO, self.flip) {
                    (true, _) => ng,
                    (false, true) => -s,
                    (false, false) => s,
                }
            }
            None => ng,
        };
        let (dpdu, dpdv) = match &self.uv {
            Some(t) => self.tangents(t),
            None => (p1 - p0, p2 - p0),
        };
        let TexAt { uv, attr } = self.tex_at(b1, b2);
        SurfacePoint {
            p,
            p_err,
            ng,
            ns,
            shape: self.shape,
            uv,
            attr,
            dpdu,
            dpdv,
        }
    }

    /// ∂p/∂u and ∂p/∂v from the vertex texture coordinates, as Mitsuba computes them (for a
    /// degenerate parameterisation, the tangents of the unflipped geometric normal's basis).
    fn tangents(&self, t: &[Vec2; 3]) -> (Vec3A, Vec3A) {
        let [p0, p1, p2] = self.p;
        let (dp0, dp1) = (p1 - p0, p2 - p0);
        let (duv0, duv1) = (t[1] - t[0], t[2] - t[0]);
        let det = duv0.x * duv1.y - duv0.y * duv1.x;
        if det == 0.0 {
            let n = dp0.cross(dp1).normalize_or_zero();
            if n == Vec3A::ZERO {
                return (Vec3A::ZERO, Vec3A::ZERO);
            }
            let f = super::Frame::from_normal(n);
            return (f.s, f.t);
        }
        (
            (duv1.y * dp0 - duv0.y * dp1) / det,
            (duv0.x * dp1 - duv1.x * dp0) / det,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Triangle {
        Triangle::bare([
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.0, 0.0),
            Vec3A::new(0.0, 1.0, 0.0),
        ])
    }

    #[test]
    fn hits_inside_and_misses_outside() {
        let t = tri();
        let r = Ray::new(Vec3A::new(0.2, 0.2, 1.0), -Vec3A::Z);
        let (d, b1, b2) = t.intersect(&r, f32::INFINITY).unwrap();
        assert!((d - 1.0).abs() < 1e-6 && (b1 - 0.2).abs() < 1e-6 && (b2 - 0.2).abs() < 1e-6);
        assert!(t.intersect(&r, 0.5).is_none());
        let miss = Ray::new(Vec3A::new(0.8, 0.8, 1.0), -Vec3A::Z);
        assert!(t.intersect(&miss, f32::INFINITY).is_none());
        let s = t.surface(b1, b2);
        assert_eq!(s.ng, Vec3A::Z);
        assert!((t.area() - 0.5).abs() < 1e-6);
    }
}
