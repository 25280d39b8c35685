use glam::Vec3A;

/// A ray: origin and direction (not necessarily normalised).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub o: Vec3A,
    /// Direction.
    pub d: Vec3A,
}

impl Ray {
    /// A ray from `o` along `d`.
    pub fn new(o: Vec3A, d: Vec3A) -> Ray {
        Ray { o, d }
    }

    /// The point at parameter `t`.
    pub fn at(&self, t: f32) -> Vec3A {
        self.o + self.d * t
    }
}

/// Moves `p` just outside its error box, on the side of the normal that `w` leaves through.
///
/// Why: a ray leaving a surface must not hit that surface again (acne), and the offset must be
/// as small as the arithmetic allows so that it never jumps through thin geometry (leaks).
/// This follows pbrt-v4's error-bound approach instead of a scene-scale epsilon.
pub fn offset_ray_origin(p: Vec3A, p_err: Vec3A, ng: Vec3A, w: Vec3A) -> Vec3A {
    let d = ng.abs().dot(p_err);
    let mut offset = d * ng;
    if w.dot(ng) < 0.0 {
        offset = -offset;
    }
    let mut po = p + offset;
    // Round away from p so that the rounding of the addition cannot undo the offset.
    for i in 0..3 {
        if offset[i] > 0.0 {
            po[i] = po[i].next_up();
        } else if offset[i] < 0.0 {
            po[i] = po[i].next_down();
        }
    }
    po
}
