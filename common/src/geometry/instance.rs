//! Mitsuba's `instance` of a `shapegroup`: one copy of a group's geometry, with its own
//! `to_world`. The group is stored once, in a tree of its own (the bottom level); the scene's tree
//! holds each instance as one primitive (the top level), whose test carries the ray into the
//! group's space. A forest of a thousand trees costs one tree's triangles.

use std::sync::Arc;

use glam::{Affine3A, Mat3A, Vec3A};

use super::{Aabb, Bvh, Hit, PrimHit, Ray, SurfacePoint, gamma};

/// A placed copy of a group.
#[derive(Clone, Debug)]
pub struct Instance {
    group: Arc<Bvh>,
    to_world: Affine3A,
    to_object: Affine3A,
    /// The inverse transpose, which carries normals: Mitsuba orients an instance by its
    /// transformed normals, so a mirroring `to_world` keeps each face's front.
    normal_to_world: Mat3A,
    bounds: Aabb,
}

impl Instance {
    /// `group` placed by `to_world`; `None` if the matrix cannot be inverted.
    pub fn new(group: Arc<Bvh>, to_world: Affine3A) -> Option<Instance> {
        let det = to_world.matrix3.determinant();
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let to_object = to_world.inverse();
        let b = group.bounds();
        let mut bounds = Aabb::EMPTY;
        for i in 0..8 {
            let corner = Vec3A::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            );
            bounds = bounds.grow(to_world.transform_point3a(corner));
        }
        // The corners' rounding, so that the box holds every transformed point.
        let slack = gamma(3) * (bounds.min.abs().max(bounds.max.abs()));
        bounds.min -= slack;
        bounds.max += slack;
        Some(Instance {
            group,
            to_world,
            to_object,
            normal_to_world: to_object.matrix3.transpose(),
            bounds,
        })
    }

    /// Bounds in world space.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The ray in the group's space. Its direction is not renormalised, so distances along it
    /// are the world ray's.
    #[inline]
    fn object_ray(&self, ray: &Ray) -> Ray {
        Ray::new(
            self.to_object.transform_point3a(ray.o),
            self.to_object.transform_vector3a(ray.d),
        )
    }

    /// The group's closest hit closer than `t_max` (its `prim` indexes the group's primitives).
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.group.intersect(&self.object_ray(ray), t_max)
    }

    /// [`Instance::intersect`] as a primitive's hit. Never inlined: the group's traversal calls
    /// the primitive test again, and that recursion would otherwise stop the compiler from
    /// inlining the triangle test into every traversal (11% slower on cbox-spheres).
    #[inline(never)]
    pub(super) fn intersect_placed(&self, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        self.intersect(ray, t_max).map(|h| PrimHit {
            t: h.t,
            b1: h.b1,
            b2: h.b2,
            inner: h.prim,
        })
    }

    /// Whether the group blocks the ray before `t_max`.
    #[inline]
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        self.group.occluded(&self.object_ray(ray), t_max)
    }

    /// The surface at the group's hit `inner`, in world space.
    pub fn surface(&self, ray: &Ray, inner: &Hit) -> SurfacePoint {
        let local = self.group.primitives()[inner.prim as usize].surface(&self.object_ray(ray), inner);
        let m = self.to_world.matrix3;
        let abs_m = Mat3A::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
        let p = self.to_world.transform_point3a(local.p);
        // pbrt's bound for a transformed point, counted twice: a ray leaving the point is
        // carried back into the group's space before it is tested, rounding again.
        let rounding = gamma(3) * (abs_m * local.p.abs() + self.to_world.translation.abs());
        let p_err = (1.0 + gamma(3)) * (abs_m * local.p_err) + 2.0 * rounding;
        let normal = |n: Vec3A| (self.normal_to_world * n).normalize_or_zero();
        SurfacePoint {
            p,
            p_err,
            ng: normal(local.ng),
            ns: normal(local.ns),
            dpdu: m * local.dpdu,
            dpdv: m * local.dpdv,
            ..local
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Quat, Vec3};

    use super::*;
    use crate::geometry::{Primitive, Triangle};
    use crate::sampling::{Sampler, Stream};

    fn triangles(m: &Mat4) -> Vec<Primitive> {
        let corners = [
            [
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            [
                Vec3::new(0.2, 0.1, 0.5),
                Vec3::new(-0.8, 0.3, 0.4),
                Vec3::new(0.1, -0.9, 0.6),
            ],
            [
                Vec3::new(0.5, 0.5, -0.5),
                Vec3::new(0.5, -0.5, -0.2),
                Vec3::new(-0.5, 0.2, -0.4),
            ],
        ];
        corners
            .iter()
            .map(|c| Primitive::Triangle(Triangle::bare(c.map(|p| Vec3A::from(m.transform_point3(p))))))
            .collect()
    }

    /// An instance finds the hits of its group's triangles placed by to_world, at the same
    /// distances, with the normals Mitsuba gives it: the transformed triangles' own under a
    /// proper transform, their reverse under a mirroring one (the winding turns, the inverse
    /// transpose does not).
    #[test]
    fn an_instance_hits_what_its_group_placed_by_to_world_would() {
        let group = Arc::new(Bvh::build(triangles(&Mat4::IDENTITY)));
        let proper = Mat4::from_scale_rotation_translation(
            Vec3::new(1.5, 0.5, 0.8),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 0.2),
            Vec3::new(0.4, -1.0, 2.0),
        );
        let mirrored = proper * Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        for (m, sign) in [(proper, 1.0), (mirrored, -1.0)] {
            let instance = Instance::new(group.clone(), glam::Affine3A::from_mat4(m)).unwrap();
            let flat = Bvh::build(triangles(&m));
            let mut s = Sampler::new(3, Stream::Camera, 0, 0);
            let mut hits = 0;
            for _ in 0..2000 {
                let o =
                    Vec3A::new(0.4, -1.0, 2.0) + 3.0 * (Vec3A::from(s.next_2d().extend(s.next_1d())) - 0.5);
                let target =
                    Vec3A::new(0.4, -1.0, 2.0) + (Vec3A::from(s.next_2d().extend(s.next_1d())) - 0.5);
                let ray = Ray::new(o, target - o);
                let a = instance.intersect(&ray, f32::INFINITY);
                let b = flat.intersect(&ray, f32::INFINITY);
                assert_eq!(a.is_some(), b.is_some(), "{ray:?}");
                let (Some(a), Some(b)) = (a, b) else { continue };
                hits += 1;
                assert!((a.t - b.t).abs() <= 1e-4 * b.t, "{} vs {}", a.t, b.t);
                let sa = instance.surface(&ray, &a);
                let sb = flat.primitives()[b.prim as usize].surface(&ray, &b);
                assert!((sa.p - sb.p).length() < 1e-4, "{} vs {}", sa.p, sb.p);
                assert!((sa.ng - sign * sb.ng).length() < 1e-4, "{} vs {}", sa.ng, sb.ng);
                assert!(instance.bounds().grow(sa.p) == instance.bounds());
                assert!(instance.occluded(&ray, f32::INFINITY));
            }
            assert!(hits > 200, "{hits} hits");
        }
    }
}
