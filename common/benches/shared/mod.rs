//! What the benches share: rays recorded as the path tracer makes them.

use glam::Vec2;
use photonfarm::geometry::Frame;
use photonfarm::sampling::{Sampler, Stream, square_to_cosine_hemisphere};
use photonfarm::scene::Scene;

/// One scene's recorded rays: camera and bounce rays (closest hit, t_max ∞) and shadow rays
/// (occlusion, t_max 1 - 1e-4, unnormalised direction), made as the path tracer makes them.
pub struct Recorded {
    pub camera: Vec<photonfarm::geometry::Ray>,
    pub bounce: Vec<photonfarm::geometry::Ray>,
    pub shadow: Vec<photonfarm::geometry::Ray>,
}

pub const SHADOW_T_MAX: f32 = 1.0 - 1e-4;

pub fn record(scene: &Scene) -> Recorded {
    use photonfarm::geometry::{Ray, offset_ray_origin};
    let mut r = Recorded {
        camera: Vec::new(),
        bounce: Vec::new(),
        shadow: Vec::new(),
    };
    for y in 0..scene.height() {
        for x in 0..scene.width() {
            let mut s = Sampler::new(1, Stream::Camera, 0, (y * scene.width() + x) as u64);
            let ray = scene.camera.generate_ray(x, y, s.next_2d(), Vec2::ZERO);
            r.camera.push(ray);
            let Some((_, sp)) = scene.intersect(&ray) else {
                continue;
            };
            let frame = Frame::from_normal(sp.ns);
            let w = frame.to_world(square_to_cosine_hemisphere(s.next_2d()));
            r.bounce.push(Scene::spawn_ray(&sp, w));
            if let Some((_, ls)) = scene.sample_light(sp.p, s.next_1d(), s.next_2d()) {
                // As Scene::transmittance builds its first segment.
                let o = offset_ray_origin(sp.p, sp.p_err, sp.ng, ls.wi);
                let target = if ls.n == glam::Vec3A::ZERO {
                    ls.p
                } else {
                    offset_ray_origin(ls.p, ls.p_err, ls.n, o - ls.p)
                };
                r.shadow.push(Ray::new(o, target - o));
            }
        }
    }
    r
}
