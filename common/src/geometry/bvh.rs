//! A bounding volume hierarchy built with the binned surface area heuristic.

use glam::Vec3A;

use super::bvh4::{self, BinaryTree, WideNode};
use super::packet::{self, Hits8, Rays8};
use super::{Aabb, Hit, PrimHit, Primitive, Ray};
use crate::engine::lanes::{LANES, M8};

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
pub(super) const STACK: usize = SAH_DEPTH + 32;

/// One node of the binary tree the build makes (traversal uses its collapse into
/// [`WideNode`]s). Interior nodes keep their first child right after them.
#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first primitive. Interior: index of the second child.
    offset: u32,
    /// Leaf: primitive count (> 0). Interior: 0.
    count: u16,
}

/// Which traversal structure a [`Bvh`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// Ours: binned SAH, binary, one box test per node.
    Own,
    /// obvhs's compressed 8-wide BVH (PLOC build, SSE2 node test).
    #[cfg(feature = "obvhs")]
    Cwbvh,
    /// obvhs's binary BVH (PLOC build, reinsertion, SAH leaf collapse).
    #[cfg(feature = "obvhs")]
    Bvh2,
}

/// The traversal structure behind a [`Bvh`].
#[derive(Clone, Default)]
enum Accel {
    #[default]
    Empty,
    Own(Vec<WideNode>),
    #[cfg(feature = "obvhs")]
    Cw(Box<obvhs::cwbvh::CwBvh>),
    #[cfg(feature = "obvhs")]
    Bin(Box<obvhs::bvh2::Bvh2>),
}

impl std::fmt::Debug for Accel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Accel::Empty => f.write_str("Empty"),
            Accel::Own(n) => write!(f, "Own({} nodes)", n.len()),
            #[cfg(feature = "obvhs")]
            Accel::Cw(c) => write!(f, "Cwbvh({} nodes)", c.nodes.len()),
            #[cfg(feature = "obvhs")]
            Accel::Bin(b) => write!(f, "Bvh2({} nodes)", b.nodes.len()),
        }
    }
}

/// The scene's acceleration structure; owns the primitives in traversal order.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    accel: Accel,
    prims: Vec<Primitive>,
    bounds: Aabb,
}

struct BuildItem {
    bounds: Aabb,
    centroid: Vec3A,
    index: usize,
}

impl Bvh {
    /// Builds the tree; primitives are reordered so that each leaf's are contiguous.
    pub fn build(prims: Vec<Primitive>) -> Bvh {
        Self::build_with(prims, Backend::Own)
    }

    /// Builds the tree with the given backend (an empty scene always gets an empty tree).
    pub fn build_with(prims: Vec<Primitive>, backend: Backend) -> Bvh {
        let bounds = prims.iter().fold(Aabb::EMPTY, |b, p| b.union(p.bounds()));
        if prims.is_empty() {
            return Bvh::default();
        }
        match backend {
            Backend::Own => Self::build_own(prims, bounds),
            #[cfg(feature = "obvhs")]
            Backend::Cwbvh | Backend::Bvh2 => {
                obvhs_backend::build(prims, bounds, backend == Backend::Cwbvh).unwrap_or_else(|prims| {
                    // Too deep for the CWBVH's fixed traversal stack: ours bounds its depth.
                    Self::build_own(prims, bounds)
                })
            }
        }
    }

    /// Which backend this tree uses.
    pub fn backend(&self) -> Backend {
        match &self.accel {
            Accel::Empty | Accel::Own(_) => Backend::Own,
            #[cfg(feature = "obvhs")]
            Accel::Cw(_) => Backend::Cwbvh,
            #[cfg(feature = "obvhs")]
            Accel::Bin(_) => Backend::Bvh2,
        }
    }

    fn build_own(prims: Vec<Primitive>, bounds: Aabb) -> Bvh {
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
        Bvh {
            accel: Accel::Own(bvh4::collapse(&Binary(&nodes))),
            prims,
            bounds,
        }
    }

    /// Primitives in BVH order; [`Hit::prim`] indexes this.
    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }

    /// Bounds of everything.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Closest hit in (0, t_max).
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        match &self.accel {
            Accel::Empty => None,
            Accel::Own(nodes) => {
                let mut best: Option<Hit> = None;
                let mut t_max = t_max;
                self.traverse::<true>(nodes, ray, &mut t_max, |prim, h| {
                    best = Some(Hit {
                        t: h.t,
                        prim,
                        b1: h.b1,
                        b2: h.b2,
                        inner: h.inner,
                    });
                    false
                });
                best
            }
            #[cfg(feature = "obvhs")]
            Accel::Cw(cw) => obvhs_backend::intersect_cw(cw, &self.prims, ray, t_max),
            #[cfg(feature = "obvhs")]
            Accel::Bin(b) => obvhs_backend::intersect_bin(b, &self.prims, ray, t_max),
        }
    }

    /// Whether anything lies in (0, t_max): shadow rays stop at the first hit.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        match &self.accel {
            Accel::Empty => false,
            Accel::Own(nodes) => {
                let mut found = false;
                let mut t_max = t_max;
                self.traverse::<false>(nodes, ray, &mut t_max, |_, _| {
                    found = true;
                    true
                });
                found
            }
            #[cfg(feature = "obvhs")]
            Accel::Cw(cw) => obvhs_backend::occluded_cw(cw, &self.prims, ray, t_max),
            #[cfg(feature = "obvhs")]
            Accel::Bin(b) => obvhs_backend::occluded_bin(b, &self.prims, ray, t_max),
        }
    }

    /// Closest hits of eight rays at once, each lane's the hit [`Bvh::intersect`] finds for
    /// its ray (see `packet.rs`).
    #[inline(always)]
    pub fn intersect8(&self, rays: &Rays8) -> Hits8 {
        match &self.accel {
            Accel::Own(nodes) => packet::closest(nodes, &self.prims, rays),
            _ => self.lane_by_lane(rays, |ray, t_max| self.intersect(ray, t_max)),
        }
    }

    /// Lanes of eight rays that something blocks, as [`Bvh::occluded`] finds them.
    #[inline(always)]
    pub fn occluded8(&self, rays: &Rays8) -> M8 {
        match &self.accel {
            Accel::Own(nodes) => packet::occluded(nodes, &self.prims, rays),
            _ => M8::from_fn(|lane| {
                rays.active.get(lane) && self.occluded(&rays.ray(lane), rays.t_max.0[lane])
            }),
        }
    }

    /// A packet query answered one ray at a time (the empty tree, obvhs's trees).
    fn lane_by_lane(&self, rays: &Rays8, query: impl Fn(&Ray, f32) -> Option<Hit>) -> Hits8 {
        let mut out = Hits8::none();
        for lane in 0..LANES {
            if rays.active.get(lane)
                && let Some(h) = query(&rays.ray(lane), rays.t_max.0[lane])
            {
                out.record(lane, &h);
            }
        }
        out
    }

    /// Traversal, front to back if `NEAREST_FIRST`; `on_hit` returns true to stop.
    #[inline]
    fn traverse<const NEAREST_FIRST: bool>(
        &self,
        nodes: &[WideNode],
        ray: &Ray,
        t_max: &mut f32,
        mut on_hit: impl FnMut(u32, PrimHit) -> bool,
    ) {
        bvh4::traverse::<NEAREST_FIRST>(nodes, ray, t_max, |first, count, t_max| {
            for i in first as usize..(first + count) as usize {
                if let Some(h) = self.prims[i].intersect(ray, *t_max) {
                    *t_max = h.t;
                    if on_hit(i as u32, h) {
                        return true;
                    }
                }
            }
            false
        });
    }
}

/// The binary tree as [`build_node`] lays it out, for [`bvh4::collapse`].
struct Binary<'a>(&'a [Node]);

impl BinaryTree for Binary<'_> {
    fn bounds(&self, i: u32) -> Aabb {
        self.0[i as usize].bounds
    }

    fn leaf(&self, i: u32) -> Option<(u32, u16)> {
        let n = &self.0[i as usize];
        (n.count > 0).then_some((n.offset, n.count))
    }

    fn children(&self, i: u32) -> [u32; 2] {
        [i + 1, self.0[i as usize].offset]
    }
}

/// The obvhs backends: PLOC-built trees over our primitives' boxes, our primitive tests.
#[cfg(feature = "obvhs")]
mod obvhs_backend {
    use obvhs::BvhBuildParams;
    use obvhs::bvh2::Bvh2;
    use obvhs::bvh2::leaf_collapser::collapse;
    use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
    use obvhs::cwbvh::CwBvh;
    use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
    use obvhs::ploc::PlocBuilder;
    use obvhs::ray::{Ray as ORay, RayHit};

    use super::{Accel, Bvh};
    use crate::geometry::{Aabb, Hit, Primitive, Ray};

    /// Deepest CWBVH its traversal can walk: obvhs's stack holds 32 entries and overwrites the
    /// last one silently when full.
    const CW_MAX_DEPTH: usize = 30;

    /// Builds with the steps of obvhs's `build_cwbvh` / `build_bvh2` (medium preset) but
    /// without their debug-build validation. Err gives the primitives back when the CWBVH is
    /// too deep to traverse safely.
    pub(super) fn build(prims: Vec<Primitive>, bounds: Aabb, wide: bool) -> Result<Bvh, Vec<Primitive>> {
        let config = BvhBuildParams::medium_build();
        let aabbs: Vec<obvhs::aabb::Aabb> = prims
            .iter()
            .map(|p| {
                let b = p.bounds();
                obvhs::aabb::Aabb::new(b.min, b.max)
            })
            .collect();
        let mut bvh2 = PlocBuilder::with_capacity(aabbs.len()).build(
            config.ploc_search_distance,
            &aabbs,
            (0..aabbs.len() as u32).collect(),
            config.sort_precision,
            config.search_depth_threshold,
        );
        let mut reinsertion = ReinsertionOptimizer::default();
        reinsertion.run(&mut bvh2, config.reinsertion_batch_ratio, None);
        let (accel, order) = if wide {
            let cw = bvh2_to_cwbvh(&bvh2, config.max_prims_per_leaf.clamp(1, 3), true, false);
            if cw_depth(&cw, 0) > CW_MAX_DEPTH {
                return Err(prims);
            }
            let order = cw.primitive_indices.clone();
            (Accel::Cw(Box::new(cw)), order)
        } else {
            collapse(
                &mut bvh2,
                config.max_prims_per_leaf.clamp(1, 255),
                config.collapse_traversal_cost,
            );
            reinsertion.run(
                &mut bvh2,
                config.reinsertion_batch_ratio * config.post_collapse_reinsertion_batch_ratio_multiplier,
                None,
            );
            let order = bvh2.primitive_indices.clone();
            (Accel::Bin(Box::new(bvh2)), order)
        };
        // Reorder the primitives so that the trees' primitive ids index them directly.
        let mut slots: Vec<Option<Primitive>> = prims.into_iter().map(Some).collect();
        let prims: Vec<Primitive> = order
            .iter()
            .map(|&i| slots[i as usize].take().expect("each primitive is placed once"))
            .collect();
        assert!(
            slots.iter().all(Option::is_none),
            "every primitive is in the tree"
        );
        Ok(Bvh { accel, prims, bounds })
    }

    /// Levels below `node` (a node with only leaf children has depth 1).
    fn cw_depth(cw: &CwBvh, node: usize) -> usize {
        let n = &cw.nodes[node];
        1 + (0..8)
            .filter(|&c| !n.is_leaf(c))
            .map(|c| cw_depth(cw, n.child_node_index(c) as usize))
            .max()
            .unwrap_or(0)
    }

    #[inline]
    fn oray(ray: &Ray, t_max: f32) -> ORay {
        ORay::new(ray.o, ray.d, 0.0, t_max)
    }

    /// obvhs's primitive callback for the closest hit: our own primitive test, keeping the
    /// barycentrics obvhs does not carry in `best`.
    fn closest<'a>(
        prims: &'a [Primitive],
        ray: &'a Ray,
        best: &'a mut Option<Hit>,
    ) -> impl FnMut(&ORay, usize) -> f32 + 'a {
        move |r, id| match prims[id].intersect(ray, r.tmax) {
            Some(h) => {
                *best = Some(Hit {
                    t: h.t,
                    prim: id as u32,
                    b1: h.b1,
                    b2: h.b2,
                    inner: h.inner,
                });
                h.t
            }
            None => f32::INFINITY,
        }
    }

    /// obvhs's primitive callback for occlusion.
    fn any<'a>(prims: &'a [Primitive], ray: &'a Ray) -> impl FnMut(&ORay, usize) -> f32 + 'a {
        move |r, id| prims[id].intersect(ray, r.tmax).map_or(f32::INFINITY, |h| h.t)
    }

    pub(super) fn intersect_cw(cw: &CwBvh, prims: &[Primitive], ray: &Ray, t_max: f32) -> Option<Hit> {
        let mut best = None;
        cw.ray_traverse(
            oray(ray, t_max),
            &mut RayHit::none(),
            closest(prims, ray, &mut best),
        );
        best
    }

    pub(super) fn occluded_cw(cw: &CwBvh, prims: &[Primitive], ray: &Ray, t_max: f32) -> bool {
        !cw.ray_traverse_miss(oray(ray, t_max), any(prims, ray))
    }

    pub(super) fn intersect_bin(b: &Bvh2, prims: &[Primitive], ray: &Ray, t_max: f32) -> Option<Hit> {
        let mut best = None;
        b.ray_traverse(
            oray(ray, t_max),
            &mut RayHit::none(),
            closest(prims, ray, &mut best),
        );
        best
    }

    pub(super) fn occluded_bin(b: &Bvh2, prims: &[Primitive], ray: &Ray, t_max: f32) -> bool {
        !b.ray_traverse_miss(oray(ray, t_max), any(prims, ray))
    }
}

fn make_leaf(items: &[BuildItem], first: usize, bounds: Aabb) -> Node {
    debug_assert!(!items.is_empty() && items.len() <= u16::MAX as usize);
    Node {
        bounds,
        offset: first as u32,
        count: items.len() as u16,
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
    let sah = if depth < SAH_DEPTH {
        sah_split(items, &centroids, bounds)
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
            // No useful SAH split (e.g. coincident centroids): split by count on the widest axis.
            let extent = centroids.extent();
            let axis = if extent.x >= extent.y && extent.x >= extent.z {
                0
            } else if extent.y >= extent.z {
                1
            } else {
                2
            };
            let m = items.len() / 2;
            items.select_nth_unstable_by(m, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
            m
        }
    };
    nodes.push(Node {
        bounds,
        offset: 0,
        count: 0,
    });
    let (left, right) = items.split_at_mut(mid);
    build_node(left, first, depth + 1, nodes);
    let second = build_node(right, first + mid, depth + 1, nodes);
    nodes[index].offset = second as u32;
    index
}

/// The bin of a centroid's coordinate on `axis`, or None if the centroids do not spread along it.
fn binning(centroids: &Aabb, axis: usize) -> Option<impl Fn(f32) -> usize> {
    let lo = centroids.min[axis];
    let width = centroids.max[axis] - lo;
    (width > 0.0 && width.is_finite())
        .then_some(move |c: f32| (((c - lo) / width * BINS as f32) as usize).min(BINS - 1))
}

/// Binned SAH over the three axes: the partition point of the cheapest split, or None when a
/// leaf is cheaper. (Binning only the axis of the widest centroids, as pbrt-v4 does, traced 7–15%
/// fewer path samples a second on the 131k-triangle mesh and the two interiors:
/// docs/engine.md, "Real scenes".)
fn sah_split(items: &mut [BuildItem], centroids: &Aabb, bounds: Aabb) -> Option<usize> {
    // (cost, axis, last bin on the left)
    let mut best = (f32::INFINITY, 0, 0);
    for axis in 0..3 {
        let Some(bin_of) = binning(centroids, axis) else {
            continue;
        };
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
        for i in 0..BINS - 1 {
            acc = acc.union(boxes[i]);
            n += counts[i];
            if n == 0 || right_count[i + 1] == 0 {
                continue;
            }
            let cost = n as f32 * acc.surface_area() + right_count[i + 1] as f32 * right_area[i + 1];
            if cost < best.0 {
                best = (cost, axis, i);
            }
        }
    }
    let parent_area = bounds.surface_area();
    let split_cost = TRAVERSAL_COST + best.0 / parent_area.max(f32::MIN_POSITIVE);
    if !best.0.is_finite() || (items.len() <= MAX_LEAF && split_cost >= items.len() as f32) {
        return None;
    }
    let (_, axis, last) = best;
    let bin_of = binning(centroids, axis).expect("the best split's axis has bins");
    let mut mid = 0;
    for i in 0..items.len() {
        if bin_of(items[i].centroid[axis]) <= last {
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

    /// Every backend this build has.
    fn backends() -> Vec<Backend> {
        #[allow(unused_mut)]
        let mut b = vec![Backend::Own];
        #[cfg(feature = "obvhs")]
        b.extend([Backend::Cwbvh, Backend::Bvh2]);
        b
    }

    /// Spheres shrinking geometrically towards the origin, placed on the x, y and z axes in
    /// turn, each 17 times closer than the one before on its axis. At every level the widest
    /// axis holds one sphere far out and everything else in the first of the 16 bins, so the
    /// SAH can only peel one sphere off per level: unbounded, the tree is as deep as there
    /// are spheres.
    fn progression(n: usize) -> Vec<Primitive> {
        let step = libm::powf(17f32, 1.0 / 3.0);
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
        for backend in backends() {
            let bvh = Bvh::build_with(prims.clone(), backend);
            if let Accel::Own(nodes) = &bvh.accel {
                let d = bvh4::depth(nodes, 0);
                assert!(d < STACK, "depth {d}");
            }
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
                    .filter_map(|p| p.intersect(&ray, f32::INFINITY).map(|h| h.t))
                    .min_by(|a, b| a.total_cmp(b));
                let fast = bvh.intersect(&ray, f32::INFINITY).map(|h| h.t);
                if bvh.backend() == Backend::Own {
                    assert_eq!(brute, fast);
                } else {
                    // obvhs's node test has no conservative far bound: among spheres ~1e-30
                    // apart it can miss the nearest by an ulp of t (BVH2 does here).
                    let (a, b) = (brute.unwrap(), fast.expect("a hit"));
                    assert!((a - b).abs() <= 1e-4 * a, "{backend:?}: {a} vs {b}");
                }
                assert_eq!(bvh.occluded(&ray, f32::INFINITY), brute.is_some());
            }
        }
    }

    #[test]
    fn matches_brute_force() {
        for n in [0, 1, 2, 3, 500] {
            for backend in backends() {
                let prims = spheres(n);
                let bvh = Bvh::build_with(prims.clone(), backend);
                let mut s = Sampler::new(4, Stream::Camera, 0, 0);
                for _ in 0..2000 {
                    let o = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 12.0 - Vec3A::ONE;
                    let ray = Ray::new(o, square_to_uniform_sphere(s.next_2d()));
                    let brute = prims
                        .iter()
                        .filter_map(|p| p.intersect(&ray, f32::INFINITY).map(|h| (h.t, p.shape())))
                        .min_by(|a, b| a.0.total_cmp(&b.0));
                    let fast = bvh
                        .intersect(&ray, f32::INFINITY)
                        .map(|h| (h.t, bvh.primitives()[h.prim as usize].shape()));
                    assert_eq!(brute, fast, "{backend:?}, {n} spheres");
                    assert_eq!(bvh.occluded(&ray, f32::INFINITY), brute.is_some());
                    // Shadow-ray range: a hit must lie in (0, t_max).
                    let t_max = 5.0;
                    let brute_short = brute.is_some_and(|h| h.0 < t_max);
                    assert_eq!(bvh.occluded(&ray, t_max), brute_short, "{backend:?}");
                }
            }
        }
    }
}
