//! Mitsuba's `linearcurve` and `bsplinecurve`: tubes through control points whose radius
//! varies along them. Mitsuba renders them with Embree's round curves: the sweep of a sphere
//! whose centre and radius follow the curve. A linear segment's sweep is the convex hull of
//! its two end spheres (a cone tangent to both, capped by them), intersected exactly. A cubic
//! B-spline segment is intersected as [`SPLINE_PIECES`] such linear sweeps through points of
//! the spline, and the hit is then put on the true sweep: the touching sphere's parameter
//! refined by Newton's method, the normal and (u, v) Mitsuba's. Backfaces are culled, as in
//! Mitsuba: a ray starting inside a curve does not hit it.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3A};

use super::{Aabb, Ray, SurfacePoint, gamma};

/// One segment of a linear curve.
#[derive(Clone, Debug)]
pub struct CurveSegment {
    /// Start and end of the centre line (world space).
    pub p: [Vec3A; 2],
    /// Radius at each end (Mitsuba leaves radii untouched by `to_world`).
    pub r: [f32; 2],
    /// Shape index.
    pub shape: u32,
    /// This segment's index among its shape's segments, and their number: v runs over all
    /// segments of the shape, as in Mitsuba.
    pub index: u32,
    /// Segments in the shape.
    pub segments: u32,
    /// Whether each end sphere is part of the surface: false at the open ends of a B-spline
    /// curve (Mitsuba's have no end caps).
    pub caps: [bool; 2],
    /// For a piece of a B-spline segment: the segment, and the piece's span of its parameter.
    pub spline: Option<(Arc<SplineSegment>, [f32; 2])>,
}

/// Linear pieces per B-spline segment: the silhouette of a piece departs from the spline's by
/// under 1/(8·16²) of the segment's curvature times its length squared, far below a pixel for
/// the curves Mitsuba's scenes hold.
pub const SPLINE_PIECES: u32 = 16;

/// One cubic B-spline segment of a `bsplinecurve`: four control points and radii.
#[derive(Clone, Debug)]
pub struct SplineSegment {
    /// Control points (world space).
    pub p: [Vec3A; 4],
    /// Radii.
    pub r: [f32; 4],
}

/// The spline's centre, radius and derivatives at a parameter.
struct SplineAt {
    c: DVec3,
    dc: DVec3,
    ddc: DVec3,
    dddc: DVec3,
    r: f64,
    dr: f64,
}

impl SplineSegment {
    /// Uniform cubic B-spline basis and its derivatives at v in [0, 1], as Mitsuba's.
    fn at(&self, v: f64) -> SplineAt {
        let (v2, v3) = (v * v, v * v * v);
        let b = [
            (-v3 + 3.0 * v2 - 3.0 * v + 1.0) / 6.0,
            (3.0 * v3 - 6.0 * v2 + 4.0) / 6.0,
            (-3.0 * v3 + 3.0 * v2 + 3.0 * v + 1.0) / 6.0,
            v3 / 6.0,
        ];
        let db = [
            (-3.0 * v2 + 6.0 * v - 3.0) / 6.0,
            (9.0 * v2 - 12.0 * v) / 6.0,
            (-9.0 * v2 + 6.0 * v + 3.0) / 6.0,
            3.0 * v2 / 6.0,
        ];
        let ddb = [1.0 - v, 3.0 * v - 2.0, 1.0 - 3.0 * v, v];
        let dddb = [-1.0, 3.0, -3.0, 1.0];
        let p = self.p.map(|q| q.as_dvec3());
        let r = self.r.map(|x| x as f64);
        let sum = |w: [f64; 4]| p[0] * w[0] + p[1] * w[1] + p[2] * w[2] + p[3] * w[3];
        let sumr = |w: [f64; 4]| r[0] * w[0] + r[1] * w[1] + r[2] * w[2] + r[3] * w[3];
        SplineAt {
            c: sum(b),
            dc: sum(db),
            ddc: sum(ddb),
            dddc: sum(dddb),
            r: sumr(b),
            dr: sumr(db),
        }
    }

    /// The centre-line point and radius at v, for the linear pieces.
    pub fn point(&self, v: f32) -> (Vec3A, f32) {
        let a = self.at(v as f64);
        (a.c.as_vec3a(), a.r as f32)
    }

    /// The parameter in [0, 1] of the sphere touching the sweep at point `p`, from `v`: Newton's
    /// method on (p − c)·c′ + r r′ = 0, the stationary point of |p − c|² − r².
    fn touching(&self, p: DVec3, mut v: f64) -> f64 {
        for _ in 0..8 {
            let a = self.at(v);
            let q = p - a.c;
            let g = q.dot(a.dc) + a.r * a.dr;
            // d/dv of g, with r″ left out (its term r·r″ is small against |c′|²).
            let dg = q.dot(a.ddc) - a.dc.dot(a.dc) + a.dr * a.dr;
            if dg == 0.0 {
                break;
            }
            let next = (v - g / dg).clamp(0.0, 1.0);
            if (next - v).abs() < 1e-9 {
                v = next;
                break;
            }
            v = next;
        }
        v
    }
}

/// The segment's sweep in its own terms: unit axis, length, and the radius' slope along it.
struct Sweep {
    p0: DVec3,
    axis: DVec3,
    len: f64,
    r0: f64,
    k: f64,
}

impl CurveSegment {
    fn sweep(&self) -> Sweep {
        let p0 = self.p[0].as_dvec3();
        let a = self.p[1].as_dvec3() - p0;
        let len = a.length();
        let (r0, r1) = (self.r[0] as f64, self.r[1] as f64);
        let axis = if len > 0.0 { a / len } else { DVec3::Z };
        Sweep {
            p0,
            axis,
            len,
            r0,
            k: if len > 0.0 { (r1 - r0) / len } else { 0.0 },
        }
    }

    /// Bounds: both end spheres.
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for (p, r) in self.p.iter().zip(self.r) {
            let pad = Vec3A::splat(r) * (1.0 + gamma(4)) + gamma(4) * p.abs();
            b = b.grow(*p - pad).grow(*p + pad);
        }
        b
    }

    /// Nearest front-facing hit in (0, t_max), in f64: the tangent cone where the sphere it
    /// touches lies within the segment, else an end sphere where the cone does not cover it.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<f32> {
        let s = self.sweep();
        let (o, d) = (ray.o.as_dvec3(), ray.d.as_dvec3());
        let tmax = t_max as f64;
        let mut best = f64::INFINITY;
        let mut consider = |t: f64| {
            if t > 0.0 && t < tmax && t < best {
                best = t;
            }
        };
        if s.is_one_sphere() {
            // One end sphere holds the other: the segment is the larger sphere.
            let (c, r) = if self.r[1] > self.r[0] {
                (self.p[1].as_dvec3(), self.r[1] as f64)
            } else {
                (s.p0, s.r0)
            };
            if let Some(t) = sphere_entry(o, d, c, r) {
                consider(t);
            }
            return (best < tmax).then_some(best as f32);
        }
        let w = 1.0 - s.k * s.k;
        // The cone (1 − k²)(|q|² − x²) = (r0 + k x)², q the point from p0, x its axial part.
        let q = o - s.p0;
        let (qz, dz) = (q.dot(s.axis), d.dot(s.axis));
        let a = w * (d.dot(d) - dz * dz) - s.k * s.k * dz * dz;
        let b = 2.0 * (w * (q.dot(d) - qz * dz) - s.k * dz * (s.r0 + s.k * qz));
        let c = w * (q.dot(q) - qz * qz) - (s.r0 + s.k * qz) * (s.r0 + s.k * qz);
        for t in quadratic_roots(a, b, c).into_iter().flatten() {
            let x = qz + t * dz;
            let rx = s.r0 + s.k * x;
            let z = x + s.k * rx / w;
            if rx > 0.0 && (0.0..=s.len).contains(&z) {
                let n = o + d * t - (s.p0 + s.axis * z);
                if n.dot(d) < 0.0 {
                    consider(t);
                }
            }
        }
        // The caps: where the touching sphere would lie beyond an end.
        let ends = [(0.0, s.p0, s.r0), (s.len, self.p[1].as_dvec3(), self.r[1] as f64)];
        for ((end, c, r), cap) in ends.into_iter().zip(self.caps) {
            if !cap {
                continue;
            }
            if let Some(t) = sphere_entry(o, d, c, r) {
                let z = s.touching(o + d * t);
                if (end == 0.0 && z <= 0.0) || (end > 0.0 && z >= s.len) {
                    consider(t);
                }
            }
        }
        (best < tmax).then_some(best as f32)
    }

    /// The surface at a point near the segment, as Mitsuba's: the normal from the centre of the
    /// sphere touching there, u the angle about the axis in Mitsuba's frame, v along all of the
    /// shape's segments.
    pub fn surface(&self, p_near: Vec3A) -> SurfacePoint {
        if let Some((spline, span)) = &self.spline {
            return self.spline_surface(spline, *span, p_near);
        }
        let s = self.sweep();
        let pd = p_near.as_dvec3();
        let v_local = if s.is_one_sphere() {
            if self.r[1] > self.r[0] { 1.0 } else { 0.0 }
        } else {
            (s.touching(pd) / s.len).clamp(0.0, 1.0)
        };
        let centre = s.p0 + (self.p[1].as_dvec3() - s.p0) * v_local;
        let radius = s.r0 + (self.r[1] as f64 - s.r0) * v_local;
        let off = pd - centre;
        let n = if off.length_squared() > 0.0 {
            off.normalize()
        } else {
            any_perpendicular(s.axis)
        };
        let p = (centre + n * radius).as_vec3a();
        let (n, axis, centre) = (n.as_vec3a(), s.axis.as_vec3a(), centre.as_vec3a());
        let (u_rot, u_rad) = local_frame(axis);
        let u = super::azimuth(u_rot.dot(n), u_rad.dot(n)) / (2.0 * PI);
        let v = (v_local as f32 + self.index as f32) / self.segments as f32;
        let segments = self.segments as f32;
        SurfacePoint {
            p,
            p_err: gamma(8) * (p.abs() + Vec3A::splat(radius as f32)),
            ng: n,
            ns: n,
            shape: self.shape,
            uv: Vec2::new(u, v),
            attr: Vec3A::ZERO,
            dpdu: axis.cross(p - centre) * (2.0 * PI),
            dpdv: ((self.p[1] - self.p[0]) + n * (self.r[1] - self.r[0])) * segments,
        }
    }
}

impl CurveSegment {
    /// [`CurveSegment::surface`] on the B-spline sweep a piece approximates, as Mitsuba's
    /// `bsplinecurve` gives it: the normal (|c′|² − (p − c)·c″)(p − c) − r r′ c′, u about the
    /// tangent in Mitsuba's frame, v over all segments, and ∂p/∂u and ∂p/∂v from the
    /// Frenet–Serret frame.
    fn spline_surface(&self, spline: &SplineSegment, [v0, v1]: [f32; 2], p_near: Vec3A) -> SurfacePoint {
        let s = self.sweep();
        let pd = p_near.as_dvec3();
        let piece = if !s.is_one_sphere() {
            (s.touching(pd) / s.len).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let v = spline.touching(pd, v0 as f64 + (v1 - v0) as f64 * piece);
        let a = spline.at(v);
        let rad_vec = pd - a.c;
        let mut n =
            (rad_vec * (a.dc.dot(a.dc) - rad_vec.dot(a.ddc)) - a.dc * (a.dr * a.r)).normalize_or_zero();
        if n == DVec3::ZERO {
            n = any_perpendicular(a.dc.normalize_or(DVec3::Z));
        }
        let rad = rad_vec.normalize_or(n);
        let p = a.c + n * a.r;
        let t = a.dc.normalize_or(DVec3::Z);
        let (u_rot, u_rad) = local_frame(t.as_vec3a());
        let rad32 = rad.as_vec3a();
        let u = super::azimuth(u_rot.dot(rad32), u_rad.dot(rad32)) / (2.0 * PI);
        // Frenet–Serret frame, as Mitsuba's partials build it.
        let speed = a.dc.length();
        let cross = a.dc.cross(a.ddc);
        let cross_len = cross.length();
        let mut kappa = cross_len / (speed * speed * speed);
        let mut tau = if cross_len < 1e-6 || a.dddc.length() < 1e-6 {
            0.0
        } else {
            a.dddc.dot(cross) / (cross_len * cross_len)
        };
        let (fn_, fb) = if kappa < f32::EPSILON as f64 || cross_len == 0.0 {
            kappa = 0.0;
            tau = 0.0;
            let f = super::Frame::from_normal(t.as_vec3a());
            (f.s.as_dvec3(), f.t.as_dvec3())
        } else {
            let fn_ = cross.cross(a.dc).normalize();
            (fn_, t.cross(fn_).normalize())
        };
        let (cos, sin) = (fn_.dot(rad), fb.dot(rad));
        let radu = fn_ * -sin + fb * cos;
        let radv = (t * -kappa + fb * tau) * (speed * cos) + fn_ * (-tau * speed * sin);
        let segments = self.segments as f64;
        let dpdu = radu * (a.r * 2.0 * std::f64::consts::PI);
        let dpdv = (a.dc + rad * a.dr + radv * a.r) * segments;
        let p32 = p.as_vec3a();
        let n32 = n.as_vec3a();
        SurfacePoint {
            p: p32,
            p_err: gamma(16) * (p32.abs() + Vec3A::splat(a.r as f32)),
            ng: n32,
            ns: n32,
            shape: self.shape,
            uv: Vec2::new(u, ((v + self.index as f64) / segments) as f32),
            attr: Vec3A::ZERO,
            dpdu: dpdu.as_vec3a(),
            dpdv: dpdv.as_vec3a(),
        }
    }
}

impl Sweep {
    /// Whether one end sphere holds the other (|Δr| ≥ length, or no length): then the segment
    /// is the larger sphere and has no cone.
    fn is_one_sphere(&self) -> bool {
        self.k.abs() >= 1.0 || self.len == 0.0
    }

    /// The centre-line distance from p0 of the sphere of the sweep (extended beyond the ends)
    /// that touches the envelope at point `p`: x + k·y/√(1 − k²) for axial x and radial y.
    fn touching(&self, p: DVec3) -> f64 {
        let q = p - self.p0;
        let x = q.dot(self.axis);
        let y = (q - self.axis * x).length();
        x + self.k * y / (1.0 - self.k * self.k).sqrt()
    }
}

/// Mitsuba's frame about a curve's axis: `u_rot` the projection of +z normal to the axis (+y
/// where the axis is ±z), `u_rad` = u_rot × axis.
fn local_frame(axis: Vec3A) -> (Vec3A, Vec3A) {
    let guide = Vec3A::Z;
    let u_rot = if guide.dot(axis).abs() == 1.0 {
        Vec3A::Y
    } else {
        (guide - axis * axis.dot(guide)).normalize()
    };
    (u_rot, u_rot.cross(axis))
}

/// A unit vector normal to `a`.
fn any_perpendicular(a: DVec3) -> DVec3 {
    let other = if a.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    a.cross(other).normalize()
}

/// Where the ray enters the sphere (the near root, if positive: an origin inside is culled).
fn sphere_entry(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<f64> {
    let q = o - c;
    let [t0, _] = quadratic_roots(d.dot(d), 2.0 * q.dot(d), q.dot(q) - r * r);
    t0.filter(|&t| t > 0.0)
}

/// The real roots of a t² + b t + c, smaller first (the stable form); a linear equation's one.
fn quadratic_roots(a: f64, b: f64, c: f64) -> [Option<f64>; 2] {
    if a == 0.0 {
        return [(b != 0.0).then(|| -c / b), None];
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return [None, None];
    }
    let qq = -0.5 * (b + b.signum() * disc.sqrt());
    let (mut t0, mut t1) = (qq / a, if qq != 0.0 { c / qq } else { qq / a });
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    [Some(t0), Some(t1)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn segment(r: [f32; 2]) -> CurveSegment {
        // Along +x from the origin to (2, 0, 0).
        CurveSegment {
            p: [Vec3A::ZERO, Vec3A::new(2.0, 0.0, 0.0)],
            r,
            shape: 0,
            index: 1,
            segments: 2,
            caps: [true; 2],
            spline: None,
        }
    }

    #[test]
    fn a_tube_of_constant_radius_is_hit_on_its_side_and_caps() {
        let s = segment([0.5, 0.5]);
        let down = Ray::new(Vec3A::new(1.0, 3.0, 0.0), -Vec3A::Y);
        let t = s.intersect(&down, f32::INFINITY).unwrap();
        assert!((t - 2.5).abs() < 1e-5, "{t}");
        let sp = s.surface(down.at(t));
        assert!((sp.ng - Vec3A::Y).length() < 1e-5);
        // Half way along the second of two segments.
        assert!((sp.uv.y - 0.75).abs() < 1e-5, "{}", sp.uv);
        // The round cap beyond the end: from +x along the axis, at x = 2.5.
        let cap = Ray::new(Vec3A::new(5.0, 0.0, 0.0), -Vec3A::X);
        assert!((s.intersect(&cap, f32::INFINITY).unwrap() - 2.5).abs() < 1e-5);
        let n = s.surface(cap.at(2.5)).ng;
        assert!((n - Vec3A::X).length() < 1e-5, "{n}");
        // From inside: culled, as in Mitsuba.
        let inside = Ray::new(Vec3A::new(1.0, 0.0, 0.0), Vec3A::Y);
        assert!(s.intersect(&inside, f32::INFINITY).is_none());
        // Past the cap, a miss.
        let past = Ray::new(Vec3A::new(2.6, 3.0, 0.0), -Vec3A::Y);
        assert!(s.intersect(&past, f32::INFINITY).is_none());
    }

    #[test]
    fn a_tapering_segment_is_the_hull_of_its_end_spheres() {
        // Radius 1 at x = 0, 0.5 at x = 2: the tangent cone, at the x where a ray straight
        // down meets it, is at height y = (r0 + k x)/√(1 − k²) with k = −¼.
        let s = segment([1.0, 0.5]);
        let k = -0.25f64;
        for x in [0.5f32, 1.0, 1.5] {
            let ray = Ray::new(Vec3A::new(x, 5.0, 0.0), -Vec3A::Y);
            let t = s.intersect(&ray, f32::INFINITY).unwrap() as f64;
            let y = (1.0 + k * x as f64) / (1.0 - k * k).sqrt();
            assert!((5.0 - t - y).abs() < 1e-5, "x = {x}: {} vs {y}", 5.0 - t);
            // The normal is perpendicular to the cone's surface: tilted towards +x.
            let n = s.surface(ray.at(t as f32)).ng;
            assert!(n.x > 0.0 && (n.length() - 1.0).abs() < 1e-5);
        }
        // Near x = 0 from above, the big end sphere (its top at y = 1) is the surface.
        let top = Ray::new(Vec3A::new(-0.2, 5.0, 0.0), -Vec3A::Y);
        let t = s.intersect(&top, f32::INFINITY).unwrap();
        assert!((5.0 - t - (1.0f32 - 0.04).sqrt()).abs() < 1e-5);
        let b = s.bounds();
        assert!(b.min.cmple(Vec3A::new(-1.0, -1.0, -1.0)).all());
        assert!(b.max.cmpge(Vec3A::new(2.5, 1.0, 1.0)).all());
    }

    #[test]
    fn a_sphere_inside_its_neighbour_leaves_the_larger() {
        let s = CurveSegment {
            p: [Vec3A::ZERO, Vec3A::new(0.2, 0.0, 0.0)],
            r: [1.0, 0.5],
            shape: 0,
            index: 0,
            segments: 1,
            caps: [true; 2],
            spline: None,
        };
        let ray = Ray::new(Vec3A::new(0.0, 5.0, 0.0), -Vec3A::Y);
        assert!((s.intersect(&ray, f32::INFINITY).unwrap() - 4.0).abs() < 1e-5);
    }
}
