//! Eight rays at once through the four-wide BVH (a packet, one ray per lane), for the lane
//! engine: each child box and each triangle is tested against all eight rays in lanes, with
//! the scalar traversal's arithmetic (`bvh4::traverse`, `Triangle::intersect`), so that a
//! lane finds the hit the scalar traversal finds for its ray.
//!
//! The packet visits the union of its rays' nodes: cheap where rays are coherent (camera rays,
//! shadow rays to one light) and on small trees, wasteful for incoherent rays in big ones
//! (docs/engine.md has the figures).

use arrayvec::ArrayVec;

use super::bvh4::{WIDE_STACK, WideNode};
use super::tri4::{Leaf, LeafPrim, Tri4};
use super::{Hit, Primitive, Ray, gamma};
use crate::engine::lanes::{F8, LANES, M8, V8};

/// Rays in lanes: origins, directions and the end of each ray's interval.
#[derive(Clone, Copy, Debug)]
pub struct Rays8 {
    /// Origins.
    pub o: V8,
    /// Directions (any length: t is in units of it).
    pub d: V8,
    /// Hits count in (0, t_max).
    pub t_max: F8,
    /// Lanes that hold a ray.
    pub active: M8,
}

/// Closest hits of a packet: per lane, as [`super::Hit`] holds them where `found`.
#[derive(Clone, Copy, Debug)]
pub struct Hits8 {
    /// Lanes whose ray hit something.
    pub found: M8,
    /// Distances.
    pub t: F8,
    /// Barycentric coordinates.
    pub b1: F8,
    /// Second barycentric coordinate.
    pub b2: F8,
    /// Primitives, in BVH order.
    pub prim: [u32; LANES],
    /// For instances, the group's primitive.
    pub inner: [u32; LANES],
}

impl Rays8 {
    /// Lane `lane`'s ray.
    pub fn ray(&self, lane: usize) -> Ray {
        Ray::new(self.o.lane(lane).into(), self.d.lane(lane).into())
    }
}

impl Hits8 {
    /// No lane hit.
    pub fn none() -> Hits8 {
        Hits8 {
            found: M8::splat(false),
            t: F8::splat(0.0),
            b1: F8::splat(0.0),
            b2: F8::splat(0.0),
            prim: [0; LANES],
            inner: [0; LANES],
        }
    }

    /// Lane `lane` hit `h`.
    pub fn record(&mut self, lane: usize, h: &Hit) {
        self.found.set(lane, true);
        self.t.0[lane] = h.t;
        self.b1.0[lane] = h.b1;
        self.b2.0[lane] = h.b2;
        self.prim[lane] = h.prim;
        self.inner[lane] = h.inner;
    }

    /// Lane `lane`'s hit, if it found one.
    pub fn hit(&self, lane: usize) -> Option<Hit> {
        self.found.get(lane).then(|| Hit {
            t: self.t.0[lane],
            prim: self.prim[lane],
            b1: self.b1.0[lane],
            b2: self.b2.0[lane],
            inner: self.inner[lane],
        })
    }
}

/// A child to visit: its box's entry distance per lane and the lanes that enter it.
#[derive(Clone, Copy)]
struct Entry {
    near: F8,
    mask: M8,
    child: u32,
    count: u16,
}

/// What a traversal looks for, tested leaf by leaf. A trait, not a closure: closures cannot be
/// marked `#[inline(always)]`, and one compiled on its own lacks the backend's instruction set
/// (it cost the packet traversal a third of its speed).
trait Query {
    /// Whether children are visited front to back (closest hits need it).
    const NEAREST_FIRST: bool;

    /// Tests a leaf's primitives (as [`Leaf`] lists them) against the lanes of `mask`,
    /// shrinking `t_max` to their hits; returns the lanes that are done (blocked shadow rays).
    fn leaf<'a>(
        &mut self,
        prims: impl Iterator<Item = (u32, LeafPrim<'a>)>,
        rays: &Rays8,
        mask: M8,
        t_max: &mut F8,
    ) -> M8;
}

/// The closest hit of each lane.
struct Closest(Hits8);

impl Query for Closest {
    const NEAREST_FIRST: bool = true;

    #[inline(always)]
    fn leaf<'a>(
        &mut self,
        prims: impl Iterator<Item = (u32, LeafPrim<'a>)>,
        rays: &Rays8,
        mask: M8,
        t_max: &mut F8,
    ) -> M8 {
        let hits = &mut self.0;
        for (i, prim) in prims {
            match prim {
                LeafPrim::Triangle(tri) => {
                    let (hit, t, b1, b2) = triangle(tri, rays, mask, *t_max);
                    hits.found = hits.found | hit;
                    hits.t = hit.select(t, hits.t);
                    hits.b1 = hit.select(b1, hits.b1);
                    hits.b2 = hit.select(b2, hits.b2);
                    for lane in 0..LANES {
                        if hit.get(lane) {
                            hits.prim[lane] = i;
                            hits.inner[lane] = 0;
                        }
                    }
                }
                LeafPrim::Other(other) => {
                    scalar_lanes(other, rays, mask, *t_max, |lane, h| {
                        let h = Hit {
                            t: h.t,
                            prim: i,
                            b1: h.b1,
                            b2: h.b2,
                            inner: h.inner,
                        };
                        hits.record(lane, &h);
                    });
                }
            }
            *t_max = hits.found.select(hits.t, *t_max);
        }
        M8::splat(false)
    }
}

/// Whether anything blocks each lane.
struct Occlusion(M8);

impl Query for Occlusion {
    const NEAREST_FIRST: bool = false;

    #[inline(always)]
    fn leaf<'a>(
        &mut self,
        prims: impl Iterator<Item = (u32, LeafPrim<'a>)>,
        rays: &Rays8,
        mut mask: M8,
        t_max: &mut F8,
    ) -> M8 {
        for (_, prim) in prims {
            let hit = match prim {
                LeafPrim::Triangle(tri) => triangle(tri, rays, mask, *t_max).0,
                LeafPrim::Other(other) => scalar_lanes(other, rays, mask, *t_max, |_, _| {}),
            };
            self.0 = self.0 | hit;
            mask = mask & !hit;
            if !mask.any() {
                break;
            }
        }
        self.0
    }
}

/// Closest hits of `rays` in `nodes` over `prims`.
#[inline(always)]
pub(super) fn closest(nodes: &[WideNode], packs: &[Tri4], prims: &[Primitive], rays: &Rays8) -> Hits8 {
    let mut q = Closest(Hits8::none());
    traverse(nodes, packs, prims, rays, &mut q);
    q.0
}

/// Lanes of `rays` that something blocks.
#[inline(always)]
pub(super) fn occluded(nodes: &[WideNode], packs: &[Tri4], prims: &[Primitive], rays: &Rays8) -> M8 {
    let mut q = Occlusion(M8::splat(false));
    traverse(nodes, packs, prims, rays, &mut q);
    q.0
}

/// `Primitive::intersect` for each lane in `mask`, one ray at a time (spheres and instances).
#[inline(always)]
fn scalar_lanes(
    prim: &Primitive,
    rays: &Rays8,
    mask: M8,
    t_max: F8,
    mut record: impl FnMut(usize, super::PrimHit),
) -> M8 {
    let mut hit = M8::splat(false);
    for lane in 0..LANES {
        if mask.get(lane)
            && let Some(h) = prim.intersect(&rays.ray(lane), t_max.0[lane])
        {
            hit.set(lane, true);
            record(lane, h);
        }
    }
    hit
}

/// `Triangle::intersect` (Möller–Trumbore) in lanes, operation for operation, on a triangle
/// as its first vertex and two edges: the lanes of `mask` it hits in (0, t_max), with their
/// (t, b1, b2).
#[inline(always)]
fn triangle(tri: [glam::Vec3A; 3], rays: &Rays8, mask: M8, t_max: F8) -> (M8, F8, F8, F8) {
    let zero = F8::splat(0.0);
    let (p0, e1, e2) = (
        V8::splat(tri[0].into()),
        V8::splat(tri[1].into()),
        V8::splat(tri[2].into()),
    );
    let pv = rays.d.cross(e2);
    let det = e1.dot(pv);
    let inv = 1.0 / det;
    let tv = rays.o - p0;
    let b1 = tv.dot(pv) * inv;
    let qv = tv.cross(e1);
    let b2 = rays.d.dot(qv) * inv;
    let t = e2.dot(qv) * inv;
    let det_ok = !det.eq(zero) & det.abs().lt(F8::splat(f32::INFINITY));
    // As the scalar test, a NaN b2 passes its two comparisons.
    let inside = b1.ge(zero) & b1.le(F8::splat(1.0)) & !b2.lt(zero) & !(b1 + b2).gt(F8::splat(1.0));
    let hit = mask & det_ok & inside & t.gt(zero) & t.lt(t_max);
    (hit, t, b1, b2)
}

/// The packet traversal for query `q`; lanes it reports done leave the packet. Children are
/// visited by their nearest lane's entry, front to back, if the query needs it.
#[inline(always)]
fn traverse<Q: Query>(nodes: &[WideNode], packs: &[Tri4], prims: &[Primitive], rays: &Rays8, q: &mut Q) {
    let mut t_max = rays.t_max;
    let t_max = &mut t_max;
    let zero = F8::splat(0.0);
    let inv_d = V8 {
        x: 1.0 / rays.d.x,
        y: 1.0 / rays.d.y,
        z: 1.0 / rays.d.z,
    };
    let widen = F8::splat(1.0 + 2.0 * gamma(3));
    let mut done = !rays.active;
    let mut stack = ArrayVec::<Entry, WIDE_STACK>::new();
    let mut cur = Entry {
        near: zero,
        mask: rays.active,
        child: 0,
        count: 0,
    };
    loop {
        if cur.count > 0 {
            let leaf = Leaf::new(packs, prims, cur.child, cur.count as u32);
            done = done | q.leaf(leaf, rays, cur.mask, t_max);
            if !(!done).any() {
                return;
            }
        } else {
            let n = &nodes[cur.child as usize];
            let base = stack.len();
            for c in 0..4 {
                if n.used & (1 << c) == 0 {
                    continue;
                }
                let b = n.child_bounds(c);
                let slab =
                    |lo: f32, hi: f32, o: F8, inv: F8| ((F8::splat(lo) - o) * inv, (F8::splat(hi) - o) * inv);
                let (tx0, tx1) = slab(b[0][0], b[1][0], rays.o.x, inv_d.x);
                let (ty0, ty1) = slab(b[0][1], b[1][1], rays.o.y, inv_d.y);
                let (tz0, tz1) = slab(b[0][2], b[1][2], rays.o.z, inv_d.z);
                let near = tx0.min(tx1).max(ty0.min(ty1)).max(tz0.min(tz1)).max(zero);
                let far = tx0.max(tx1).min(ty0.max(ty1)).min(tz0.max(tz1)) * widen;
                let mask = cur.mask & !done & near.le(far.min(*t_max));
                if !mask.any() {
                    continue;
                }
                let (child, count) = n.child(c);
                stack.push(Entry {
                    near,
                    mask,
                    child,
                    count,
                });
                // Far to near by the nearest lane's entry, so the nearest child is on top.
                let key = |e: &Entry| e.mask.select(e.near, F8::splat(f32::INFINITY)).reduce_min();
                let mut i = stack.len() - 1;
                while Q::NEAREST_FIRST && i > base && key(&stack[i - 1]) < key(&stack[i]) {
                    stack.swap(i - 1, i);
                    i -= 1;
                }
            }
        }
        // Next: the top entry whose lanes have not all been hit nearer since it was pushed.
        loop {
            let Some(e) = stack.pop() else { return };
            let mask = e.mask & !done & e.near.le(*t_max);
            if mask.any() {
                cur = Entry { mask, ..e };
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use glam::Vec3A;

    use super::*;
    use crate::sampling::{Sampler, Stream};
    use crate::scene::Scene;

    fn scene(name: &str) -> Scene {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/refs")
            .join(name);
        Scene::load(&path, &[("res".to_string(), "16".to_string())]).unwrap()
    }

    /// Packets of rays from points in and around the box: coherent ones (one origin, nearby
    /// directions) and incoherent ones, with some lanes off and some short intervals.
    fn packets(n: u64) -> Vec<Rays8> {
        (0..n)
            .map(|k| {
                let mut s = Sampler::new(3, Stream::Camera, 0, k);
                let mut u = || s.next_1d() * 2.0 - 1.0;
                let coherent = k % 2 == 0;
                let centre = Vec3A::new(u(), u(), u() * 1.5);
                let aim = Vec3A::new(u(), u(), u());
                let rays: [(Vec3A, Vec3A, f32, bool); LANES] = std::array::from_fn(|_| {
                    let (o, d) = if coherent {
                        (centre, aim + 0.05 * Vec3A::new(u(), u(), u()))
                    } else {
                        (Vec3A::new(u(), u(), u() * 1.5), Vec3A::new(u(), u(), u()))
                    };
                    let t_max = if u() > 0.5 { 0.5 + u().abs() } else { f32::INFINITY };
                    (o, d, t_max, u() > -0.8)
                });
                Rays8 {
                    o: V8 {
                        x: F8::from_fn(|i| rays[i].0.x),
                        y: F8::from_fn(|i| rays[i].0.y),
                        z: F8::from_fn(|i| rays[i].0.z),
                    },
                    d: V8 {
                        x: F8::from_fn(|i| rays[i].1.x),
                        y: F8::from_fn(|i| rays[i].1.y),
                        z: F8::from_fn(|i| rays[i].1.z),
                    },
                    t_max: F8::from_fn(|i| rays[i].2),
                    active: M8::from_fn(|i| rays[i].3),
                }
            })
            .collect()
    }

    #[test]
    fn each_lane_finds_the_scalar_traversals_hit() {
        for name in ["cbox.xml", "cbox-spheres.xml"] {
            let scene = scene(name);
            let (mut hits, mut blocked) = (0, 0);
            for rays in packets(4000) {
                let closest = scene.bvh.intersect8(&rays);
                let occluded = scene.bvh.occluded8(&rays);
                for lane in 0..LANES {
                    let ray = rays.ray(lane);
                    let (want, want_blocked) = if rays.active.get(lane) {
                        let t_max = rays.t_max.0[lane];
                        (scene.bvh.intersect(&ray, t_max), scene.bvh.occluded(&ray, t_max))
                    } else {
                        (None, false)
                    };
                    let got = closest.hit(lane);
                    let bits = |h: Option<crate::geometry::Hit>| {
                        h.map(|h| (h.t.to_bits(), h.prim, h.b1.to_bits(), h.b2.to_bits(), h.inner))
                    };
                    assert_eq!(bits(got), bits(want), "{name}: lane {lane} of {rays:?}");
                    assert_eq!(
                        occluded.get(lane),
                        want_blocked,
                        "{name}: lane {lane} of {rays:?}"
                    );
                    hits += usize::from(want.is_some());
                    blocked += usize::from(want_blocked);
                }
            }
            // The test means something only if most rays hit.
            assert!(
                hits > 15_000 && blocked > 15_000,
                "{name}: {hits} hits, {blocked} blocked"
            );
        }
    }
}
