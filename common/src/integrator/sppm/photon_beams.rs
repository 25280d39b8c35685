//! Photon beams (Jarosz, Nowrouzezahrai, Sadeghi and Jensen 2011, "A comprehensive theory of
//! volumetric radiance estimation using photon points and beams", with the progressive radius
//! of "Progressive Photon Beams"): a photon's flight through a medium is kept as a segment, and
//! a camera ray gathers every segment that passes within the radius of it, with a 1D kernel
//! across both. One segment lights every pixel whose rays it passes, where a photon point lights
//! only the rays through its sphere, so in a thin medium far fewer photons make smooth light.
//!
//! The query is the hashed grid of [`BeamMap`](super::BeamMap), marched along the camera ray.
//! Segments are cut into pieces no longer than a cell, each listed in every cell that its
//! bounds grown by the radius overlap; a segment counts once, in the piece that holds its point
//! nearest the camera ray and the cell that holds the ray's point nearest it. Sums are taken in
//! a fixed order, so an iteration gives the same bits on every machine.

use glam::Vec3A;

use super::grid::{Buckets, buckets_of_box, clip_to_box, hash_cell, march};
use crate::color::Rgb;
use crate::geometry::{Aabb, Ray};

/// A photon's flight through a medium, from where it started (a light's first flight is direct
/// light and not kept) to its collision or the surface behind.
#[derive(Clone, Copy, Debug)]
pub struct BeamSegment {
    /// Start.
    pub origin: Vec3A,
    /// Unit direction of flight.
    pub direction: Vec3A,
    /// Length (a flight to infinity is cut where it leaves the scene's bounds and the camera).
    pub length: f32,
    /// Power at the start, in units of the iteration's power unit, already divided by the share
    /// of photons that keep beams.
    pub power: Rgb,
    /// The medium flown through.
    pub medium: u32,
}

/// A piece of a segment, listed in a cell.
#[derive(Clone, Copy, Debug, Default)]
struct Piece {
    segment: u32,
    /// The part [s0, s1) of the segment's length this piece holds.
    s0: f32,
    s1: f32,
}

/// Where a segment passes nearest a camera ray.
#[derive(Clone, Copy, Debug)]
pub struct Crossing {
    /// Distance along the camera ray.
    pub t: f32,
    /// Distance along the segment.
    pub s: f32,
    /// Sine of the angle between the two.
    pub sin: f32,
}

/// The segments of an iteration, bucketed for ray queries.
#[derive(Debug, Default)]
pub struct PhotonBeamMap {
    radius: f32,
    cell: f32,
    mask: usize,
    lo: Vec3A,
    hi: Vec3A,
    segments: Vec<BeamSegment>,
    buckets: Buckets,
    pieces: Vec<Piece>,
}

/// Cell width in radii. Wider cells hold more pieces a ray must test, narrower ones list each
/// piece in more cells and make rays step through more of them. 10 iterations of
/// `scenes/volumetric.xml` at 240×160 took 131 s with 2 radii, 25 s with 4, 6.5 s with 8,
/// 4.7 s with 16 and 6.8 s with 32.
const CELL_RADII: f32 = 16.0;

/// Cells per axis of the beams' bounds at most: as the radius shrinks over thousands of
/// iterations, cells stop shrinking with it here.
const CELLS_PER_AXIS: f32 = 128.0;

impl PhotonBeamMap {
    /// An empty map.
    pub fn new() -> PhotonBeamMap {
        PhotonBeamMap::default()
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.segments.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.segments.is_empty()
    }

    /// Replaces the contents with `segments` (those flying to infinity cut where they leave
    /// `bounds`, which must hold everything the camera sees in a medium), for a kernel of
    /// `radius`.
    pub fn build(&mut self, segments: &[BeamSegment], radius: f32, bounds: &Aabb) {
        self.radius = radius;
        let extent = (bounds.max - bounds.min).max_element();
        self.cell = (CELL_RADII * radius).max(extent / CELLS_PER_AXIS);
        self.segments.clear();
        for seg in segments {
            let length = if seg.length.is_finite() {
                seg.length
            } else {
                let ray = Ray::new(seg.origin, seg.direction);
                match clip_to_box(&ray, bounds.min, bounds.max, seg.length) {
                    Some((_, t1)) => t1,
                    None => continue,
                }
            };
            self.segments.push(BeamSegment { length, ..*seg });
        }
        let grow = Vec3A::splat(radius);
        self.lo = Vec3A::INFINITY;
        self.hi = Vec3A::NEG_INFINITY;
        for seg in &self.segments {
            let end = seg.origin + seg.direction * seg.length;
            self.lo = self.lo.min(seg.origin.min(end) - grow);
            self.hi = self.hi.max(seg.origin.max(end) + grow);
        }
        let size = (self.segments.len() * 8).max(1).next_power_of_two();
        self.mask = size - 1;
        let (cell, mask, inv_cell) = (self.cell, self.mask, 1.0 / self.cell);
        let segments = &self.segments;
        self.buckets.sort(
            size,
            |add| {
                let mut seen = [0usize; 27];
                for (i, seg) in segments.iter().enumerate() {
                    let n = (seg.length / cell).ceil().max(1.0) as usize;
                    for k in 0..n {
                        let s0 = seg.length * k as f32 / n as f32;
                        let s1 = if k + 1 == n {
                            seg.length
                        } else {
                            seg.length * (k + 1) as f32 / n as f32
                        };
                        let (a, b) = (seg.origin + seg.direction * s0, seg.origin + seg.direction * s1);
                        let piece = Piece {
                            segment: i as u32,
                            s0,
                            s1,
                        };
                        // A piece spans at most 1.5 cells with its radius: 3 per axis.
                        let count =
                            buckets_of_box(a.min(b) - grow, a.max(b) + grow, inv_cell, mask, 3, &mut seen);
                        for &bucket in &seen[..count] {
                            add(bucket, piece);
                        }
                    }
                }
            },
            &mut self.pieces,
        );
    }

    /// Calls `f(segment, crossing)` once for every segment in medium `medium` that passes
    /// within the radius of `ray.at(0..t_max)` at a ray distance before `t_stop`, in ray order
    /// of the cells and in segment order within a cell. Segments parallel to the ray (within
    /// 1e-3 radians) are skipped: the 1D kernel's 1/sin has no finite sum there, and they meet
    /// a ray with probability zero.
    pub fn for_each_near_ray(
        &self,
        ray: &Ray,
        medium: u32,
        t_max: f32,
        t_stop: f32,
        mut f: impl FnMut(&BeamSegment, Crossing),
    ) {
        if self.segments.is_empty() {
            return;
        }
        let t_end = t_max.min(t_stop);
        let Some((t0, t1)) = clip_to_box(ray, self.lo, self.hi, t_end) else {
            return;
        };
        let (o, d, r2) = (ray.o, ray.d, self.radius * self.radius);
        march(ray, t0, t1, self.cell, |cell, t_in, t_out, last| {
            for piece in &self.pieces[self.buckets.range(hash_cell(cell, self.mask))] {
                let seg = &self.segments[piece.segment as usize];
                if seg.medium != medium {
                    continue;
                }
                // Nearest points of the two lines: o + t d and origin + s w.
                let w = seg.direction;
                let r0 = o - seg.origin;
                let (cos, dd, e) = (d.dot(w), d.dot(r0), w.dot(r0));
                let sin2 = 1.0 - cos * cos;
                if sin2 < 1e-6 {
                    continue;
                }
                let t = (cos * e - dd) / sin2;
                let s = e + t * cos;
                let owned = t >= t_in && (t < t_out || (last && t <= t_out));
                if !owned || s < piece.s0 || s >= piece.s1 || t < 0.0 {
                    continue;
                }
                if (r0 + d * t - w * s).length_squared() >= r2 {
                    continue;
                }
                f(
                    seg,
                    Crossing {
                        t,
                        s,
                        sin: sin2.sqrt(),
                    },
                );
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Sampler, Stream};

    fn point(s: &mut Sampler, half: f32) -> Vec3A {
        (Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) - 0.5) * (2.0 * half)
    }

    /// The march finds exactly the segments a brute-force test over all of them finds, each
    /// once, with the nearest points.
    #[test]
    fn finds_each_segment_near_the_ray_once() {
        let mut s = Sampler::new(3, Stream::Photon, 0, 0);
        let bounds = Aabb {
            min: Vec3A::splat(-4.0),
            max: Vec3A::splat(4.0),
        };
        let segments: Vec<BeamSegment> = (0..3000)
            .map(|i| {
                let origin = point(&mut s, 3.5);
                BeamSegment {
                    origin,
                    direction: point(&mut s, 1.0).normalize(),
                    // Some run out of the bounds and are cut.
                    length: if i % 10 == 0 {
                        f32::INFINITY
                    } else {
                        3.0 * s.next_1d()
                    },
                    power: Rgb::splat(i as f32),
                    medium: (i % 3 == 0) as u32,
                }
            })
            .collect();
        let radius = 0.05;
        let mut map = PhotonBeamMap::new();
        map.build(&segments, radius, &bounds);
        let mut found_total = 0;
        for q in 0..300 {
            let o = point(&mut s, 4.5);
            let ray = Ray::new(o, point(&mut s, 1.0).normalize());
            let t_max = if q % 7 == 0 {
                f32::INFINITY
            } else {
                6.0 * s.next_1d()
            };
            let t_stop = if q % 5 == 0 { t_max * 0.5 } else { f32::INFINITY };
            let mut found = Vec::new();
            map.for_each_near_ray(&ray, 0, t_max, t_stop, |seg, c| {
                found.push((seg.power.x as usize, c))
            });
            let mut expect = Vec::new();
            for (i, seg) in segments.iter().enumerate() {
                if seg.medium != 0 {
                    continue;
                }
                let len = map
                    .segments
                    .iter()
                    .find(|m| m.power.x as usize == i)
                    .map(|m| m.length);
                let Some(len) = len else { continue };
                // Brute force: the nearest points by dense sampling of the segment.
                let n = 4000;
                let mut best = (f32::INFINITY, 0.0, 0.0);
                for k in 0..=n {
                    let sb = len * k as f32 / n as f32;
                    let p = seg.origin + seg.direction * sb;
                    let t = (p - ray.o).dot(ray.d);
                    let dist = (ray.o + ray.d * t - p).length();
                    if dist < best.0 {
                        best = (dist, t, sb);
                    }
                }
                let (dist, t, sb) = best;
                let interior = sb > 1e-3 && sb < len - 1e-3;
                if interior && t > 0.0 && t < t_max.min(t_stop) && dist < radius {
                    expect.push(i);
                }
            }
            let mut ids: Vec<usize> = found.iter().map(|f| f.0).collect();
            ids.sort();
            let before = ids.len();
            ids.dedup();
            assert_eq!(before, ids.len(), "a segment counted twice");
            for i in &expect {
                assert!(
                    ids.contains(i),
                    "ray {q}: segment {i} missed ({ids:?} vs {expect:?})"
                );
            }
            // Found ones the brute force did not expect are at a segment's end or the radius.
            assert!(ids.len() <= expect.len() + 1, "ray {q}: {ids:?} vs {expect:?}");
            found_total += ids.len();
        }
        assert!(found_total > 100, "{found_total}");
    }
}
