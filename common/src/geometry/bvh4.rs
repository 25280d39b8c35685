//! Four-wide nodes collapsed from the binary SAH tree, each tested against a ray with one SIMD
//! slab test over its four children's boxes.
//!
//! Why: on the Cornell box a binary node visit was most of a ray's cost, one box per load and
//! per branch; four boxes in structure-of-arrays lanes cost about as much as one. The binary
//! tree stays the build's output (its SAH and depth bound are unchanged); this is only its
//! traversal layout.

use arrayvec::ArrayVec;
use glam::{Vec3A, Vec4};

use super::tri4::PACKED;
use super::{Aabb, Ray, gamma};

/// Entries of the traversal stack. A wide node is never deeper than the binary node it was
/// collapsed from (`super::bvh::STACK` levels at most), and each visit pushes at most three
/// entries more than it pops.
pub(super) const WIDE_STACK: usize = 3 * super::bvh::STACK + 1;

/// A node of the binary tree as the build leaves it, read by [`collapse`].
pub(super) trait BinaryTree {
    /// Bounds of node `i`.
    fn bounds(&self, i: u32) -> Aabb;
    /// `Some((first, count))` for a leaf, `None` for an interior node.
    fn leaf(&self, i: u32) -> Option<(u32, u16)>;
    /// The two children of interior node `i`.
    fn children(&self, i: u32) -> [u32; 2];
}

/// Up to four children: boxes in SIMD lanes, then what each child is.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct WideNode {
    min_x: Vec4,
    min_y: Vec4,
    min_z: Vec4,
    max_x: Vec4,
    max_y: Vec4,
    max_z: Vec4,
    /// Interior child: its wide node's index. Leaf child: its first primitive, or if its count
    /// is marked [`PACKED`], its pack of triangles.
    child: [u32; 4],
    /// Leaf child: its primitive count (> 0), maybe marked [`PACKED`]. Interior child: 0.
    /// (Sixteen bits keep a node in two cache lines: with 32 it took three.)
    count: [u16; 4],
    /// Lanes that hold a child, as a bit mask (empty lanes' boxes are never tested in).
    pub(super) used: u32,
}

/// What the traversal does next: a wide node to test, or a leaf's primitives.
#[derive(Clone, Copy)]
struct Entry {
    /// Entry distance of the child's box: skipped when something nearer has been hit since.
    t: f32,
    child: u32,
    count: u16,
}

impl WideNode {
    fn empty() -> WideNode {
        WideNode {
            min_x: Vec4::ZERO,
            min_y: Vec4::ZERO,
            min_z: Vec4::ZERO,
            max_x: Vec4::ZERO,
            max_y: Vec4::ZERO,
            max_z: Vec4::ZERO,
            child: [0; 4],
            count: [0; 4],
            used: 0,
        }
    }

    /// Child `lane`'s box as (min, max), for the packet traversal.
    #[inline(always)]
    pub(super) fn child_bounds(&self, lane: usize) -> [[f32; 3]; 2] {
        [
            [self.min_x[lane], self.min_y[lane], self.min_z[lane]],
            [self.max_x[lane], self.max_y[lane], self.max_z[lane]],
        ]
    }

    /// Child `lane`: (wide node, 0), (first primitive, count) or (pack, count | [`PACKED`]).
    #[inline(always)]
    pub(super) fn child(&self, lane: usize) -> (u32, u16) {
        (self.child[lane], self.count[lane])
    }

    fn set(&mut self, lane: usize, b: Aabb, child: u32, count: u16) {
        self.min_x[lane] = b.min.x;
        self.min_y[lane] = b.min.y;
        self.min_z[lane] = b.min.z;
        self.max_x[lane] = b.max.x;
        self.max_y[lane] = b.max.y;
        self.max_z[lane] = b.max.z;
        self.child[lane] = child;
        self.count[lane] = count;
        self.used |= 1 << lane;
    }
}

/// Collapses the binary tree rooted at node 0 into wide nodes (the root is wide node 0): each
/// wide node takes a binary node's children and keeps opening its largest interior child
/// (by surface area, the SAH's measure) until it has four.
pub(super) fn collapse(tree: &impl BinaryTree) -> Vec<WideNode> {
    let mut nodes = vec![WideNode::empty()];
    if let Some((first, count)) = tree.leaf(0) {
        nodes[0].set(0, tree.bounds(0), first, count);
        return nodes;
    }
    // (wide node to fill, binary interior node whose subtree it holds)
    let mut todo = vec![(0usize, 0u32)];
    while let Some((wide, binary)) = todo.pop() {
        let mut kids: Vec<u32> = tree.children(binary).to_vec();
        while kids.len() < 4 {
            let open = kids
                .iter()
                .enumerate()
                .filter(|&(_, &k)| tree.leaf(k).is_none())
                .max_by(|a, b| {
                    tree.bounds(*a.1)
                        .surface_area()
                        .total_cmp(&tree.bounds(*b.1).surface_area())
                })
                .map(|(i, _)| i);
            let Some(i) = open else { break };
            let k = kids.remove(i);
            kids.splice(i..i, tree.children(k));
        }
        for (lane, &k) in kids.iter().enumerate() {
            match tree.leaf(k) {
                Some((first, count)) => nodes[wide].set(lane, tree.bounds(k), first, count),
                None => {
                    let index = nodes.len();
                    nodes.push(WideNode::empty());
                    nodes[wide].set(lane, tree.bounds(k), index as u32, 0);
                    todo.push((index, k));
                }
            }
        }
    }
    nodes
}

/// Hands each leaf child's (first, count) to `pack`; where it returns an index, the child
/// becomes that pack's, its count marked [`PACKED`].
pub(super) fn pack_leaves(nodes: &mut [WideNode], mut pack: impl FnMut(u32, u16) -> Option<u32>) {
    for n in nodes {
        for lane in 0..4 {
            if n.used & (1 << lane) != 0
                && n.count[lane] > 0
                && let Some(index) = pack(n.child[lane], n.count[lane])
            {
                n.child[lane] = index;
                n.count[lane] |= PACKED;
            }
        }
    }
}

/// Traversal of `nodes`: `test(child, count, t_max)` tests a leaf child's primitives, shrinking
/// `t_max` to any hit, and returns true to stop. `NEAREST_FIRST` visits a node's children front
/// to back, which the closest hit needs; a query for any hit (a shadow ray) skips the sorting,
/// as its answer does not depend on the order (docs/benchmarks.md, "Traversal order", has
/// what that gained).
#[inline]
pub(super) fn traverse<const NEAREST_FIRST: bool>(
    nodes: &[WideNode],
    ray: &Ray,
    t_max: &mut f32,
    mut test: impl FnMut(u32, u32, &mut f32) -> bool,
) {
    let inv_d = Vec3A::ONE / ray.d;
    let (ox, oy, oz) = (Vec4::splat(ray.o.x), Vec4::splat(ray.o.y), Vec4::splat(ray.o.z));
    let (ix, iy, iz) = (Vec4::splat(inv_d.x), Vec4::splat(inv_d.y), Vec4::splat(inv_d.z));
    // The far bound is widened by 2γ(3) so that rounding never loses a grazing hit.
    let widen = Vec4::splat(1.0 + 2.0 * gamma(3));
    // Not zeroed: a ray's stack is written as it is used (zeroing it cost 8% of a path).
    let mut stack = ArrayVec::<Entry, WIDE_STACK>::new();
    // The entry being visited: the nearest child hit goes on without a trip through the stack.
    let mut cur = Entry {
        t: 0.0,
        child: 0,
        count: 0,
    };
    loop {
        if cur.count > 0 {
            if test(cur.child, cur.count as u32, t_max) {
                return;
            }
        } else {
            let n = &nodes[cur.child as usize];
            let (tx0, tx1) = ((n.min_x - ox) * ix, (n.max_x - ox) * ix);
            let (ty0, ty1) = ((n.min_y - oy) * iy, (n.max_y - oy) * iy);
            let (tz0, tz1) = ((n.min_z - oz) * iz, (n.max_z - oz) * iz);
            let near = tx0.min(tx1).max(ty0.min(ty1)).max(tz0.min(tz1)).max(Vec4::ZERO);
            let far = tx0.max(tx1).min(ty0.max(ty1)).min(tz0.max(tz1)) * widen;
            let mut hit = near.cmple(far.min(Vec4::splat(*t_max))).bitmask() & n.used;
            let entry = |lane: usize| Entry {
                t: near[lane],
                child: n.child[lane],
                count: n.count[lane],
            };
            if hit != 0 && hit & (hit - 1) == 0 {
                cur = entry(hit.trailing_zeros() as usize);
                continue;
            }
            // Push the hit children (far to near if `NEAREST_FIRST`, so that the nearest is
            // tested first).
            let base = stack.len();
            while hit != 0 {
                let lane = hit.trailing_zeros() as usize;
                hit &= hit - 1;
                stack.push(entry(lane));
                let mut i = stack.len() - 1;
                while NEAREST_FIRST && i > base && stack[i - 1].t < stack[i].t {
                    stack.swap(i - 1, i);
                    i -= 1;
                }
            }
        }
        // Next: the top entry (the nearest left, if `NEAREST_FIRST`) that is not beyond a hit
        // found since it was pushed.
        loop {
            let Some(e) = stack.pop() else { return };
            if e.t > *t_max {
                continue;
            }
            cur = e;
            break;
        }
    }
}

/// Interior levels below `node`: the traversal stack must hold three entries per level.
#[cfg(test)]
pub(super) fn depth(nodes: &[WideNode], node: usize) -> usize {
    let n = &nodes[node];
    (0..4)
        .filter(|&lane| n.used & (1 << lane) != 0 && n.count[lane] == 0)
        .map(|lane| 1 + depth(nodes, n.child[lane] as usize))
        .max()
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    /// A binary node: bounds, leaf (first, count), children.
    type LineNode = (Aabb, Option<(u32, u32)>, [u32; 2]);

    /// A binary tree over `n` unit boxes on a line, split by count: leaves of one or two.
    struct Line(Vec<LineNode>);

    impl Line {
        fn new(n: u32) -> Line {
            let mut nodes = Vec::new();
            Self::build(&mut nodes, 0, n);
            Line(nodes)
        }

        fn build(nodes: &mut Vec<LineNode>, first: u32, count: u32) -> u32 {
            let bounds = Aabb {
                min: Vec3A::new(first as f32, 0.0, 0.0),
                max: Vec3A::new((first + count) as f32, 1.0, 1.0),
            };
            let index = nodes.len() as u32;
            nodes.push((bounds, None, [0, 0]));
            if count <= 2 {
                nodes[index as usize].1 = Some((first, count));
            } else {
                let half = count / 2;
                let a = Self::build(nodes, first, half);
                let b = Self::build(nodes, first + half, count - half);
                nodes[index as usize].2 = [a, b];
            }
            index
        }
    }

    impl BinaryTree for Line {
        fn bounds(&self, i: u32) -> Aabb {
            self.0[i as usize].0
        }
        fn leaf(&self, i: u32) -> Option<(u32, u16)> {
            self.0[i as usize].1.map(|(first, count)| (first, count as u16))
        }
        fn children(&self, i: u32) -> [u32; 2] {
            self.0[i as usize].2
        }
    }

    #[test]
    fn a_node_fills_two_cache_lines() {
        assert_eq!(std::mem::size_of::<WideNode>(), 128);
    }

    #[test]
    fn collapse_keeps_every_leaf_once_and_fills_nodes() {
        for n in [1, 2, 3, 5, 8, 17, 100] {
            let wide = collapse(&Line::new(n));
            let mut seen = vec![0; n as usize];
            let mut interior_refs = vec![0; wide.len()];
            for node in &wide {
                assert!(node.used != 0 && node.used.count_ones() <= 4);
                for lane in (0..4).filter(|&l| node.used & (1 << l) != 0) {
                    if node.count[lane] > 0 {
                        for p in node.child[lane]..node.child[lane] + node.count[lane] as u32 {
                            seen[p as usize] += 1;
                        }
                    } else {
                        interior_refs[node.child[lane] as usize] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&s| s == 1), "{n} boxes: {seen:?}");
            // Every wide node but the root is some node's child, once.
            assert_eq!(interior_refs[0], 0);
            assert!(interior_refs[1..].iter().all(|&r| r == 1));
            // Wide nodes are full wherever the binary tree had enough below them.
            if n >= 8 {
                assert_eq!(wide[0].used.count_ones(), 4);
            }
            // Four children per node: at most half as many levels as the binary tree's.
            let binary_depth = libm::log2f(n as f32 / 2.0).ceil() as usize;
            assert!(
                depth(&wide, 0) <= binary_depth.div_ceil(2),
                "{n}: {}",
                depth(&wide, 0)
            );
        }
    }

    #[test]
    fn a_ray_finds_the_nearest_leaf_first() {
        let line = Line::new(100);
        let mut leaves: Vec<u32> = line.0.iter().filter_map(|n| n.1.map(|l| l.0)).collect();
        leaves.sort();
        let wide = collapse(&line);
        // Along +x every leaf is hit, nearest first.
        let ray = Ray::new(Vec3A::new(-1.0, 0.5, 0.5), Vec3A::X);
        let mut order = Vec::new();
        let mut t_max = f32::INFINITY;
        traverse::<true>(&wide, &ray, &mut t_max, |first, _, _| {
            order.push(first);
            false
        });
        assert_eq!(order, leaves);
        // From the far end, a hit inside the first leaf reached ends the search: the next leaf
        // starts beyond it.
        let back = Ray::new(Vec3A::new(101.0, 0.5, 0.5), -Vec3A::X);
        order.clear();
        traverse::<true>(&wide, &back, &mut t_max, |first, count, t_max| {
            order.push(first);
            *t_max = 101.0 - (first + count) as f32 + 0.5;
            false
        });
        assert_eq!(order, vec![*leaves.last().unwrap()]);
    }
}
