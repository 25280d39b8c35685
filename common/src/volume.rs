//! Mitsuba's `gridvolume`: values on a voxel grid over a box, read from Mitsuba's binary `.vol`
//! files, looked up as Mitsuba's Dr.Jit textures do (texel centres at (i + ½)/res, trilinear or
//! nearest, and the same wrap modes as bitmaps). Media read their density and albedo from it.

use glam::{Affine3A, Vec3A};

use crate::color::Rgb;
use crate::geometry::Aabb;
use crate::texture::{Wrap, wrap_index};

/// How values between voxel centres are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VolumeFilter {
    /// Trilinear interpolation of the eight nearest voxel centres (Mitsuba's default).
    Trilinear,
    /// The voxel the point lies in.
    Nearest,
}

/// Why a `.vol` file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// The file could not be read.
    #[error("cannot read: {0}")]
    Io(#[from] std::io::Error),
    /// Not Mitsuba's format.
    #[error("not a Mitsuba volume file (it should start with \"VOL\" and version 3)")]
    NotVol,
    /// Another value encoding than float32 (Mitsuba reads only that).
    #[error("only float32 volume data (encoding 1) is supported, as in Mitsuba, not encoding {0}")]
    Encoding(i32),
    /// A channel count Mitsuba's RGB renderers cannot use as a colour.
    #[error("a volume needs 1 or 3 channels, not {0}")]
    Channels(i32),
    /// A resolution below one voxel.
    #[error("the grid's resolution {0}×{1}×{2} is not positive")]
    Resolution(i32, i32, i32),
    /// Fewer bytes than the header announces.
    #[error("the header announces {expected} bytes of data but the file holds {found}")]
    Truncated {
        /// Bytes the header implies.
        expected: u64,
        /// Bytes after the header.
        found: u64,
    },
    /// A voxel that is not a finite number.
    #[error("voxel value {0} is not a finite number")]
    NotFinite(f32),
}

/// The contents of a `.vol` file.
#[derive(Clone, Debug, PartialEq)]
pub struct VolumeData {
    /// Voxels along x, y and z.
    pub res: [usize; 3],
    /// Values per voxel (1 or 3).
    pub channels: usize,
    /// Values, x fastest, then y, then z, channels interleaved.
    pub values: Box<[f32]>,
    /// The box the file says the grid covers (what `use_grid_bbox` maps to the unit cube).
    pub bbox: Aabb,
}

/// Length of a `.vol` header: "VOL", version, encoding, resolution, channels, box.
const HEADER: usize = 48;

impl VolumeData {
    /// Reads Mitsuba's `.vol` format (version 3, float32). What the header announces is checked
    /// against the file's length before anything is allocated, so a hostile header cannot make
    /// the reader allocate more than the file's size.
    pub fn parse(bytes: &[u8]) -> Result<VolumeData, VolumeError> {
        if bytes.len() < HEADER || &bytes[..3] != b"VOL" || bytes[3] != 3 {
            return Err(VolumeError::NotVol);
        }
        let int = |at: usize| i32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        let float = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        let encoding = int(4);
        if encoding != 1 {
            return Err(VolumeError::Encoding(encoding));
        }
        let (x, y, z) = (int(8), int(12), int(16));
        if x <= 0 || y <= 0 || z <= 0 {
            return Err(VolumeError::Resolution(x, y, z));
        }
        let channels = int(20);
        if channels != 1 && channels != 3 {
            return Err(VolumeError::Channels(channels));
        }
        let count = x as u64 * y as u64 * z as u64 * channels as u64;
        let found = (bytes.len() - HEADER) as u64;
        if found / 4 < count {
            return Err(VolumeError::Truncated {
                expected: count * 4,
                found,
            });
        }
        let values: Box<[f32]> = bytes[HEADER..HEADER + count as usize * 4]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
            .collect();
        if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
            return Err(VolumeError::NotFinite(*bad));
        }
        Ok(VolumeData {
            res: [x as usize, y as usize, z as usize],
            channels: channels as usize,
            values,
            bbox: Aabb {
                min: Vec3A::new(float(24), float(28), float(32)),
                max: Vec3A::new(float(36), float(40), float(44)),
            },
        })
    }

    /// The largest value over every voxel and channel: the majorant of a density read from it.
    pub fn max(&self) -> f32 {
        self.values
            .iter()
            .fold(f32::NEG_INFINITY, |m, &v| if v > m { v } else { m })
    }
}

/// A `gridvolume`: the data, placed in the scene by `to_world`.
#[derive(Clone, Debug, PartialEq)]
pub struct GridVolume {
    data: VolumeData,
    /// World to the grid's unit cube.
    to_local: Affine3A,
    filter: VolumeFilter,
    wrap: Wrap,
    /// Where the grid lies in the world: the unit cube under `to_world`.
    bbox: Aabb,
}

impl GridVolume {
    /// The grid `data` with the unit cube mapped into the world by `to_world`, or (with
    /// `use_grid_bbox`) the file's box mapped into the world by it.
    pub fn new(
        data: VolumeData,
        to_world: Affine3A,
        use_grid_bbox: bool,
        filter: VolumeFilter,
        wrap: Wrap,
    ) -> GridVolume {
        let mut to_local = to_world.inverse();
        if use_grid_bbox {
            // Mitsuba: to_local = bbox_transform · to_local, bbox_transform mapping the file's box
            // to the unit cube.
            let b = data.bbox;
            let scale = Vec3A::ONE / (b.max - b.min);
            to_local =
                Affine3A::from_scale(scale.into()) * Affine3A::from_translation((-b.min).into()) * to_local;
        }
        let to_unit = to_local.inverse();
        let mut bbox = Aabb::EMPTY;
        for corner in 0..8 {
            let c = Vec3A::new(
                (corner & 1) as f32,
                ((corner >> 1) & 1) as f32,
                (corner >> 2) as f32,
            );
            bbox = bbox.grow(to_unit.transform_point3a(c));
        }
        GridVolume {
            data,
            to_local,
            filter,
            wrap,
            bbox,
        }
    }

    /// The world box the grid covers.
    pub fn bbox(&self) -> Aabb {
        self.bbox
    }

    /// The largest value the grid holds.
    pub fn max(&self) -> f32 {
        self.data.max()
    }

    /// The smallest value the grid holds.
    pub fn min(&self) -> f32 {
        self.data
            .values
            .iter()
            .fold(f32::INFINITY, |m, &v| if v < m { v } else { m })
    }

    /// The value at world point `p` (one channel given as grey).
    pub fn eval(&self, p: Vec3A) -> Rgb {
        let q = self.to_local.transform_point3a(p);
        if !q.is_finite() {
            return Rgb::ZERO;
        }
        let [rx, ry, rz] = self.data.res;
        let res = Vec3A::new(rx as f32, ry as f32, rz as f32);
        match self.filter {
            VolumeFilter::Nearest => {
                let i = (q * res).floor();
                self.voxel(i.x as i64, i.y as i64, i.z as i64)
            }
            VolumeFilter::Trilinear => {
                let f = q * res - Vec3A::splat(0.5);
                let i = f.floor();
                let w1 = f - i;
                let w0 = Vec3A::ONE - w1;
                let (x, y, z) = (i.x as i64, i.y as i64, i.z as i64);
                let mut sum = Rgb::ZERO;
                for corner in 0..8 {
                    let (dx, dy, dz) = (corner & 1, (corner >> 1) & 1, corner >> 2);
                    let wx = if dx == 0 { w0.x } else { w1.x };
                    let wy = if dy == 0 { w0.y } else { w1.y };
                    let wz = if dz == 0 { w0.z } else { w1.z };
                    sum += self.voxel(x + dx, y + dy, z + dz) * (wx * wy * wz);
                }
                sum
            }
        }
    }

    /// Voxel (x, y, z), wrapped into the grid.
    fn voxel(&self, x: i64, y: i64, z: i64) -> Rgb {
        let [rx, ry, rz] = self.data.res;
        let x = wrap_index(x, rx as i64, self.wrap) as usize;
        let y = wrap_index(y, ry as i64, self.wrap) as usize;
        let z = wrap_index(z, rz as i64, self.wrap) as usize;
        let i = ((z * ry + y) * rx + x) * self.data.channels;
        let v = &self.data.values;
        if self.data.channels == 1 {
            Rgb::splat(v[i])
        } else {
            Rgb::new(v[i], v[i + 1], v[i + 2])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `.vol` file's bytes.
    pub(crate) fn vol_bytes(res: [i32; 3], channels: i32, values: &[f32]) -> Vec<u8> {
        let mut b = b"VOL\x03".to_vec();
        for i in [1, res[0], res[1], res[2], channels] {
            b.extend(i.to_le_bytes());
        }
        for f in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0].iter().chain(values) {
            b.extend(f.to_le_bytes());
        }
        b
    }

    #[test]
    fn a_vol_file_is_read_and_interpolated_between_voxel_centres() {
        // 2×1×1, one channel: 1 at x = ¼, 3 at x = ¾.
        let data = VolumeData::parse(&vol_bytes([2, 1, 1], 1, &[1.0, 3.0])).unwrap();
        assert_eq!(data.max(), 3.0);
        let g = GridVolume::new(
            data.clone(),
            Affine3A::IDENTITY,
            false,
            VolumeFilter::Trilinear,
            Wrap::Clamp,
        );
        let at = |x: f32| g.eval(Vec3A::new(x, 0.5, 0.5)).x;
        assert_eq!(at(0.25), 1.0);
        assert_eq!(at(0.75), 3.0);
        assert_eq!(at(0.5), 2.0);
        // Clamped beyond the outer centres, and beyond the box.
        assert_eq!(at(0.1), 1.0);
        assert_eq!(at(1.5), 3.0);
        let repeat = GridVolume::new(
            data.clone(),
            Affine3A::IDENTITY,
            false,
            VolumeFilter::Trilinear,
            Wrap::Repeat,
        );
        // Between x = ¾ (3) and x = 1¼ (1 again).
        assert_eq!(repeat.eval(Vec3A::new(1.0, 0.5, 0.5)).x, 2.0);
        let nearest = GridVolume::new(
            data.clone(),
            Affine3A::IDENTITY,
            false,
            VolumeFilter::Nearest,
            Wrap::Clamp,
        );
        assert_eq!(nearest.eval(Vec3A::new(0.49, 0.5, 0.5)).x, 1.0);
        assert_eq!(nearest.eval(Vec3A::new(0.51, 0.5, 0.5)).x, 3.0);
        // Placed by to_world: the unit cube scaled by 2 and moved by (1, 0, 0).
        let to_world =
            Affine3A::from_translation(glam::Vec3::X) * Affine3A::from_scale(glam::Vec3::splat(2.0));
        let placed = GridVolume::new(data, to_world, false, VolumeFilter::Trilinear, Wrap::Clamp);
        assert_eq!(placed.eval(Vec3A::new(2.0, 1.0, 1.0)).x, 2.0);
        assert_eq!(placed.bbox().min, Vec3A::new(1.0, 0.0, 0.0));
        assert_eq!(placed.bbox().max, Vec3A::new(3.0, 2.0, 2.0));
    }

    #[test]
    fn three_channels_are_a_colour_indexed_x_fastest() {
        // 1×2×1: voxel y = 0 is (1, 2, 3), voxel y = 1 is (4, 5, 6).
        let data = VolumeData::parse(&vol_bytes([1, 2, 1], 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])).unwrap();
        let g = GridVolume::new(
            data,
            Affine3A::IDENTITY,
            false,
            VolumeFilter::Nearest,
            Wrap::Clamp,
        );
        assert_eq!(g.eval(Vec3A::new(0.5, 0.2, 0.5)), Rgb::new(1.0, 2.0, 3.0));
        assert_eq!(g.eval(Vec3A::new(0.5, 0.8, 0.5)), Rgb::new(4.0, 5.0, 6.0));
    }

    #[test]
    fn bad_vol_files_are_refused_before_allocating() {
        assert!(matches!(VolumeData::parse(b"VOX\x03"), Err(VolumeError::NotVol)));
        // A header announcing 2³¹ voxels in a file of a few bytes.
        let huge = vol_bytes([1 << 10, 1 << 10, 1 << 11], 1, &[0.5]);
        assert!(matches!(
            VolumeData::parse(&huge),
            Err(VolumeError::Truncated { .. })
        ));
        assert!(matches!(
            VolumeData::parse(&vol_bytes([1, 1, 1], 2, &[0.0, 0.0])),
            Err(VolumeError::Channels(2))
        ));
        assert!(matches!(
            VolumeData::parse(&vol_bytes([0, 1, 1], 1, &[])),
            Err(VolumeError::Resolution(0, 1, 1))
        ));
        assert!(matches!(
            VolumeData::parse(&vol_bytes([1, 1, 1], 1, &[f32::NAN])),
            Err(VolumeError::NotFinite(_))
        ));
        let mut other = vol_bytes([1, 1, 1], 1, &[0.0]);
        other[4] = 2;
        assert!(matches!(VolumeData::parse(&other), Err(VolumeError::Encoding(2))));
    }
}
