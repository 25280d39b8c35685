//! The hashed uniform grid both photon maps bucket photons in: cells at least twice the
//! iteration's radius wide, so that a sphere of that radius overlaps at most 2 × 2 × 2 of them.

use glam::Vec3A;

/// The bucket of cell `c` in a table of `mask + 1` buckets.
#[inline]
pub fn hash_cell(c: [i32; 3], mask: usize) -> usize {
    let h = (c[0] as u32).wrapping_mul(73_856_093)
        ^ (c[1] as u32).wrapping_mul(19_349_663)
        ^ (c[2] as u32).wrapping_mul(83_492_791);
    (h as usize) & mask
}

/// The cell holding `p`.
#[inline]
pub fn cell_of(p: Vec3A, inv_cell: f32) -> [i32; 3] {
    let c = (p * inv_cell).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

/// The distinct buckets of the cells that the sphere of radius `r` at `p` overlaps, into
/// `out`; returns how many. Distinct cells may share a bucket, and a bucket must be visited
/// (or filled) once.
#[inline]
pub fn buckets_of_sphere(p: Vec3A, r: f32, inv_cell: f32, mask: usize, out: &mut [usize; 8]) -> usize {
    let lo = cell_of(p - Vec3A::splat(r), inv_cell);
    let hi = cell_of(p + Vec3A::splat(r), inv_cell);
    let mut n = 0;
    for x in lo[0]..=hi[0].min(lo[0] + 1) {
        for y in lo[1]..=hi[1].min(lo[1] + 1) {
            for z in lo[2]..=hi[2].min(lo[2] + 1) {
                let b = hash_cell([x, y, z], mask);
                if !out[..n].contains(&b) {
                    out[n] = b;
                    n += 1;
                }
            }
        }
    }
    n
}

/// Items grouped by bucket, by one counting sort: the build both photon maps share.
#[derive(Debug, Default)]
pub struct Buckets {
    /// Bucket b's items are `items[starts[b]..starts[b + 1]]`.
    starts: Vec<u32>,
    /// Scratch: each bucket's next write position (kept between builds, so memory stays flat).
    cursor: Vec<u32>,
}

impl Buckets {
    /// Sorts the (bucket, item) pairs that `pairs` yields into `items` by bucket, keeping their
    /// order within a bucket (so queries visit them in a deterministic order). `pairs` is called
    /// twice, to count and to fill, and must yield the same pairs both times.
    pub fn sort<T: Copy + Default>(
        &mut self,
        buckets: usize,
        pairs: impl Fn(&mut dyn FnMut(usize, T)),
        items: &mut Vec<T>,
    ) {
        self.starts.clear();
        self.starts.resize(buckets + 1, 0);
        pairs(&mut |b, _| self.starts[b + 1] += 1);
        for i in 0..buckets {
            self.starts[i + 1] += self.starts[i];
        }
        items.clear();
        items.resize(self.starts[buckets] as usize, T::default());
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.starts[..buckets]);
        pairs(&mut |b, item| {
            items[self.cursor[b] as usize] = item;
            self.cursor[b] += 1;
        });
    }

    /// Where bucket `b`'s items are.
    #[inline]
    pub fn range(&self, b: usize) -> std::ops::Range<usize> {
        self.starts[b] as usize..self.starts[b + 1] as usize
    }
}
