//! A bounding volume hierarchy built with the binned surface area heuristic, object splits and
//! spatial splits (`spatial_split.rs`).

use glam::Vec3A;

use super::bvh4::{self, BinaryTree, WideNode};
use super::packet::{self, Hits8, Rays8};
use super::spatial_split;
use super::tri4::{self, PACKED, Tri4};
use super::{Aabb, Hit, PrimHit, Primitive, Ray};
use crate::engine::lanes::{LANES, M8};

pub(super) const BINS: usize = 16;
const MAX_LEAF: usize = 4;
/// Cost of a traversal step relative to one primitive test, for the SAH.
const TRAVERSAL_COST: f32 = 1.0;
/// References in a node from which its two halves are built in parallel (below, a task's
/// overhead and the renumbering of its nodes cost more than the parallelism gains).
const PARALLEL_BUILD: usize = 1 << 14;
/// Spatial splits may add one reference for every this many primitives (Embree's default
/// replication bound is of this order; without one, a scene of long slivers could multiply
/// its references many times over).
const SPATIAL_BUDGET_DIVISOR: usize = 2;
/// Depth below which the SAH chooses splits (object and spatial). Deeper, splits are by count
/// (median), which halves the references at every level: with at most 2^32 the tree's depth stays
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
    Own(Own),
    #[cfg(feature = "obvhs")]
    Cw(Box<obvhs::cwbvh::CwBvh>),
    #[cfg(feature = "obvhs")]
    Bin(Box<obvhs::bvh2::Bvh2>),
}

/// Our tree: wide nodes, and the leaves of triangles packed in lanes (`tri4.rs`).
#[derive(Clone, Debug)]
struct Own {
    nodes: Vec<WideNode>,
    packs: Vec<Tri4>,
}

impl std::fmt::Debug for Accel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Accel::Empty => f.write_str("Empty"),
            Accel::Own(o) => write!(f, "Own({} nodes, {} packs)", o.nodes.len(), o.packs.len()),
            #[cfg(feature = "obvhs")]
            Accel::Cw(c) => write!(f, "Cwbvh({} nodes)", c.nodes.len()),
            #[cfg(feature = "obvhs")]
            Accel::Bin(b) => write!(f, "Bvh2({} nodes)", b.nodes.len()),
        }
    }
}

/// The scene's acceleration structure; owns the primitives in traversal order.
///
/// With spatial splits (`spatial_split.rs`) a primitive can sit in several leaves: each leaf
/// holds its own copy, so that a leaf's primitives stay contiguous (reaching them through an
/// index array instead cost the living room 5–10% of its rays a second), and `distinct` names
/// the first copy of each.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    accel: Accel,
    prims: Vec<Primitive>,
    /// Slot of each primitive's first copy, ascending.
    distinct: Vec<u32>,
    bounds: Aabb,
}

/// A reference to a primitive during the build: the box of its part in the node.
#[derive(Clone, Copy, Debug)]
pub(super) struct BuildItem {
    pub(super) bounds: Aabb,
    centroid: Vec3A,
    pub(super) index: usize,
}

impl BuildItem {
    fn new(index: usize, bounds: Aabb) -> BuildItem {
        BuildItem {
            bounds,
            centroid: bounds.center(),
            index,
        }
    }

    /// The same primitive with a smaller part's box (a spatial split's side).
    pub(super) fn with_bounds(&self, bounds: Aabb) -> BuildItem {
        BuildItem::new(self.index, bounds)
    }
}

/// What the build accumulates while it recurses.
struct Builder<'a> {
    prims: &'a [Primitive],
    nodes: Vec<Node>,
    /// Leaf slots in order: the primitive each holds.
    order: Vec<u32>,
    /// References spatial splits may still add (bounds the build's memory).
    budget: usize,
    /// Surface area of the root, against which a split's overlap is judged.
    root_area: f32,
}

impl<'a> Builder<'a> {
    fn new(prims: &'a [Primitive], root_area: f32, budget: usize, capacity: usize) -> Builder<'a> {
        Builder {
            prims,
            nodes: Vec::with_capacity(2 * capacity),
            order: Vec::with_capacity(capacity),
            budget,
            root_area,
        }
    }

    /// Builds `items` as a subtree of its own (nodes and slots numbered from 0).
    fn subtree(&self, items: Vec<BuildItem>, budget: usize, depth: usize) -> Builder<'a> {
        let mut b = Builder::new(self.prims, self.root_area, budget, 0);
        build_node(&mut b, items, depth);
        b
    }

    /// Appends a subtree built on its own, renumbering its nodes and slots; returns the index
    /// of its root.
    fn append(&mut self, sub: Builder) -> usize {
        let (node_base, slot_base) = (self.nodes.len() as u32, self.order.len() as u32);
        self.nodes.extend(sub.nodes.into_iter().map(|mut n| {
            n.offset += if n.count > 0 { slot_base } else { node_base };
            n
        }));
        self.order.extend(sub.order);
        node_base as usize
    }
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
        let items: Vec<BuildItem> = prims
            .iter()
            .enumerate()
            .map(|(index, p)| BuildItem::new(index, p.bounds()))
            .collect();
        let mut b = Builder::new(
            &prims,
            bounds.surface_area(),
            prims.len() / SPATIAL_BUDGET_DIVISOR,
            prims.len(),
        );
        if !items.is_empty() {
            build_node(&mut b, items, 0);
        }
        let (nodes, order) = (b.nodes, b.order);
        assert!(
            order.len() <= u32::MAX as usize,
            "leaf slots are numbered in 32 bits"
        );
        let mut seen = vec![false; prims.len()];
        let distinct = (0..order.len() as u32)
            .filter(|&slot| !std::mem::replace(&mut seen[order[slot as usize] as usize], true))
            .collect::<Vec<u32>>();
        assert_eq!(distinct.len(), prims.len(), "every primitive is in a leaf");
        // Each primitive moves to its first slot and is copied to the others.
        let mut slots: Vec<Option<Primitive>> = prims.into_iter().map(Some).collect();
        let mut placed: Vec<Option<Primitive>> = vec![None; order.len()];
        for &slot in &distinct {
            placed[slot as usize] = slots[order[slot as usize] as usize].take();
        }
        let first: Vec<u32> = {
            let mut first = vec![0; slots.len()];
            for &slot in &distinct {
                first[order[slot as usize] as usize] = slot;
            }
            first
        };
        for slot in 0..order.len() {
            if placed[slot].is_none() {
                placed[slot] = placed[first[order[slot] as usize] as usize].clone();
            }
        }
        let prims: Vec<Primitive> = placed
            .into_iter()
            .map(|p| p.expect("every slot holds a primitive"))
            .collect();
        let mut wide = bvh4::collapse(&Binary(&nodes));
        // At most one pack a leaf: reserved, a doubling vector's peak cost the staircase 20 MB.
        let mut packs = Vec::with_capacity(nodes.iter().filter(|n| n.count > 0).count());
        bvh4::pack_leaves(&mut wide, |first, count| {
            tri4::pack(&prims, first, count, &mut packs)
        });
        Bvh {
            accel: Accel::Own(Own { nodes: wide, packs }),
            prims,
            distinct,
            bounds,
        }
    }

    /// Each primitive once, with the slot of its first copy ([`Bvh::primitives`] holds a
    /// primitive once per leaf it sits in): what an area light samples.
    pub fn distinct(&self) -> impl Iterator<Item = (u32, &Primitive)> {
        self.distinct
            .iter()
            .map(|&slot| (slot, &self.prims[slot as usize]))
    }

    /// How many distinct primitives the tree holds.
    pub fn distinct_len(&self) -> usize {
        self.distinct.len()
    }

    /// Primitives by leaf slot, in BVH order (a primitive in several leaves is here once per
    /// leaf); [`Hit::prim`] indexes this.
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
            Accel::Own(own) => {
                let mut best: Option<Hit> = None;
                let mut t_max = t_max;
                self.traverse::<true>(own, ray, &mut t_max, |prim, h| {
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
            Accel::Own(own) => {
                let mut found = false;
                let mut t_max = t_max;
                self.traverse::<false>(own, ray, &mut t_max, |_, _| {
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
            Accel::Own(own) => packet::closest(&own.nodes, &own.packs, &self.prims, rays),
            _ => self.lane_by_lane(rays, |ray, t_max| self.intersect(ray, t_max)),
        }
    }

    /// Lanes of eight rays that something blocks, as [`Bvh::occluded`] finds them.
    #[inline(always)]
    pub fn occluded8(&self, rays: &Rays8) -> M8 {
        match &self.accel {
            Accel::Own(own) => packet::occluded(&own.nodes, &own.packs, &self.prims, rays),
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
        own: &Own,
        ray: &Ray,
        t_max: &mut f32,
        mut on_hit: impl FnMut(u32, PrimHit) -> bool,
    ) {
        bvh4::traverse::<NEAREST_FIRST>(&own.nodes, ray, t_max, |child, count, t_max| {
            if count & PACKED as u32 != 0 {
                return own.packs[child as usize]
                    .intersect(ray, *t_max)
                    .is_some_and(|(slot, h)| {
                        *t_max = h.t;
                        on_hit(slot, h)
                    });
            }
            for i in child as usize..(child + count) as usize {
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
        Ok(Bvh {
            accel,
            distinct: (0..prims.len() as u32).collect(),
            prims,
            bounds,
        })
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

/// Builds the subtree over `items` at `depth`; returns its index. Leaves append their
/// references to `b.order`.
fn build_node(b: &mut Builder, mut items: Vec<BuildItem>, depth: usize) -> usize {
    let bounds = items.iter().fold(Aabb::EMPTY, |b, it| b.union(it.bounds));
    let index = b.nodes.len();
    let leaf = |b: &mut Builder, items: &[BuildItem]| {
        debug_assert!(!items.is_empty() && items.len() <= u16::MAX as usize);
        b.nodes.push(Node {
            bounds,
            offset: b.order.len() as u32,
            count: items.len() as u16,
        });
        b.order.extend(items.iter().map(|it| it.index as u32));
        index
    };
    if items.len() <= 1 {
        return leaf(b, &items);
    }
    let centroids = items.iter().fold(Aabb::EMPTY, |b, it| b.grow(it.centroid));
    let n = items.len();
    let sah = depth < SAH_DEPTH;
    let object = sah.then(|| object_split(&items, &centroids)).flatten();
    // Spatial splits only where the object split's children overlap much (or none exists), and
    // while the budget of copies lasts.
    let overlapping = object.is_none_or(|o| {
        o.left.intersection(o.right).surface_area() > spatial_split::MIN_OVERLAP * b.root_area
    });
    let spatial = (sah && overlapping && b.budget > 0)
        .then(|| spatial_split::find(&items, b.prims, bounds))
        .flatten()
        .filter(|s| s.duplicates(n) <= b.budget && object.is_none_or(|o| s.cost < o.cost));
    let best_cost = spatial.map(|s| s.cost).or(object.map(|o| o.cost));
    let split_cost = best_cost.map(|c| TRAVERSAL_COST + c / bounds.surface_area().max(f32::MIN_POSITIVE));
    if n <= MAX_LEAF && split_cost.is_none_or(|c| c >= n as f32) {
        return leaf(b, &items);
    }
    let (left, right) = match spatial.and_then(|s| s.partition(&items, b.prims)) {
        Some(halves) => {
            // The node's own references are not needed below it (kept, every level of spatial
            // splits held its copy to the end of the build).
            drop(items);
            halves
        }
        None => {
            let mid = match object.and_then(|o| o.partition(&mut items, &centroids)) {
                Some(mid) => mid,
                None if n <= MAX_LEAF => return leaf(b, &items),
                None => median(&mut items, &centroids),
            };
            let right = items.split_off(mid);
            (items, right)
        }
    };
    b.budget = b.budget.saturating_sub(left.len() + right.len() - n);
    b.nodes.push(Node {
        bounds,
        offset: 0,
        count: 0,
    });
    let second = if n >= PARALLEL_BUILD {
        // The halves in parallel, each with its share of the budget by size: the tree depends
        // on the items alone, not on how many threads build it or which finishes first.
        let left_budget = (b.budget as u64 * left.len() as u64 / (left.len() + right.len()) as u64) as usize;
        let right_budget = b.budget - left_budget;
        let (l, r) = rayon::join(
            || b.subtree(left, left_budget, depth + 1),
            || b.subtree(right, right_budget, depth + 1),
        );
        b.append(l);
        b.append(r)
    } else {
        build_node(b, left, depth + 1);
        build_node(b, right, depth + 1)
    };
    b.nodes[index].offset = second as u32;
    index
}

/// No useful SAH split (coincident centroids, or below the SAH's depth): by count on the widest
/// axis of the centroids.
fn median(items: &mut [BuildItem], centroids: &Aabb) -> usize {
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

/// The bin of a centroid's coordinate on `axis`, or None if the centroids do not spread along it.
fn binning(centroids: &Aabb, axis: usize) -> Option<impl Fn(f32) -> usize> {
    let lo = centroids.min[axis];
    let width = centroids.max[axis] - lo;
    (width > 0.0 && width.is_finite())
        .then_some(move |c: f32| (((c - lo) / width * BINS as f32) as usize).min(BINS - 1))
}

/// The cheapest partition of a node's references by their centroids: SAH cost (unnormalised),
/// the axis, the last bin on the left, and the two sides' boxes.
#[derive(Clone, Copy, Debug)]
struct ObjectSplit {
    cost: f32,
    axis: usize,
    last: usize,
    left: Aabb,
    right: Aabb,
}

/// Binned SAH over the three axes: the cheapest object split, if the centroids spread at all.
/// (Binning only the axis of the widest centroids, as pbrt-v4 does, traced 7–15% fewer path
/// samples a second on the 131k-triangle mesh and the two interiors: docs/engine.md, "Real
/// scenes".)
fn object_split(items: &[BuildItem], centroids: &Aabb) -> Option<ObjectSplit> {
    let mut best: Option<ObjectSplit> = None;
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
        // Sweep from the right to get every right-hand side, then from the left.
        let mut right_box = [Aabb::EMPTY; BINS];
        let mut right_count = [0usize; BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in (1..BINS).rev() {
            acc = acc.union(boxes[i]);
            n += counts[i];
            right_box[i] = acc;
            right_count[i] = n;
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in 0..BINS - 1 {
            acc = acc.union(boxes[i]);
            n += counts[i];
            if n == 0 || right_count[i + 1] == 0 {
                continue;
            }
            let cost =
                n as f32 * acc.surface_area() + right_count[i + 1] as f32 * right_box[i + 1].surface_area();
            // (A NaN or infinite cost, from infinite coordinates, never wins.)
            if cost.is_finite() && best.is_none_or(|b| cost < b.cost) {
                best = Some(ObjectSplit {
                    cost,
                    axis,
                    last: i,
                    left: acc,
                    right: right_box[i + 1],
                });
            }
        }
    }
    best
}

impl ObjectSplit {
    /// Moves the left side's references first; the partition point, if both sides hold some.
    fn partition(&self, items: &mut [BuildItem], centroids: &Aabb) -> Option<usize> {
        let bin_of = binning(centroids, self.axis).expect("the split's axis has bins");
        let mut mid = 0;
        for i in 0..items.len() {
            if bin_of(items[i].centroid[self.axis]) <= self.last {
                items.swap(i, mid);
                mid += 1;
            }
        }
        (mid > 0 && mid < items.len()).then_some(mid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::lanes::{F8, V8};
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
            if let Accel::Own(own) = &bvh.accel {
                let d = bvh4::depth(&own.nodes, 0);
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

    /// Long thin triangles crossing a box at random: every one's box is far larger than it is.
    fn slivers(n: usize) -> Vec<Primitive> {
        let mut s = Sampler::new(6, Stream::Camera, 0, 0);
        let mut point = || Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 10.0;
        (0..n)
            .map(|i| {
                let (a, b) = (point(), point());
                let side = (b - a).cross(Vec3A::Y).normalize_or_zero() * 0.05;
                Primitive::Triangle(crate::geometry::Triangle {
                    shape: i as u32,
                    ..crate::geometry::Triangle::bare([a, b, a + side])
                })
            })
            .collect()
    }

    #[test]
    fn spatial_splits_share_slivers_between_leaves_and_find_the_same_hits() {
        let prims = slivers(400);
        let bvh = Bvh::build(prims.clone());
        let copies = bvh.primitives().len();
        assert_eq!(bvh.distinct_len(), prims.len());
        assert!(
            copies > prims.len() && copies <= prims.len() * 3 / 2,
            "{copies} copies"
        );
        let mut shapes: Vec<u32> = bvh.distinct().map(|(_, p)| p.shape()).collect();
        shapes.sort();
        assert_eq!(shapes, (0..prims.len() as u32).collect::<Vec<_>>());
        let mut s = Sampler::new(7, Stream::Camera, 0, 0);
        let mut batch = Vec::new();
        for _ in 0..4000 {
            let o = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 12.0 - Vec3A::ONE;
            let ray = Ray::new(o, square_to_uniform_sphere(s.next_2d()));
            let brute = prims
                .iter()
                .filter_map(|p| {
                    p.intersect(&ray, f32::INFINITY)
                        .map(|h| (h.t, h.b1, h.b2, p.shape()))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let hit = bvh.intersect(&ray, f32::INFINITY);
            let fast = hit.map(|h| (h.t, h.b1, h.b2, bvh.primitives()[h.prim as usize].shape()));
            assert_eq!(brute, fast);
            assert_eq!(bvh.occluded(&ray, f32::INFINITY), brute.is_some());
            // The packet traversal finds the same primitive (perhaps another leaf's copy).
            batch.push(ray);
            if batch.len() == LANES {
                let v = |f: &dyn Fn(&Ray) -> Vec3A| {
                    let p: Vec<Vec3A> = batch.iter().map(f).collect();
                    V8 {
                        x: F8::from_fn(|l| p[l].x),
                        y: F8::from_fn(|l| p[l].y),
                        z: F8::from_fn(|l| p[l].z),
                    }
                };
                let rays = Rays8 {
                    o: v(&|r| r.o),
                    d: v(&|r| r.d),
                    t_max: F8::splat(f32::INFINITY),
                    active: M8::splat(true),
                };
                let hits = bvh.intersect8(&rays);
                for (lane, ray) in batch.drain(..).enumerate() {
                    let one = bvh.intersect(&ray, f32::INFINITY);
                    let shape = |h: Hit| (h.t, h.b1, h.b2, bvh.primitives()[h.prim as usize].shape());
                    assert_eq!(hits.hit(lane).map(shape), one.map(shape));
                }
            }
        }
    }

    #[test]
    fn a_parallel_build_is_the_same_tree_on_any_number_of_threads() {
        let prims = slivers(3 * PARALLEL_BUILD);
        let build = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| Bvh::build(prims.clone()))
        };
        let (one, two) = (build(1), build(2));
        let layout = |b: &Bvh| -> (Vec<u32>, Vec<u32>, String) {
            (
                b.primitives().iter().map(Primitive::shape).collect(),
                b.distinct.clone(),
                match &b.accel {
                    Accel::Own(own) => format!("{own:?}"),
                    other => panic!("{other:?}"),
                },
            )
        };
        assert_eq!(layout(&one), layout(&two));
        assert_eq!(one.distinct_len(), prims.len());
        let mut s = Sampler::new(8, Stream::Camera, 0, 0);
        for _ in 0..300 {
            let o = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 12.0 - Vec3A::ONE;
            let ray = Ray::new(o, square_to_uniform_sphere(s.next_2d()));
            let brute = prims
                .iter()
                .filter_map(|p| p.intersect(&ray, f32::INFINITY).map(|h| (h.t, p.shape())))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let fast = two.intersect(&ray, f32::INFINITY);
            assert_eq!(
                brute,
                fast.map(|h| (h.t, two.primitives()[h.prim as usize].shape()))
            );
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
