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

    /// Mitsuba's shading frame: the first tangent is `dpdu` made orthogonal to `n` (Gram–Schmidt),
    /// the second n × s; where `dpdu` is degenerate, [`Frame::from_normal`]. Anisotropic
    /// materials need it: their roughness follows the surface's parameterisation.
    pub fn from_normal_and_tangent(n: Vec3A, dpdu: Vec3A) -> Frame {
        let s = (dpdu - n * n.dot(dpdu)).normalize_or_zero();
        if s == Vec3A::ZERO {
            return Frame::from_normal(n);
        }
        Frame { s, t: n.cross(s), n }
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
            for dpdu in [Vec3A::X, Vec3A::new(0.3, 2.0, -1.0), Vec3A::ZERO, n] {
                let f = Frame::from_normal_and_tangent(n, dpdu);
                assert!((f.s.length() - 1.0).abs() < 1e-5);
                assert!((f.t.length() - 1.0).abs() < 1e-5);
                assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5);
                assert!((f.s.cross(f.t) - n).length() < 1e-5);
                assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
            }
        }
    }
}
