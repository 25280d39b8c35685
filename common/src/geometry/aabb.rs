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
}
