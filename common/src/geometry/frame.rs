use glam::Vec3A;

/// An orthonormal basis around a normal: BSDFs work in this local frame, with the normal as +z.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// First tangent.
    pub s: Vec3A,
    /// Second tangent.
    pub t: Vec3A,
    /// Normal.
    pub n: Vec3A,
}

impl Frame {
    /// Duff et al.'s branchless basis (2017): continuous almost everywhere, no normalisation.
    pub fn from_normal(n: Vec3A) -> Frame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Frame {
            s: Vec3A::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            t: Vec3A::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// World direction to local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3A) -> Vec3A {
        Vec3A::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local direction to world coordinates.
    #[inline]
    pub fn to_world(&self, v: Vec3A) -> Vec3A {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal() {
        for n in [
            Vec3A::Z,
            -Vec3A::Z,
            Vec3A::X,
            Vec3A::new(0.3, -0.5, 0.8).normalize(),
            Vec3A::new(1e-8, 0.0, -1.0).normalize(),
        ] {
            let f = Frame::from_normal(n);
            assert!((f.s.length() - 1.0).abs() < 1e-5);
            assert!((f.t.length() - 1.0).abs() < 1e-5);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5);
            let v = Vec3A::new(0.2, 0.4, -0.7);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }
}
