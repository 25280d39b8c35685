//! A leaf's triangles (up to four) in SIMD lanes, tested against one ray in one pass.
//!
//! Why: on the Cornell box the triangle tests were 45% of a bounce ray's traversal. Each test
//! loaded an 80-byte [`Primitive`], branched on its kind and summed every dot product across
//! one register. Here a leaf of triangles keeps its vertices and edges in structure-of-arrays
//! lanes, so the four tests are the work of one and each dot product is two vertical adds.
//!
//! Every lane does [`Triangle::intersect`]'s arithmetic, operation for operation (the edges are
//! the same differences, taken once at the build), so it gives that test's bits. The nearest
//! lane, the first of equals, is then the hit the scalar loop over the leaf finds, which keeps
//! closest hits, and so images, as they were.

use arrayvec::ArrayVec;
use glam::{Vec3A, Vec4};

use super::{PrimHit, Primitive, Ray, Triangle};

/// A leaf child whose count has this bit set holds triangles only, packed in the [`Tri4`]
/// that its `child` indexes; the count's other bits are how many.
pub(super) const PACKED: u16 = 1 << 15;

/// Up to four triangles as origins and edges in lanes; empty lanes are degenerate (zero
/// edges), which the determinant test rejects.
#[derive(Clone, Debug)]
pub(super) struct Tri4 {
    p0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    /// The leaf's first primitive slot: lane i holds slot `first + i`.
    first: u32,
}

/// One of a leaf's primitives, as the packet test reads it.
pub(super) enum LeafPrim<'a> {
    /// A triangle as its first vertex and two edges (`p1 - p0`, `p2 - p0`).
    Triangle([Vec3A; 3]),
    /// Anything else, tested one ray at a time.
    Other(&'a Primitive),
}

impl Tri4 {
    /// Packs the triangles of slots `first..first + tris.len()` (at most four).
    pub(super) fn new(first: u32, tris: &[&Triangle]) -> Tri4 {
        debug_assert!(tris.len() <= 4);
        let mut lanes = [[[0.0f32; 4]; 3]; 3];
        for (lane, tri) in tris.iter().enumerate() {
            let [p0, p1, p2] = tri.p;
            for (k, v) in [p0, p1 - p0, p2 - p0].into_iter().enumerate() {
                for axis in 0..3 {
                    lanes[k][axis][lane] = v[axis];
                }
            }
        }
        let v = |k: usize| lanes[k].map(Vec4::from_array);
        Tri4 {
            p0: v(0),
            e1: v(1),
            e2: v(2),
            first,
        }
    }

    /// The nearest of the four hits in (0, t_max): its slot and (t, b1, b2).
    #[inline(always)]
    pub(super) fn intersect(&self, ray: &Ray, t_max: f32) -> Option<(u32, PrimHit)> {
        let (zero, one) = (Vec4::ZERO, Vec4::ONE);
        let [dx, dy, dz] = [ray.d.x, ray.d.y, ray.d.z].map(Vec4::splat);
        let [p0x, p0y, p0z] = self.p0;
        let [e1x, e1y, e1z] = self.e1;
        let [e2x, e2y, e2z] = self.e2;
        // pv = d × e2, det = e1 · pv, as glam's cross and dot order them.
        let pvx = dy * e2z - dz * e2y;
        let pvy = dz * e2x - dx * e2z;
        let pvz = dx * e2y - dy * e2x;
        let det = e1x * pvx + e1y * pvy + e1z * pvz;
        let inv = one / det;
        let tvx = Vec4::splat(ray.o.x) - p0x;
        let tvy = Vec4::splat(ray.o.y) - p0y;
        let tvz = Vec4::splat(ray.o.z) - p0z;
        let b1 = (tvx * pvx + tvy * pvy + tvz * pvz) * inv;
        // qv = tv × e1.
        let qvx = tvy * e1z - tvz * e1y;
        let qvy = tvz * e1x - tvx * e1z;
        let qvz = tvx * e1y - tvy * e1x;
        let b2 = (dx * qvx + dy * qvy + dz * qvz) * inv;
        let t = (e2x * qvx + e2y * qvy + e2z * qvz) * inv;
        let det_ok = det.cmpne(zero) & det.abs().cmplt(Vec4::INFINITY);
        // As the scalar test, a NaN b2 passes its two comparisons.
        let inside = b1.cmpge(zero) & b1.cmple(one) & !b2.cmplt(zero) & !(b1 + b2).cmpgt(one);
        let hit = det_ok & inside & t.cmpgt(zero) & t.cmplt(Vec4::splat(t_max));
        let mut lanes = hit.bitmask();
        if lanes == 0 {
            return None;
        }
        let mut best = lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        while lanes != 0 {
            let lane = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if t[lane] < t[best] {
                best = lane;
            }
        }
        Some((
            self.first + best as u32,
            PrimHit {
                t: t[best],
                b1: b1[best],
                b2: b2[best],
                inner: 0,
            },
        ))
    }

    /// Lane `lane`'s triangle as its first vertex and two edges.
    #[inline(always)]
    fn triangle(&self, lane: usize) -> [Vec3A; 3] {
        let [p, e, f] = [&self.p0, &self.e1, &self.e2];
        [
            Vec3A::new(p[0][lane], p[1][lane], p[2][lane]),
            Vec3A::new(e[0][lane], e[1][lane], e[2][lane]),
            Vec3A::new(f[0][lane], f[1][lane], f[2][lane]),
        ]
    }
}

/// The leaf of slots `first..first + count` packed onto `packs`, with its pack's index, if it
/// holds at most four primitives, all triangles (other leaves stay as slots).
pub(super) fn pack(prims: &[Primitive], first: u32, count: u16, packs: &mut Vec<Tri4>) -> Option<u32> {
    let slots = &prims[first as usize..][..count as usize];
    let tris: ArrayVec<&Triangle, 4> = slots
        .iter()
        .take(4)
        .map_while(|p| match p {
            Primitive::Triangle(t) => Some(t),
            _ => None,
        })
        .collect();
    if tris.len() < slots.len() {
        return None;
    }
    packs.push(Tri4::new(first, &tris));
    Some(packs.len() as u32 - 1)
}

/// A leaf child's primitives with their slots, packed or not, as an iterator whose `next` is
/// inlined into the packet traversal (a closure's body would be compiled on its own, without
/// the backend's instruction set: it cost camera packets 30%).
pub(super) struct Leaf<'a> {
    pack: Option<&'a Tri4>,
    prims: &'a [Primitive],
    child: u32,
    next: u32,
    count: u32,
}

impl<'a> Leaf<'a> {
    /// Leaf child (child, count) of a wide node.
    #[inline(always)]
    pub(super) fn new(packs: &'a [Tri4], prims: &'a [Primitive], child: u32, count: u32) -> Leaf<'a> {
        let packed = count & PACKED as u32 != 0;
        Leaf {
            pack: packed.then(|| &packs[child as usize]),
            prims,
            child,
            next: 0,
            count: count & !(PACKED as u32),
        }
    }
}

impl<'a> Iterator for Leaf<'a> {
    type Item = (u32, LeafPrim<'a>);

    #[inline(always)]
    fn next(&mut self) -> Option<Self::Item> {
        if self.next == self.count {
            return None;
        }
        let i = self.next;
        self.next += 1;
        Some(match self.pack {
            Some(p) => (p.first + i, LeafPrim::Triangle(p.triangle(i as usize))),
            None => {
                let slot = self.child + i;
                let prim = match &self.prims[slot as usize] {
                    Primitive::Triangle(t) => LeafPrim::Triangle([t.p[0], t.p[1] - t.p[0], t.p[2] - t.p[0]]),
                    other => LeafPrim::Other(other),
                };
                (slot, prim)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Sampler, Stream};

    /// Four triangles round a point, rays at them from all sides, some through shared edges
    /// and vertices (where two lanes tie): each pack's hit is the scalar loop's, bit for bit.
    #[test]
    fn a_pack_finds_the_scalar_loops_hit_bit_for_bit() {
        let mut hits = 0;
        for case in 0..4000 {
            let mut s = Sampler::new(7, Stream::Camera, case as u64, 0);
            let mut r = || 2.0 * s.next_1d() - 1.0;
            let c = Vec3A::new(r(), r(), r());
            let shared = c + Vec3A::new(r(), r(), r());
            let tris: Vec<Triangle> = (0..1 + case % 4)
                .map(|_| {
                    Triangle::bare([
                        shared,
                        c + Vec3A::new(r(), r(), r()),
                        c + Vec3A::new(r(), r(), r()),
                    ])
                })
                .collect();
            let refs: Vec<&Triangle> = tris.iter().collect();
            let pack = Tri4::new(10, &refs);
            let o = Vec3A::new(r(), r(), r()) * 4.0;
            let aim = if case % 3 == 0 { shared } else { c };
            let ray = Ray::new(o, aim - o + Vec3A::new(r(), r(), r()) * 0.1 * (case % 2) as f32);
            let t_max = if case % 5 == 0 { 1.0 } else { f32::INFINITY };
            let mut scalar = None;
            let mut t = t_max;
            for (i, tri) in tris.iter().enumerate() {
                if let Some((d, b1, b2)) = tri.intersect(&ray, t) {
                    t = d;
                    scalar = Some((10 + i as u32, d.to_bits(), b1.to_bits(), b2.to_bits()));
                }
            }
            let packed = pack
                .intersect(&ray, t_max)
                .map(|(slot, h)| (slot, h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits()));
            assert_eq!(packed, scalar, "case {case}");
            hits += scalar.is_some() as u32;
        }
        assert!(hits > 1000, "{hits} hits: the rays must mostly hit");
    }
}
