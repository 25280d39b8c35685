//! A hashed uniform grid over the photons of one iteration.
//!
//! Why a grid and not a kd-tree: every query of an iteration has the same radius, so cells of
//! twice that radius put every neighbourhood in at most 8 cells, and the grid is built by one
//! counting sort (linear time, no recursion). The SPPM benchmark measures it against kiddo's
//! kd-tree on the same photons. Buffers are kept between iterations, so memory stays flat.

use glam::Vec3A;

use super::grid::{Buckets, buckets_of_sphere, cell_of, hash_cell};
use super::photon::Photon;

/// Photons bucketed by grid cell.
#[derive(Debug, Default)]
pub struct PhotonMap {
    inv_cell: f32,
    radius: f32,
    mask: usize,
    buckets: Buckets,
    photons: Vec<Photon>,
}

impl PhotonMap {
    /// An empty map.
    pub fn new() -> PhotonMap {
        PhotonMap::default()
    }

    /// Number of photons.
    pub fn len(&self) -> usize {
        self.photons.len()
    }

    /// Whether there are no photons.
    pub fn is_empty(&self) -> bool {
        self.photons.is_empty()
    }

    /// Replaces the contents with `photons`, for queries of `radius`. Photons keep their input
    /// order within a bucket, so queries visit them in a deterministic order.
    pub fn build(&mut self, photons: &[Photon], radius: f32) {
        self.radius = radius;
        self.inv_cell = 1.0 / (2.0 * radius);
        let size = photons.len().max(1).next_power_of_two();
        self.mask = size - 1;
        let (inv_cell, mask) = (self.inv_cell, self.mask);
        self.buckets.sort(
            size,
            |add| {
                for p in photons {
                    add(hash_cell(cell_of(p.position(), inv_cell), mask), *p);
                }
            },
            &mut self.photons,
        );
    }

    /// Calls `f(photon, squared distance)` for every photon within the radius of `p`.
    #[inline]
    pub fn for_each_near(&self, p: Vec3A, mut f: impl FnMut(&Photon, f32)) {
        if self.photons.is_empty() {
            return;
        }
        let r = self.radius;
        let mut seen = [0usize; 8];
        let n = buckets_of_sphere(p, r, self.inv_cell, self.mask, &mut seen);
        let r2 = r * r;
        for &b in &seen[..n] {
            for ph in &self.photons[self.buckets.range(b)] {
                let d2 = (ph.position() - p).length_squared();
                if d2 < r2 {
                    f(ph, d2);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use crate::sampling::{Sampler, Stream};

    #[test]
    fn finds_exactly_the_photons_within_the_radius() {
        let mut s = Sampler::new(5, Stream::Photon, 0, 0);
        let photons: Vec<Photon> = (0..20_000)
            .map(|_| {
                Photon::new(
                    Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 4.0 - 2.0,
                    Vec3A::Z,
                    Rgb::ONE,
                )
            })
            .collect();
        let mut map = PhotonMap::new();
        for radius in [0.05f32, 0.3] {
            map.build(&photons, radius);
            for _ in 0..300 {
                let q = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 4.4 - 2.2;
                let mut found = Vec::new();
                map.for_each_near(q, |p, _| found.push(p.p));
                let mut brute: Vec<[f32; 3]> = photons
                    .iter()
                    .filter(|p| (p.position() - q).length_squared() < radius * radius)
                    .map(|p| p.p)
                    .collect();
                let key = |a: &[f32; 3], b: &[f32; 3]| a.partial_cmp(b).unwrap();
                found.sort_by(key);
                brute.sort_by(key);
                assert_eq!(found, brute);
            }
        }
    }
}
