//! Perspective and thin-lens cameras, in Mitsuba's conventions.

use glam::{Mat4, Vec2, Vec3A};

use crate::geometry::Ray;
use crate::sampling::square_to_uniform_disk_concentric;

/// A pinhole (aperture 0) or thin-lens camera.
///
/// Camera space is Mitsuba's: +z forward, +y up, +x to the left of the image, so that a
/// `lookat` transform reproduces Mitsuba's framing exactly.
#[derive(Clone, Debug)]
pub struct Camera {
    /// Camera to world.
    pub to_world: Mat4,
    /// tan(fov/2) along the image's x axis.
    pub tan_half_x: f32,
    /// tan(fov/2) along the image's y axis.
    pub tan_half_y: f32,
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
}
