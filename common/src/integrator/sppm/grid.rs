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
