//! Rays, shapes and the bounding volume hierarchy that finds what a ray hits first.

mod aabb;
mod bvh;
mod bvh4;
mod curve;
mod cylinder;
mod frame;
mod instance;
mod packet;
mod ray;
mod spatial_split;
mod sphere;
mod tri4;
mod triangle;

pub use aabb::Aabb;
pub use bvh::{Backend, Bvh};
pub use curve::{CurveSegment, SPLINE_PIECES, SplineSegment};
pub use cylinder::Cylinder;
pub use frame::Frame;
pub use instance::Instance;
pub use packet::{Hits8, Rays8};
pub use ray::{Ray, offset_ray_origin};
pub use sphere::Sphere;
pub use triangle::Triangle;

use glam::Vec3A;

/// Something the BVH holds: a triangle or an analytic sphere, tagged with its shape.
#[derive(Clone, Debug)]
pub enum Primitive {
    /// A triangle of a mesh (rectangles, cubes, disks, OBJ and PLY files all become these).
    Triangle(Triangle),
    /// An analytic sphere: exact silhouette and normals, which glass spheres need.
    Sphere(Sphere),
    /// An analytic open tube (Mitsuba's `cylinder`).
    Cylinder(Box<Cylinder>),
    /// A segment of a linear curve (Mitsuba's `linearcurve`).
    Curve(Box<CurveSegment>),
    /// A placed copy of a shape group, tested in the group's own tree.
    Instance(Box<Instance>),
}

/// A primitive's hit: distance and barycentrics, and for an instance which of its group's
/// primitives was hit.
#[derive(Clone, Copy, Debug)]
pub struct PrimHit {
    /// Distance along the ray.
    pub t: f32,
    /// First barycentric coordinate (triangles).
    pub b1: f32,
    /// Second barycentric coordinate.
    pub b2: f32,
    /// The group's primitive (instances; 0 otherwise).
    pub inner: u32,
}

/// The closest hit along a ray, before the surface is evaluated.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray (in units of its direction's length).
    pub t: f32,
    /// Index of the primitive in the BVH's order.
    pub prim: u32,
    /// Barycentric coordinates of the hit (triangles only).
    pub b1: f32,
    /// Second barycentric coordinate.
    pub b2: f32,
    /// For an instance, the primitive of its group that was hit.
    pub inner: u32,
}

/// Everything the integrators need about a surface point.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    /// Position.
    pub p: Vec3A,
    /// Conservative bound on the floating-point error of `p`, per axis: rays leaving the point
    /// start just outside this box, which avoids self-intersection without a scene-scale epsilon.
    pub p_err: Vec3A,
    /// Geometric normal, oriented as the shape's normals are (after `flip_normals`).
    pub ng: Vec3A,
    /// Shading normal (interpolated vertex normals where a mesh has them), same hemisphere as `ng`.
    pub ns: Vec3A,
    /// Which shape was hit.
    pub shape: u32,
    /// Texture coordinates, parameterised as Mitsuba's shapes are.
    pub uv: glam::Vec2,
    /// The mesh attribute its material reads, interpolated (zero on other shapes).
    pub attr: Vec3A,
    /// ∂p/∂u as Mitsuba's shapes give it (may be zero where the parameterisation is
    /// singular): anisotropic materials orient their frame by it, bump maps scale by it.
    pub dpdu: Vec3A,
    /// ∂p/∂v, likewise.
    pub dpdv: Vec3A,
}

impl SurfacePoint {
    /// Where its material's textures are looked up.
    #[inline]
    pub fn tex(&self) -> crate::texture::TexAt {
        crate::texture::TexAt {
            uv: self.uv,
            attr: self.attr,
        }
    }

    /// A point inside a medium: no surface, no error box, no normal.
    pub fn in_medium(p: Vec3A) -> SurfacePoint {
        SurfacePoint {
            p,
            p_err: Vec3A::ZERO,
            ng: Vec3A::ZERO,
            ns: Vec3A::ZERO,
            shape: u32::MAX,
            uv: glam::Vec2::ZERO,
            attr: Vec3A::ZERO,
            dpdu: Vec3A::ZERO,
            dpdv: Vec3A::ZERO,
        }
    }
}

impl Primitive {
    /// Bounds of the primitive.
    pub fn bounds(&self) -> Aabb {
        match self {
            Primitive::Triangle(t) => t.bounds(),
            Primitive::Sphere(s) => s.bounds(),
            Primitive::Cylinder(c) => c.bounds(),
            Primitive::Curve(c) => c.bounds(),
            Primitive::Instance(i) => i.bounds(),
        }
    }

    /// Shape index the primitive belongs to (an instance's surfaces name their own shapes; it
    /// belongs to none).
    pub fn shape(&self) -> u32 {
        match self {
            Primitive::Triangle(t) => t.shape,
            Primitive::Sphere(s) => s.shape,
            Primitive::Cylinder(c) => c.shape,
            Primitive::Curve(c) => c.shape,
            Primitive::Instance(_) => u32::MAX,
        }
    }

    /// Surface area, used to sample area lights uniformly (an instance is never one: the loader
    /// refuses emitters in shape groups, as Mitsuba does).
    pub fn area(&self) -> f32 {
        match self {
            Primitive::Triangle(t) => t.area(),
            Primitive::Sphere(s) => s.area(),
            Primitive::Cylinder(c) => c.area(),
            // Curves are never lights: the loader refuses them, as Mitsuba cannot sample them.
            Primitive::Curve(_) | Primitive::Instance(_) => 0.0,
        }
    }

    /// Ray intersection closer than `t_max`. Inlined into every traversal loop, where the time
    /// goes (left to the compiler once instances made it recursive, it was not: 4-11% slower).
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        match self {
            Primitive::Triangle(tri) => {
                tri.intersect(ray, t_max)
                    .map(|(t, b1, b2)| PrimHit { t, b1, b2, inner: 0 })
            }
            Primitive::Sphere(s) => s.intersect(ray, t_max).map(|t| PrimHit {
                t,
                b1: 0.0,
                b2: 0.0,
                inner: 0,
            }),
            Primitive::Cylinder(c) => c.intersect(ray, t_max).map(|t| PrimHit {
                t,
                b1: 0.0,
                b2: 0.0,
                inner: 0,
            }),
            Primitive::Curve(c) => c.intersect(ray, t_max).map(|t| PrimHit {
                t,
                b1: 0.0,
                b2: 0.0,
                inner: 0,
            }),
            Primitive::Instance(i) => i.intersect_placed(ray, t_max),
        }
    }

    /// The surface at a hit.
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> SurfacePoint {
        match self {
            Primitive::Triangle(t) => t.surface(hit.b1, hit.b2),
            Primitive::Sphere(s) => s.surface(ray.o + ray.d * hit.t),
            Primitive::Cylinder(c) => c.surface(ray.o + ray.d * hit.t),
            Primitive::Curve(c) => c.surface(ray.o + ray.d * hit.t),
            Primitive::Instance(i) => i.surface(
                ray,
                &Hit {
                    prim: hit.inner,
                    inner: 0,
                    ..*hit
                },
            ),
        }
    }

    /// A uniformly distributed point on the primitive: (point, its surface).
    pub fn sample_point(&self, u: glam::Vec2) -> SurfacePoint {
        match self {
            Primitive::Triangle(t) => {
                let b = crate::sampling::square_to_uniform_triangle(u);
                t.surface(b.x, b.y)
            }
            Primitive::Sphere(s) => {
                s.surface(s.center + s.radius * crate::sampling::square_to_uniform_sphere(u))
            }
            Primitive::Cylinder(c) => c.sample_point(u),
            Primitive::Instance(_) => {
                unreachable!("the loader refuses emitters in shape groups, so no light holds an instance")
            }
            Primitive::Curve(_) => unreachable!("the loader refuses curves as emitters"),
        }
    }
}

/// The angle of (x, y) about the origin from +x, in [0, 2π): the u of Mitsuba's analytic
/// shapes.
#[inline]
pub(crate) fn azimuth(y: f32, x: f32) -> f32 {
    let phi = libm::atan2f(y, x);
    if phi < 0.0 {
        phi + 2.0 * std::f32::consts::PI
    } else {
        phi
    }
}

/// pbrt's γ(n): the relative error bound of n chained floating-point operations.
#[inline]
pub(crate) fn gamma(n: i32) -> f32 {
    let e = f32::EPSILON * 0.5 * n as f32;
    e / (1.0 - e)
}
