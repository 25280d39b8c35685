//! What the benches share: a large mesh, and rays recorded as the path tracer makes them.

#![allow(dead_code)] // each bench uses part of it

use std::io::Write;
use std::path::Path;

use glam::Vec2;
use photonfarm::geometry::Frame;
use photonfarm::sampling::{Sampler, Stream, square_to_cosine_hemisphere};
use photonfarm::scene::Scene;

/// A lat-long sphere with a bumpy radius, as a binary little-endian PLY.
fn write_bumpy_sphere(path: &Path, rings: u32, segments: u32) -> usize {
    let mut verts = Vec::new();
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let phi = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
            let r = 0.45 * (1.0 + 0.06 * libm::sinf(13.0 * theta) * libm::sinf(17.0 * phi));
            verts.push([
                r * libm::sinf(theta) * libm::cosf(phi),
                -0.5 + r * libm::cosf(theta),
                r * libm::sinf(theta) * libm::sinf(phi),
            ]);
        }
    }
    let mut faces = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let a = i * segments + j;
            let b = i * segments + (j + 1) % segments;
            let (c, d) = (a + segments, b + segments);
            faces.push([a, c, b]);
            faces.push([b, c, d]);
        }
    }
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    write!(
        f,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        verts.len(),
        faces.len()
    )
    .unwrap();
    for v in &verts {
        for c in v {
            f.write_all(&c.to_le_bytes()).unwrap();
        }
    }
    for t in &faces {
        f.write_all(&[3u8]).unwrap();
        for i in t {
            f.write_all(&(*i as i32).to_le_bytes()).unwrap();
        }
    }
    faces.len()
}

/// The Cornell box with its two boxes replaced by a bumpy sphere of 131,072 triangles (a
/// binary PLY written to `dir`; smooth vertex normals unless `face_normals`), and the triangle
/// count.
pub fn bumpy_cbox(dir: &Path, defines: &[(String, String)], face_normals: bool) -> (Scene, usize) {
    let refs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs");
    let tris = write_bumpy_sphere(&dir.join("bumpy.ply"), 256, 256);
    let text = std::fs::read_to_string(refs.join("cbox.xml")).unwrap();
    let start = text.find("<shape type=\"cube\" id=\"small-box\">").unwrap();
    let text = format!(
        "{}<shape type=\"ply\"><string name=\"filename\" value=\"bumpy.ply\"/>\
         <boolean name=\"face_normals\" value=\"{face_normals}\"/><ref id=\"white\"/></shape>\n</scene>\n",
        &text[..start]
    );
    let path = dir.join("bumpy.xml");
    std::fs::write(&path, text).unwrap();
    (Scene::load(&path, defines).unwrap(), tris)
}

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
