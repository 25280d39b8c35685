//! Spatial splits for the BVH build (Stich, Friedrich and Dietrich, "Spatial Splits in Bounding
//! Volume Hierarchies", 2009): a node may cut space with a plane and put a primitive that
//! straddles it on both sides, each side bounding only its part.
//!
//! Why: the staircase's long thin triangles (stair stringers, banisters, floor boards) have
//! boxes much larger than themselves, so object splits leave children that overlap and a ray
//! visits both. Splitting the references rather than the set keeps the children apart. A
//! primitive then sits in several leaves, each holding its own copy (`Bvh::distinct` names
//! each primitive once).

use glam::{BVec3A, Vec3A};

use super::{Aabb, Primitive, Triangle};
use crate::geometry::bvh::BuildItem;

/// Slabs a node is cut into on each axis (8 traced the staircase's rays 10% slower for 0.2 s
/// less load: docs/engine.md).
const BINS: usize = 16;

/// Overlap of an object split's children, as a fraction of the root's surface area, above
/// which a spatial split is tried (the paper's α: 1e-5 keeps the search to the few nodes where
/// it can pay and the references to a modest growth).
pub(super) const MIN_OVERLAP: f32 = 1e-5;

/// The cheapest spatial split of a node: a plane on `axis`, its SAH cost (unnormalised, as
/// [`super::bvh`]'s object split's), and the two sides' boxes and reference counts as the
/// bins found them.
#[derive(Clone, Copy, Debug)]
pub(super) struct SpatialSplit {
    pub cost: f32,
    axis: usize,
    plane: f32,
    left: Aabb,
    right: Aabb,
    n_left: usize,
    n_right: usize,
}

/// Where a triangle's edges cross the plane `plane` on `axis`: the box of the crossings, and
/// the largest coordinates of the crossed edges' ends, which bound a crossing's rounding.
/// (Empty and zero where none crosses.) A node's search computes each plane's once for the
/// two slabs beside it.
#[derive(Clone, Copy)]
struct Crossings {
    points: Aabb,
    ends: Vec3A,
}

impl Crossings {
    const NONE: Crossings = Crossings {
        points: Aabb::EMPTY,
        ends: Vec3A::ZERO,
    };

    fn new(tri: &Triangle, axis: usize, plane: f32) -> Crossings {
        let mut c = Crossings::NONE;
        for i in 0..3 {
            let (a, e) = (tri.p[i], tri.p[(i + 1) % 3]);
            let (ka, ke) = (a[axis], e[axis]);
            if (ka < plane && ke > plane) || (ka > plane && ke < plane) {
                let q = a + (e - a) * ((plane - ka) / (ke - ka));
                // On the plane exactly. (A select, not `q[axis] = plane`: writing one lane
                // through memory stalled the next read of `q` on a failed store forward, a
                // fifth of the search's time.)
                c.points = c.points.grow(Vec3A::select(on(axis), Vec3A::splat(plane), q));
                c.ends = c.ends.max(a.abs()).max(e.abs());
            }
        }
        c
    }
}

/// The box of the part of `prim` that lies in `slab` (`lo..=hi` on `axis`) and in `within` (the
/// reference's box so far). Triangles are clipped exactly (the box of the triangle's vertices
/// inside the slab and its edges' crossings of the slab's planes); other primitives keep their
/// box cut to the slab, which is conservative.
fn clip(prim: &Primitive, within: Aabb, axis: usize, lo: f32, hi: f32) -> Aabb {
    match prim {
        Primitive::Triangle(tri) => clip_between(
            tri,
            within,
            axis,
            (lo, Crossings::new(tri, axis, lo)),
            (hi, Crossings::new(tri, axis, hi)),
        ),
        _ => slab(within, axis, lo, hi),
    }
}

/// `within` cut to `lo..=hi` on `axis`.
fn slab(within: Aabb, axis: usize, lo: f32, hi: f32) -> Aabb {
    Aabb {
        min: Vec3A::select(on(axis), within.min.max(Vec3A::splat(lo)), within.min),
        max: Vec3A::select(on(axis), within.max.min(Vec3A::splat(hi)), within.max),
    }
}

/// The lane of `axis`.
#[inline(always)]
fn on(axis: usize) -> BVec3A {
    BVec3A::new(axis == 0, axis == 1, axis == 2)
}

/// [`clip`] for a triangle, given its crossings of the slab's two planes.
fn clip_between(
    tri: &Triangle,
    within: Aabb,
    axis: usize,
    lo: (f32, Crossings),
    hi: (f32, Crossings),
) -> Aabb {
    let slab = slab(within, axis, lo.0, hi.0);
    let mut b = lo.1.points.union(hi.1.points);
    for a in tri.p {
        if (lo.0..=hi.0).contains(&a[axis]) {
            b = b.grow(a);
        }
    }
    if b.is_empty() {
        return Aabb::EMPTY;
    }
    let ends = lo.1.ends.max(hi.1.ends);
    // A crossing `a + (c - a) t` is off by some ulps of the edge's larger end (far more than an
    // ulp of the crossing itself when that end is far away): widen by 16 of those, so that the
    // two sides' boxes still cover every point of the triangle, then keep within the
    // reference's box and the slab (whose faces are exact).
    let pad = (b.max - b.min).max(b.max.abs().max(b.min.abs())).max(ends) * 16.0 * f32::EPSILON;
    let padded = Aabb {
        min: (b.min - pad).max(slab.min),
        max: (b.max + pad).min(slab.max),
    };
    if padded.is_empty() { Aabb::EMPTY } else { padded }
}

/// The node's bins on `axis`: the position of plane `i` (0..=BINS), and the bin of a coordinate.
struct Planes {
    lo: f32,
    width: f32,
}

impl Planes {
    fn plane(&self, i: usize) -> f32 {
        if i == BINS {
            self.lo + self.width
        } else {
            self.lo + self.width * (i as f32 / BINS as f32)
        }
    }

    fn bin(&self, x: f32) -> usize {
        (((x - self.lo) / self.width * BINS as f32).max(0.0) as usize).min(BINS - 1)
    }
}

/// The cheapest spatial split of `items` (inside `bounds`) over the three axes, if any plane
/// has references on both sides.
pub(super) fn find(items: &[BuildItem], prims: &[Primitive], bounds: Aabb) -> Option<SpatialSplit> {
    let mut best: Option<SpatialSplit> = None;
    for axis in 0..3 {
        let planes = Planes {
            lo: bounds.min[axis],
            width: bounds.max[axis] - bounds.min[axis],
        };
        if !(planes.width > 0.0 && planes.width.is_finite()) {
            continue;
        }
        let mut boxes = [Aabb::EMPTY; BINS];
        let mut entries = [0usize; BINS];
        let mut exits = [0usize; BINS];
        for it in items {
            let (first, last) = (planes.bin(it.bounds.min[axis]), planes.bin(it.bounds.max[axis]));
            entries[first] += 1;
            exits[last] += 1;
            if first == last {
                boxes[first] = boxes[first].union(it.bounds);
                continue;
            }
            let Primitive::Triangle(tri) = &prims[it.index] else {
                for (b, bin) in boxes.iter_mut().enumerate().take(last + 1).skip(first) {
                    *bin = bin.union(slab(it.bounds, axis, planes.plane(b), planes.plane(b + 1)));
                }
                continue;
            };
            // Each plane's crossings once, for the slabs on both its sides.
            let at = |b: usize| {
                let plane = planes.plane(b);
                (plane, Crossings::new(tri, axis, plane))
            };
            let mut lo = at(first);
            for (b, bin) in boxes.iter_mut().enumerate().take(last + 1).skip(first) {
                let hi = at(b + 1);
                *bin = bin.union(clip_between(tri, it.bounds, axis, lo, hi));
                lo = hi;
            }
        }
        let mut right_box = [Aabb::EMPTY; BINS];
        let mut right_count = [0usize; BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in (1..BINS).rev() {
            acc = acc.union(boxes[i]);
            n += exits[i];
            right_box[i] = acc;
            right_count[i] = n;
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in 0..BINS - 1 {
            acc = acc.union(boxes[i]);
            n += entries[i];
            let n_right = right_count[i + 1];
            if n == 0 || n_right == 0 {
                continue;
            }
            let cost = n as f32 * acc.surface_area() + n_right as f32 * right_box[i + 1].surface_area();
            // (A NaN or infinite cost, from infinite coordinates, never wins.)
            if cost.is_finite() && best.is_none_or(|b| cost < b.cost) {
                best = Some(SpatialSplit {
                    cost,
                    axis,
                    plane: planes.plane(i + 1),
                    left: acc,
                    right: right_box[i + 1],
                    n_left: n,
                    n_right,
                });
            }
        }
    }
    best
}

impl SpatialSplit {
    /// How many references the split adds at most (those that straddle its plane).
    pub fn duplicates(&self, items: usize) -> usize {
        (self.n_left + self.n_right).saturating_sub(items)
    }

    /// The two sides' references, a straddling one on both (each with its part's box) unless
    /// putting it whole on one side is cheaper ("reference unsplitting"). None if a side would
    /// be empty (the bins' rounding can disagree with the plane's).
    pub fn partition(
        &self,
        items: &[BuildItem],
        prims: &[Primitive],
    ) -> Option<(Vec<BuildItem>, Vec<BuildItem>)> {
        let (axis, plane) = (self.axis, self.plane);
        let (area_l, area_r) = (self.left.surface_area(), self.right.surface_area());
        let (n_l, n_r) = (self.n_left as f32, self.n_right as f32);
        let split_cost = area_l * n_l + area_r * n_r;
        let (mut left, mut right) = (Vec::new(), Vec::new());
        for it in items {
            if it.bounds.max[axis] <= plane {
                left.push(*it);
                continue;
            }
            if it.bounds.min[axis] >= plane {
                right.push(*it);
                continue;
            }
            let whole_left = self.left.union(it.bounds).surface_area() * n_l + area_r * (n_r - 1.0);
            let whole_right = area_l * (n_l - 1.0) + self.right.union(it.bounds).surface_area() * n_r;
            if whole_left < split_cost && whole_left <= whole_right {
                left.push(*it);
                continue;
            }
            if whole_right < split_cost {
                right.push(*it);
                continue;
            }
            let prim = &prims[it.index];
            let l = clip(prim, it.bounds, axis, f32::NEG_INFINITY, plane);
            let r = clip(prim, it.bounds, axis, plane, f32::INFINITY);
            match (l.is_empty(), r.is_empty()) {
                (false, false) => {
                    left.push(it.with_bounds(l));
                    right.push(it.with_bounds(r));
                }
                (false, true) => left.push(it.with_bounds(l)),
                (true, false) => right.push(it.with_bounds(r)),
                // Degenerate (no area on either side once rounded): keep it whole.
                (true, true) => left.push(*it),
            }
        }
        (!left.is_empty() && !right.is_empty()).then_some((left, right))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Triangle;
    use crate::sampling::{Sampler, Stream};

    fn tri(p: [Vec3A; 3]) -> Primitive {
        Primitive::Triangle(Triangle::bare(p))
    }

    #[test]
    fn a_clipped_triangle_bounds_only_its_part() {
        // A sliver along the diagonal of the unit square: its box is the whole square, the
        // part left of x = 0.25 only the square's lower-left corner.
        let t = tri([Vec3A::ZERO, Vec3A::new(1.0, 1.0, 0.0), Vec3A::new(1.0, 0.99, 0.0)]);
        let b = clip(&t, t.bounds(), 0, f32::NEG_INFINITY, 0.25);
        assert_eq!(b.min.x, 0.0);
        assert_eq!(b.max.x, 0.25);
        assert!(b.max.y > 0.2475 && b.max.y < 0.2501, "{b:?}");
        // Both parts together hold every vertex and crossing.
        let r = clip(&t, t.bounds(), 0, 0.25, f32::INFINITY);
        assert_eq!(b.union(r), t.bounds());
        // A slab the triangle does not reach holds nothing of it.
        let far = clip(&t, t.bounds(), 1, 2.0, 3.0);
        assert!(far.is_empty());
    }

    #[test]
    fn the_two_sides_cover_a_triangle_with_a_far_vertex() {
        // A long triangle reaching far from a plane near the origin: its crossings are rounded
        // by ulps of the far vertex, far more than of themselves (the reviewer's case missed
        // points at x = 0.500005 with ulps of the crossing only).
        let mut s = Sampler::new(9, Stream::Camera, 0, 0);
        let mut u = || s.next_1d();
        for case in 0..200 {
            let far = libm::powf(10.0, 1.0 + 3.0 * u());
            let t = tri([
                Vec3A::new(-far * (0.5 + u()), -far * u(), u() - 0.5),
                Vec3A::new(0.5 + u(), u(), u()),
                Vec3A::new(0.5 + u(), u(), u()),
            ]);
            let Primitive::Triangle(p) = &t else {
                unreachable!()
            };
            let plane = 0.5;
            let l = clip(&t, t.bounds(), 0, f32::NEG_INFINITY, plane);
            let r = clip(&t, t.bounds(), 0, plane, f32::INFINITY);
            let inside = |b: &Aabb, q: Vec3A| q.cmpge(b.min).all() && q.cmple(b.max).all();
            let v = p.p.map(|v| [v.x as f64, v.y as f64, v.z as f64]);
            for _ in 0..200 {
                // A point of the triangle's cross-section at x near the plane, in f64.
                let x = plane as f64 + (u() as f64 - 0.5) * 1e-3;
                let cuts: Vec<[f64; 3]> = (0..3)
                    .filter_map(|i| {
                        let (a, c) = (v[i], v[(i + 1) % 3]);
                        let t = (x - a[0]) / (c[0] - a[0]);
                        (0.0..=1.0)
                            .contains(&t)
                            .then(|| std::array::from_fn(|k| a[k] + (c[k] - a[k]) * t))
                    })
                    .collect();
                let w = u() as f64;
                let q = Vec3A::from_array(std::array::from_fn(|k| {
                    (cuts[0][k] * (1.0 - w) + cuts[cuts.len() - 1][k] * w) as f32
                }));
                assert!(
                    inside(&l, q) || inside(&r, q),
                    "case {case}: {q} in neither {l:?} nor {r:?}"
                );
            }
        }
    }
}
