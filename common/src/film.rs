//! The film: exact sums of pixel samples, and image output.
//!
//! Why fixed point: the farm adds partial images from many machines in whatever order they
//! arrive. Integer addition is associative and commutative, so the sum, and so every byte of
//! the image, does not depend on that order or on how passes were split.

use std::path::Path;

use crate::color::{Rgb, srgb_encode};

/// Fixed-point scale: 2^24 steps per unit of radiance. A sample's rounding error (3e-8) is far
/// below the f32 precision of the output, and i64 sums hold 5e11 units per pixel.
pub const FIXED_SCALE: f64 = (1u64 << 24) as f64;

/// Summed samples of a range of passes.
///
/// With a box filter every sample lands in its own pixel with weight one, so a pixel's weight is
/// its pass count and `weights` stays empty: such scenes send and store 24 bytes a pixel. Wider
/// filters spread a sample over its neighbours (as Mitsuba's film does), and each pixel keeps the
/// exact sum of the weights it received, by which its sum is divided.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FilmSum {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Per pixel, per channel: the sum of (filter-weighted) samples in units of 1 /
    /// [`FIXED_SCALE`].
    pub sums: Vec<[i64; 3]>,
    /// Per pixel: the sum of filter weights in units of 1 / [`FIXED_SCALE`]; empty when every
    /// pixel's weight is its pass count (box filter).
    pub weights: Vec<i64>,
    /// Passes summed (each pass is one sample per pixel).
    pub passes: u64,
    /// Samples that were NaN or infinite and were left out (counted so they can be reported).
    pub nonfinite: u64,
}

/// Why two sums cannot be added or an image written.
#[derive(Debug, thiserror::Error)]
pub enum FilmError {
    /// The two sums are of different image sizes.
    #[error("cannot add a {0}x{1} film to a {2}x{3} film")]
    SizeMismatch(u32, u32, u32, u32),
    /// Nothing has been rendered yet.
    #[error("no pass has been rendered yet")]
    Empty,
    /// The output file name has no supported extension.
    #[error("unsupported output format \"{0}\": use .exr or .png")]
    Format(String),
    /// Writing the image failed.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: String,
        /// The cause.
        source: image::ImageError,
    },
    /// Writing an EXR with layers failed.
    #[error("cannot write {path}: {source}")]
    WriteLayers {
        /// The file.
        path: String,
        /// The cause.
        source: exr::error::Error,
    },
}

/// Converts one sample to fixed point; None for NaN or infinity.
#[inline]
pub fn to_fixed(v: Rgb) -> Option<[i64; 3]> {
    if !v.is_finite() {
        return None;
    }
    // Negative radiance cannot arise from valid transport; clamp so it cannot cancel energy.
    Some([v.x, v.y, v.z].map(|c| (c.max(0.0) as f64 * FIXED_SCALE).round() as i64))
}

/// Adds one pixel's fixed-point channels to another's.
#[inline]
pub fn add_fixed(acc: &mut [i64; 3], v: &[i64; 3]) {
    for (a, b) in acc.iter_mut().zip(v) {
        *a = a.saturating_add(*b);
    }
}

impl FilmSum {
    /// An empty sum.
    pub fn new(width: u32, height: u32) -> FilmSum {
        FilmSum {
            width,
            height,
            sums: vec![[0; 3]; width as usize * height as usize],
            weights: Vec::new(),
            passes: 0,
            nonfinite: 0,
        }
    }

    /// Empties the sum, keeping its pixels' memory (a renderer's reused pass).
    pub fn clear(&mut self) {
        self.sums.fill([0; 3]);
        self.weights.clear();
        self.passes = 0;
        self.nonfinite = 0;
    }

    /// Adds another sum: exact, so the order of additions never matters.
    pub fn add(&mut self, other: &FilmSum) -> Result<(), FilmError> {
        if (self.width, self.height) != (other.width, other.height) {
            return Err(FilmError::SizeMismatch(
                other.width,
                other.height,
                self.width,
                self.height,
            ));
        }
        for (a, b) in self.sums.iter_mut().zip(&other.sums) {
            add_fixed(a, b);
        }
        // A box-filtered sum is a weighted one whose weights are its pass counts.
        if !other.weights.is_empty() || !self.weights.is_empty() {
            self.make_weighted();
            let implicit = vec![other.box_weight(); self.weights.len()];
            let theirs = if other.weights.is_empty() {
                &implicit
            } else {
                &other.weights
            };
            for (a, b) in self.weights.iter_mut().zip(theirs) {
                *a = a.saturating_add(*b);
            }
        }
        self.passes += other.passes;
        self.nonfinite += other.nonfinite;
        Ok(())
    }

    /// The weight of every pixel of a box-filtered sum: one per pass.
    fn box_weight(&self) -> i64 {
        (self.passes as f64 * FIXED_SCALE) as i64
    }

    /// Gives every pixel an explicit weight (its pass count, if it had none).
    pub fn make_weighted(&mut self) {
        if self.weights.is_empty() {
            self.weights = vec![self.box_weight(); self.sums.len()];
        }
    }

    /// The image: each pixel's weighted mean of its samples (a box filter's is the mean of the
    /// passes). A pixel that received no weight is black.
    pub fn image(&self) -> Result<Vec<Rgb>, FilmError> {
        if self.passes == 0 {
            return Err(FilmError::Empty);
        }
        let pass_scale = 1.0 / (FIXED_SCALE * self.passes as f64);
        Ok(self
            .sums
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let scale = match self.weights.get(i) {
                    Some(&w) if w > 0 => 1.0 / w as f64,
                    Some(_) => 0.0,
                    None => pass_scale,
                };
                Rgb::new(
                    (s[0] as f64 * scale) as f32,
                    (s[1] as f64 * scale) as f32,
                    (s[2] as f64 * scale) as f32,
                )
            })
            .collect())
    }

    /// Writes the image: linear 32-bit float EXR or sRGB 8-bit PNG, by the file's extension.
    pub fn write(&self, path: &Path) -> Result<(), FilmError> {
        write_image(&self.image()?, self.width, self.height, path)
    }
}

/// Writes linear RGB pixels (row by row from the top) as EXR or PNG.
pub fn write_image(pixels: &[Rgb], width: u32, height: u32, path: &Path) -> Result<(), FilmError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let write_err = |source| FilmError::Write {
        path: path.display().to_string(),
        source,
    };
    match ext.as_str() {
        "exr" => {
            if pixels.len() != width as usize * height as usize {
                return Err(FilmError::Empty);
            }
            write_exr_layers(width, height, &[("", pixels)], path)
        }
        "png" => {
            let to8 = |v: f32| (srgb_encode(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8;
            let data: Vec<u8> = pixels
                .iter()
                .flat_map(|p| [to8(p.x), to8(p.y), to8(p.z)])
                .collect();
            let img = image::RgbImage::from_raw(width, height, data).ok_or(FilmError::Empty)?;
            img.save_with_format(path, image::ImageFormat::Png)
                .map_err(write_err)
        }
        other => Err(FilmError::Format(other.to_string())),
    }
}

/// Writes an EXR of 32-bit float RGB layers: `(prefix, pixels)` becomes channels `{prefix}R`,
/// `{prefix}G` and `{prefix}B` (the image as `R`, `G`, `B`, what every viewer shows; features as
/// `albedo.R` …, the names Mitsuba's `aov` integrator and Blender give their passes).
///
/// Why not the image crate's EXR encoder: it writes tiles as its threads finish them, so the
/// same pixels gave other bytes from run to run (six runs of one render, five different files),
/// and the farm promises the same bytes. Chunks here go in increasing order.
pub fn write_exr_layers(
    width: u32,
    height: u32,
    layers: &[(&str, &[Rgb])],
    path: &Path,
) -> Result<(), FilmError> {
    use exr::prelude::*;
    let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (prefix, pixels) in layers {
        for (c, name) in ["R", "G", "B"].iter().enumerate() {
            let values = pixels.iter().map(|p| p[c]).collect();
            channels.push(AnyChannel::new(
                format!("{prefix}{name}").as_str(),
                FlatSamples::F32(values),
            ));
        }
    }
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::default(),
        // Lossless, and in increasing order (`Encoding::SMALL_LOSSLESS`'s line order): the crate
        // compresses chunks in parallel but writes them sorted.
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|source| FilmError::WriteLayers {
            path: path.display().to_string(),
            source,
        })
}

/// Whether `path` names an EXR file (by its extension, as [`write_image`] decides).
pub fn is_exr(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// `out` with `insert` before its extension, beside it: the names of the files that go with
/// an output (`x.exr` → `x-000256.exr`, `x.denoised.exr`, `x0007.exr`).
pub fn beside(out: &Path, insert: &str) -> std::path::PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy()).unwrap_or_default();
    let name = match out.extension() {
        Some(ext) => format!("{stem}{insert}.{}", ext.to_string_lossy()),
        None => format!("{stem}{insert}"),
    };
    out.with_file_name(name)
}

/// Reads an image (EXR or PNG) as linear RGB, for comparisons against references.
pub fn read_image(path: &Path) -> Result<(u32, u32, Vec<Rgb>), image::ImageError> {
    let img = image::open(path)?.into_rgb32f();
    let (w, h) = img.dimensions();
    let px = img.pixels().map(|p| Rgb::new(p.0[0], p.0[1], p.0[2])).collect();
    Ok((w, h, px))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same pixels give the same EXR every time, and read back as written. (Through the
    /// image crate's encoder, six runs of one render gave five different files.)
    #[test]
    fn an_exr_has_the_same_bytes_every_time() {
        let (w, h) = (320u32, 200u32);
        let image: Vec<Rgb> = (0..w * h)
            .map(|i| Rgb::new((i % 7) as f32, (i % 13) as f32 * 0.1, (i % 101) as f32 * 0.37))
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let bytes: Vec<Vec<u8>> = (0..12)
            .map(|k| {
                let path = dir.path().join(format!("{k}.exr"));
                write_image(&image, w, h, &path).unwrap();
                std::fs::read(&path).unwrap()
            })
            .collect();
        assert!(bytes.windows(2).all(|p| p[0] == p[1]));
        let (rw, rh, back) = read_image(&dir.path().join("0.exr")).unwrap();
        assert_eq!((rw, rh, back), (w, h, image));
    }

    #[test]
    fn adding_is_exact_in_any_order() {
        let mk = |v: f32| {
            let mut f = FilmSum::new(1, 1);
            f.sums[0] = to_fixed(Rgb::splat(v)).unwrap();
            f.passes = 1;
            f
        };
        let parts = [mk(0.1), mk(1e3), mk(3.3e-5), mk(7.77)];
        let mut a = FilmSum::new(1, 1);
        for p in &parts {
            a.add(p).unwrap();
        }
        let mut b = FilmSum::new(1, 1);
        for p in parts.iter().rev() {
            b.add(p).unwrap();
        }
        assert_eq!(a, b);
        assert!(FilmSum::new(2, 1).add(&a).is_err());
        assert!(to_fixed(Rgb::new(f32::NAN, 0.0, 0.0)).is_none());
    }
}
