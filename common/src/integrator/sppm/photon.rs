//! The stored photon: 24 bytes, so that a million photons fit in 24 MB.

use glam::Vec3A;
use half::f16;

use crate::color::Rgb;

/// A photon at a surface: where, from where, how much.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
pub struct Photon {
    /// Position.
    pub p: [f32; 3],
    /// Unit direction towards where the photon came from, octahedrally encoded in 2 × 16 bits.
    dir: u32,
    /// Power in units of the iteration's power unit, as half floats: relative precision 5e-4,
    /// far below the noise of a density estimate.
    power: [u16; 3],
    _pad: u16,
}

const _: () = assert!(std::mem::size_of::<Photon>() == 24);

impl Photon {
    /// A photon; `power` is in units of the caller's power unit.
    pub fn new(p: Vec3A, dir: Vec3A, power: Rgb) -> Photon {
        Photon {
            p: p.into(),
            dir: encode_octahedral(dir),
            power: [power.x, power.y, power.z].map(|c| f16::from_f32(c).to_bits()),
            _pad: 0,
        }
    }

    /// Position.
    #[inline]
    pub fn position(&self) -> Vec3A {
        Vec3A::from(self.p)
    }

    /// Direction towards the photon's origin.
    #[inline]
    pub fn direction(&self) -> Vec3A {
        decode_octahedral(self.dir)
    }

    /// Power in units of the iteration's power unit.
    #[inline]
    pub fn power(&self) -> Rgb {
        let [r, g, b] = self.power.map(|c| f16::from_bits(c).to_f32());
        Rgb::new(r, g, b)
    }
}

/// Octahedral map of a unit vector to 2 × 16 bits (Meyer et al. 2010).
fn encode_octahedral(v: Vec3A) -> u32 {
    let l1 = v.x.abs() + v.y.abs() + v.z.abs();
    let (mut x, mut y) = (v.x / l1, v.y / l1);
    if v.z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * ox.signum();
        y = (1.0 - ox.abs()) * oy.signum();
    }
    let q = |c: f32| ((c.clamp(-1.0, 1.0) * 0.5 + 0.5) * 65535.0).round() as u32;
    q(x) | (q(y) << 16)
}

fn decode_octahedral(e: u32) -> Vec3A {
    let d = |c: u32| (c as f32 / 65535.0) * 2.0 - 1.0;
    let (x, y) = (d(e & 0xffff), d(e >> 16));
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - y.abs()) * x.signum(), (1.0 - x.abs()) * y.signum())
    } else {
        (x, y)
    };
    Vec3A::new(x, y, z).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Sampler, Stream, square_to_uniform_sphere};

    #[test]
    fn round_trips() {
        let mut s = Sampler::new(1, Stream::Photon, 0, 0);
        for _ in 0..10_000 {
            let d = square_to_uniform_sphere(s.next_2d());
            let ph = Photon::new(Vec3A::new(1.0, -2.0, 3.5), d, Rgb::new(0.25, 1.5, 3.0e-3));
            // 16 bits per coordinate: about 5e-5 radians at worst.
            assert!((ph.direction() - d).length() < 2e-4, "{d} -> {}", ph.direction());
            assert_eq!(ph.position(), Vec3A::new(1.0, -2.0, 3.5));
            assert!((ph.power() - Rgb::new(0.25, 1.5, 3.0e-3)).abs().max_element() < 1e-3);
        }
        for d in [Vec3A::Z, -Vec3A::Z, Vec3A::X, -Vec3A::Y] {
            assert!(Photon::new(Vec3A::ZERO, d, Rgb::ONE).direction().dot(d) > 0.99999);
        }
    }
}
