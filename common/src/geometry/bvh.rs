//! A bounding volume hierarchy built with the binned surface area heuristic.

use glam::Vec3A;

use super::{Aabb, Hit, Primitive, Ray};

const BINS: usize = 16;
const MAX_LEAF: usize = 4;
/// Cost of a traversal step relative to one primitive test, for the SAH.
const TRAVERSAL_COST: f32 = 1.0;
/// Depth below which the SAH chooses splits. Deeper, splits are by count (median), which
/// halves the primitives at every level: with at most 2^32 primitives the tree's depth stays
/// below `SAH_DEPTH + 32 = STACK`, so the traversal stack cannot overflow, whatever the
/// geometry (the SAH alone peels one primitive per level off nested sizes in a progression).
const SAH_DEPTH: usize = 32;
/// Traversal stack entries: one per level of the deepest possible tree.
const STACK: usize = SAH_DEPTH + 32;

/// One node of the flattened tree. Interior nodes keep their first child right after them.
#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first primitive. Interior: index of the second child.
    offset: u32,
    /// Leaf: primitive count (> 0). Interior: 0.
    count: u16,
    /// Interior: split axis, which orders the children front to back during traversal.
    axis: u8,
}

/// The scene's acceleration structure; owns the primitives in traversal order.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    prims: Vec<Primitive>,
}

struct BuildItem {
    bounds: Aabb,
    centroid: Vec3A,
    index: usize,
}

impl Bvh {
    /// Builds the tree; primitives are reordered so that each leaf's are contiguous.
    pub fn build(prims: Vec<Primitive>) -> Bvh {
        let mut items: Vec<BuildItem> = prims
            .iter()
            .enumerate()
            .map(|(index, p)| {
                let bounds = p.bounds();
                BuildItem {
                    bounds,
                    centroid: bounds.center(),
                    index,
                }
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * prims.len().max(1));
        if !items.is_empty() {
            build_node(&mut items, 0, 0, &mut nodes);
        }
        let mut slots: Vec<Option<Primitive>> = prims.into_iter().map(Some).collect();
        let prims = items
            .iter()
            .map(|it| slots[it.index].take().expect("each primitive is placed once"))
            .collect();
        Bvh { nodes, prims }
    }

    /// Primitives in BVH order; [`Hit::prim`] indexes this.
    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }

    /// Bounds of everything.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map(|n| n.bounds).unwrap_or(Aabb::EMPTY)
    }

    /// Closest hit in (0, t_max).
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_max = t_max;
        self.traverse(ray, &mut t_max, |prim, t, b1, b2| {
            best = Some(Hit { t, prim, b1, b2 });
            false
        });
        best
    }

    /// Whether anything lies in (0, t_max): shadow rays stop at the first hit.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        let mut found = false;
        let mut t_max = t_max;
        self.traverse(ray, &mut t_max, |_, _, _, _| {
            found = true;
            true
        });
        found
    }

    /// Front-to-back traversal; `on_hit` returns true to stop.
    #[inline]
    fn traverse(&self, ray: &Ray, t_max: &mut f32, mut on_hit: impl FnMut(u32, f32, f32, f32) -> bool) {
        if self.nodes.is_empty() {
            return;
        }
        let inv_d = Vec3A::ONE / ray.d;
        let neg = [inv_d.x < 0.0, inv_d.y < 0.0, inv_d.z < 0.0];
        let mut stack = [0u32; STACK];
        let mut sp = 0usize;
        let mut current = 0u32;
        loop {
            let node = &self.nodes[current as usize];
            if node.bounds.hit(ray, inv_d, *t_max) {
                if node.count > 0 {
                    let first = node.offset as usize;
                    for i in first..first + node.count as usize {
                        if let Some((t, b1, b2)) = self.prims[i].intersect(ray, *t_max) {
                            *t_max = t;
                            if on_hit(i as u32, t, b1, b2) {
                                return;
                            }
                        }
                    }
                } else {
                    let (near, far) = if neg[node.axis as usize] {
                        (node.offset, current + 1)
                    } else {
                        (current + 1, node.offset)
                    };
                    stack[sp] = far;
                    sp += 1;
                    current = near;
                    continue;
                }
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            current = stack[sp];
        }
    }
}

fn make_leaf(items: &[BuildItem], first: usize, bounds: Aabb) -> Node {
    debug_assert!(!items.is_empty() && items.len() <= u16::MAX as usize);
    Node {
        bounds,
        offset: first as u32,
        count: items.len() as u16,
        axis: 0,
    }
}

/// Builds the subtree over `items` (which start at `first` in the final order) at `depth`;
/// returns its index.
fn build_node(items: &mut [BuildItem], first: usize, depth: usize, nodes: &mut Vec<Node>) -> usize {
    let bounds = items.iter().fold(Aabb::EMPTY, |b, it| b.union(it.bounds));
    let index = nodes.len();
    if items.len() <= 1 {
        nodes.push(make_leaf(items, first, bounds));
        return index;
    }
    let centroids = items.iter().fold(Aabb::EMPTY, |b, it| b.grow(it.centroid));
    let extent = centroids.extent();
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let sah = if depth < SAH_DEPTH {
        sah_split(items, &centroids, axis, bounds)
    } else {
        None
    };
    let mid = match sah {
        Some(split) => split,
        None if items.len() <= MAX_LEAF => {
            nodes.push(make_leaf(items, first, bounds));
            return index;
        }
        None => {
            // No useful SAH split (e.g. coincident centroids): split by count.
            let m = items.len() / 2;
            items.select_nth_unstable_by(m, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
            m
        }
    };
    nodes.push(Node {
        bounds,
        offset: 0,
        count: 0,
        axis: axis as u8,
    });
    let (left, right) = items.split_at_mut(mid);
    build_node(left, first, depth + 1, nodes);
    let second = build_node(right, first + mid, depth + 1, nodes);
    nodes[index].offset = second as u32;
    index
}

/// Binned SAH: the partition point of the cheapest split, or None when a leaf is cheaper.
fn sah_split(items: &mut [BuildItem], centroids: &Aabb, axis: usize, bounds: Aabb) -> Option<usize> {
    let lo = centroids.min[axis];
    let width = centroids.max[axis] - lo;
    if width <= 0.0 || !width.is_finite() {
        return None;
    }
    let bin_of = |c: f32| (((c - lo) / width * BINS as f32) as usize).min(BINS - 1);
    let mut counts = [0usize; BINS];
    let mut boxes = [Aabb::EMPTY; BINS];
    for it in items.iter() {
        let b = bin_of(it.centroid[axis]);
        counts[b] += 1;
        boxes[b] = boxes[b].union(it.bounds);
    }
    // Sweep from the right to get the cost of every right-hand side, then from the left.
    let mut right_area = [0.0f32; BINS];
    let mut right_count = [0usize; BINS];
    let (mut acc, mut n) = (Aabb::EMPTY, 0);
    for i in (1..BINS).rev() {
        acc = acc.union(boxes[i]);
        n += counts[i];
        right_area[i] = acc.surface_area();
        right_count[i] = n;
    }
    let (mut acc, mut n) = (Aabb::EMPTY, 0);
    let mut best = (f32::INFINITY, 0);
    for i in 0..BINS - 1 {
        acc = acc.union(boxes[i]);
        n += counts[i];
        if n == 0 || right_count[i + 1] == 0 {
            continue;
        }
        let cost = n as f32 * acc.surface_area() + right_count[i + 1] as f32 * right_area[i + 1];
        if cost < best.0 {
            best = (cost, i);
        }
    }
    let parent_area = bounds.surface_area();
    let split_cost = TRAVERSAL_COST + best.0 / parent_area.max(f32::MIN_POSITIVE);
    if !best.0.is_finite() || (items.len() <= MAX_LEAF && split_cost >= items.len() as f32) {
        return None;
    }
    let mut mid = 0;
    for i in 0..items.len() {
        if bin_of(items[i].centroid[axis]) <= best.1 {
            items.swap(i, mid);
            mid += 1;
        }
    }
    (mid > 0 && mid < items.len()).then_some(mid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Sphere;
    use crate::sampling::{Sampler, Stream, square_to_uniform_sphere};

    fn spheres(n: usize) -> Vec<Primitive> {
        let mut s = Sampler::new(3, Stream::Camera, 0, 0);
        (0..n)
            .map(|i| {
                Primitive::Sphere(Sphere {
                    center: Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 10.0,
                    radius: 0.05 + 0.3 * s.next_1d(),
                    shape: i as u32,
                    flip: false,
                    rotation: glam::Quat::IDENTITY,
                })
            })
            .collect()
    }

    /// Depth of the deepest leaf.
    fn depth(bvh: &Bvh, node: usize) -> usize {
        let n = &bvh.nodes[node];
        if n.count > 0 {
            0
        } else {
            1 + depth(bvh, node + 1).max(depth(bvh, n.offset as usize))
        }
    }

    /// Spheres shrinking geometrically towards the origin, placed on the x, y and z axes in
    /// turn, each 17 times closer than the one before on its axis. At every level the widest
    /// axis holds one sphere far out and everything else in the first of the 16 bins, so the
    /// SAH can only peel one sphere off per level: unbounded, the tree is as deep as there
    /// are spheres.
    fn progression(n: usize) -> Vec<Primitive> {
        let step = 17f32.powf(1.0 / 3.0);
        (0..n)
            .map(|i| {
                let l = step.powi(-(i as i32));
                let mut center = Vec3A::ZERO;
                center[i % 3] = l;
                Primitive::Sphere(Sphere {
                    center,
                    radius: 0.1 * l,
                    shape: i as u32,
                    flip: false,
                    rotation: glam::Quat::IDENTITY,
                })
            })
            .collect()
    }

    #[test]
    fn nested_sizes_in_a_progression_cannot_overflow_the_traversal_stack() {
        // 90 spheres: with the SAH alone the tree was 87 levels deep and a ray from the small
        // end overflowed the old fixed stack of 64 entries (index out of bounds).
        let prims = progression(90);
        let bvh = Bvh::build(prims.clone());
        let d = depth(&bvh, 0);
        assert!(d < STACK, "depth {d}");
        let mut s = Sampler::new(5, Stream::Camera, 0, 0);
        for _ in 0..500 {
            // From below the origin outwards: the near child is always the deeper subtree, so
            // every level pushes one entry.
            // Towards the origin, where the smallest spheres are, passing between them.
            let target = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 1e-30;
            let o = Vec3A::splat(-1.0);
            let ray = Ray::new(o, (target - o).normalize());
            let brute = prims
                .iter()
                .filter_map(|p| p.intersect(&ray, f32::INFINITY).map(|h| h.0))
                .min_by(|a, b| a.total_cmp(b));
            assert_eq!(brute, bvh.intersect(&ray, f32::INFINITY).map(|h| h.t));
            assert_eq!(bvh.occluded(&ray, f32::INFINITY), brute.is_some());
        }
    }

    #[test]
    fn matches_brute_force() {
        let prims = spheres(500);
        let bvh = Bvh::build(prims.clone());
        let mut s = Sampler::new(4, Stream::Camera, 0, 0);
        for _ in 0..2000 {
            let o = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 12.0 - Vec3A::ONE;
            let ray = Ray::new(o, square_to_uniform_sphere(s.next_2d()));
            let brute = prims
                .iter()
                .filter_map(|p| p.intersect(&ray, f32::INFINITY).map(|h| (h.0, p.shape())))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let fast = bvh
                .intersect(&ray, f32::INFINITY)
                .map(|h| (h.t, bvh.primitives()[h.prim as usize].shape()));
            assert_eq!(brute, fast);
            assert_eq!(bvh.occluded(&ray, f32::INFINITY), brute.is_some());
        }
    }
}
