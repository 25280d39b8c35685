//! Perspective, thin-lens and orthographic cameras, in Mitsuba's conventions.

use glam::{Mat4, Vec2, Vec3A};

use crate::geometry::Ray;
use crate::sampling::square_to_uniform_disk_concentric;

/// A pinhole (aperture 0), thin-lens or orthographic camera.
///
/// Camera space is Mitsuba's: +z forward, +y up, +x to the left of the image, so that a
/// `lookat` transform reproduces Mitsuba's framing exactly.
#[derive(Clone, Debug)]
pub struct Camera {
    /// Camera to world.
    pub to_world: Mat4,
    /// tan(fov/2) along the image's x axis (an orthographic camera's half width in camera
    /// space: 1, as Mitsuba's, whose `to_world` scales it).
    pub tan_half_x: f32,
    /// tan(fov/2) along the image's y axis (orthographic: the half height, 1 / aspect).
    pub tan_half_y: f32,
    /// Parallel rays along +z from the near plane (Mitsuba's `orthographic`) instead of rays
    /// through a lens.
    pub orthographic: bool,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Lens radius; 0 for a pinhole.
    pub aperture_radius: f32,
    /// Distance of the plane in focus, along the view axis.
    pub focus_distance: f32,
    /// Distance below which nothing is seen (Mitsuba's `near_clip`).
    pub near_clip: f32,
}

impl Camera {
    /// A ray through pixel (x, y) (y down from the top row), at offset `u_pixel` within the
    /// pixel (box filter) and lens position `u_lens`.
    pub fn generate_ray(&self, x: u32, y: u32, u_pixel: Vec2, u_lens: Vec2) -> Ray {
        let sx = (x as f32 + u_pixel.x) / self.width as f32;
        let sy = (y as f32 + u_pixel.y) / self.height as f32;
        let d = Vec3A::new(
            (1.0 - 2.0 * sx) * self.tan_half_x,
            (1.0 - 2.0 * sy) * self.tan_half_y,
            1.0,
        );
        if self.orthographic {
            let o = Vec3A::new(d.x, d.y, self.near_clip);
            let dir = self.to_world.transform_vector3a(Vec3A::Z).normalize();
            return Ray::new(self.to_world.transform_point3a(o), dir);
        }
        let (o_local, d_local) = if self.aperture_radius > 0.0 {
            let lens = square_to_uniform_disk_concentric(u_lens) * self.aperture_radius;
            let focus = d * self.focus_distance;
            let o = Vec3A::new(lens.x, lens.y, 0.0);
            (o, (focus - o).normalize())
        } else {
            (Vec3A::ZERO, d.normalize())
        };
        let near_t = self.near_clip / d_local.z;
        let o_local = o_local + d_local * near_t;
        let o = self.to_world.transform_point3a(o_local);
        let dir = self.to_world.transform_vector3a(d_local).normalize();
        Ray::new(o, dir)
    }

    /// Connects world point `p` to the camera through lens position `u_lens` (ignored by a
    /// pinhole), for particle tracing: where on the film (continuous pixel coordinates, x right
    /// and y down from the top-left corner) the ray from the lens point through `p` lands, the
    /// lens point, and the camera's share of the contribution, 1 / (A cos³θ r²): its importance
    /// 1 / (A cos⁴θ) (A the film's area at unit distance, so that the whole film integrates to
    /// one) times cos θ / r², over the lens point's density (which cancels the thin lens's
    /// importance over its area). A pass of one light path per pixel then adds, per pixel, what
    /// the pixel's mean is made of. None if `p` is behind the camera, nearer than the near clip
    /// or off the film.
    pub fn connect(&self, p: Vec3A, u_lens: Vec2) -> Option<CameraConnection> {
        let local = self.to_world.inverse().transform_point3a(p);
        if self.orthographic {
            return self.connect_orthographic(local);
        }
        let lens = if self.aperture_radius > 0.0 {
            let l = square_to_uniform_disk_concentric(u_lens) * self.aperture_radius;
            Vec3A::new(l.x, l.y, 0.0)
        } else {
            Vec3A::ZERO
        };
        let v = local - lens;
        let r = v.length();
        if v.z.is_nan() || v.z <= 0.0 || r <= self.near_clip {
            return None;
        }
        // The direction through the film plane at unit distance: for a thin lens, where the ray
        // from the lens point through `p` crosses the plane in focus, over its distance.
        let d = if self.aperture_radius > 0.0 {
            (lens + v * (self.focus_distance / v.z)) / self.focus_distance
        } else {
            v / v.z
        };
        let sx = (1.0 - d.x / self.tan_half_x) / 2.0;
        let sy = (1.0 - d.y / self.tan_half_y) / 2.0;
        if !((0.0..1.0).contains(&sx) && (0.0..1.0).contains(&sy)) {
            return None;
        }
        let cos = v.z / r;
        let area = 4.0 * self.tan_half_x * self.tan_half_y;
        Some(CameraConnection {
            film: Vec2::new(sx * self.width as f32, sy * self.height as f32),
            lens: self.to_world.transform_point3a(lens),
            weight: 1.0 / (area * cos * cos * cos * r * r),
        })
    }
}

impl Camera {
    /// [`Camera::connect`] for parallel rays: the film point straight behind `local` (in camera
    /// space), on the near plane. A delta direction has no 1/r² or cosine at the camera: the
    /// camera's share is 1 / A, A the film's area in world space (`to_world` scales it).
    fn connect_orthographic(&self, local: Vec3A) -> Option<CameraConnection> {
        if local.z.is_nan() || local.z <= self.near_clip {
            return None;
        }
        let sx = (1.0 - local.x / self.tan_half_x) / 2.0;
        let sy = (1.0 - local.y / self.tan_half_y) / 2.0;
        if !((0.0..1.0).contains(&sx) && (0.0..1.0).contains(&sy)) {
            return None;
        }
        let width = self.to_world.transform_vector3a(Vec3A::X).length() * 2.0 * self.tan_half_x;
        let height = self.to_world.transform_vector3a(Vec3A::Y).length() * 2.0 * self.tan_half_y;
        Some(CameraConnection {
            film: Vec2::new(sx * self.width as f32, sy * self.height as f32),
            lens: self
                .to_world
                .transform_point3a(Vec3A::new(local.x, local.y, self.near_clip)),
            weight: 1.0 / (width * height),
        })
    }
}

/// A world point connected to the camera ([`Camera::connect`]).
#[derive(Clone, Copy, Debug)]
pub struct CameraConnection {
    /// Where on the film, in pixels from the top-left corner.
    pub film: Vec2,
    /// The lens point, in world space.
    pub lens: Vec3A,
    /// The camera's share of the contribution, 1 / (A cos³θ r²).
    pub weight: f32,
}
