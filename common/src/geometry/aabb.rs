use glam::Vec3A;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3A,
    /// Upper corner.
    pub max: Vec3A,
}

impl Default for Aabb {
    fn default() -> Self {
        Aabb::EMPTY
    }
}

impl Aabb {
    /// The box that contains nothing: the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: Vec3A::splat(f32::INFINITY),
        max: Vec3A::splat(f32::NEG_INFINITY),
    };

    /// Box around one point.
    pub fn point(p: Vec3A) -> Aabb {
        Aabb { min: p, max: p }
    }

    /// Smallest box holding both.
    pub fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// Smallest box holding the box and the point.
    pub fn grow(self, p: Vec3A) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The box both hold (empty if they do not meet).
    pub fn intersection(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.max(o.min),
            max: self.max.min(o.max),
        }
    }

    /// Whether the box holds nothing.
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Edge lengths.
    pub fn extent(&self) -> Vec3A {
        if self.is_empty() {
            Vec3A::ZERO
        } else {
            self.max - self.min
        }
    }

    /// Centre.
    pub fn center(&self) -> Vec3A {
        0.5 * (self.min + self.max)
    }

    /// Surface area: the SAH's measure of how likely a random ray is to hit the box.
    pub fn surface_area(&self) -> f32 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// The part of `ray.at(0..t_max)` inside the box (slab test), as (entry, exit) with
    /// entry < exit; None if the ray misses it. Axis by axis, with a zero direction component
    /// tested by the origin, so that no NaN arises whatever the platform's min and max do.
    pub fn clip(&self, ray: &crate::geometry::Ray, t_max: f32) -> Option<(f32, f32)> {
        let (mut near, mut far) = (0.0f32, t_max);
        for axis in 0..3 {
            let (o, d) = (ray.o[axis], ray.d[axis]);
            let (lo, hi) = (self.min[axis], self.max[axis]);
            if d == 0.0 {
                if o < lo || o > hi {
                    return None;
                }
                continue;
            }
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            let (a, b) = if a <= b { (a, b) } else { (b, a) };
            near = if a > near { a } else { near };
            far = if b < far { b } else { far };
        }
        (near < far).then_some((near, far))
    }
}
