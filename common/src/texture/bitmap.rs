//! Mitsuba's `bitmap` texture: an image file looked up at (u, v), with bilinear or nearest
//! filtering and repeat, mirror or clamp wrapping.

use std::path::Path;

use glam::{Affine2, Vec2};

use super::texels::Texels;
use crate::color::{Rgb, luminance};

/// How texels are interpolated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    /// The nearest texel.
    Nearest,
    /// Bilinear interpolation of the four nearest texel centres (Mitsuba's default).
    Bilinear,
}

/// What lies outside the unit square.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    /// The image again (Mitsuba's default).
    Repeat,
    /// The image mirrored at each edge.
    Mirror,
    /// The edge texels, stretched.
    Clamp,
}

/// Why an image cannot be used as a texture.
#[derive(Debug, thiserror::Error)]
pub enum BitmapError {
    /// The file could not be read or decoded.
    #[error("{0}")]
    Image(#[from] image::ImageError),
    /// It has no pixels.
    #[error("the image is empty")]
    Empty,
}

/// The linear value of each level of an 8- or 16-bit sample: level / (levels − 1), sRGB-decoded
/// unless the texture is `raw`. Why a table: `powf` for each channel of each texel was 67% of
/// loading Bitterli's staircase (ten JPEGs, 3.6 s). Why from the integer samples: the image
/// crate's own conversion to floats is not always level / 255 to the bit (and runs its SIMD
/// code, picked by CPU), so the texels now depend on our arithmetic alone.
fn level_values<const LEVELS: usize>(srgb: bool) -> Box<[f32; LEVELS]> {
    let top = (LEVELS - 1) as f32;
    let values: Vec<f32> = (0..LEVELS)
        .map(|i| {
            let v = i as f32 / top;
            if srgb { crate::color::srgb_decode(v) } else { v }
        })
        .collect();
    values.into_boxed_slice().try_into().expect("one value a level")
}

/// An image, in linear RGB, ready for lookups.
#[derive(Clone, Debug)]
pub struct Bitmap {
    width: u32,
    height: u32,
    /// Row by row from the top of the image.
    texels: Texels,
    filter: Filter,
    wrap: Wrap,
    to_uv: Affine2,
    mean: Rgb,
}

impl Bitmap {
    /// Loads an image file. 8- and 16-bit images (PNG, JPEG) are sRGB-encoded and decoded to
    /// linear values unless `raw`; floating-point ones (EXR, HDR) are linear already.
    pub fn load(
        path: &Path,
        raw: bool,
        filter: Filter,
        wrap: Wrap,
        to_uv: Affine2,
    ) -> Result<Bitmap, BitmapError> {
        let image = image::ImageReader::open(path)
            .map_err(image::ImageError::IoError)?
            .with_guessed_format()
            .map_err(image::ImageError::IoError)?
            .decode()?;
        use image::ColorType::{L8, L16, La8, La16, Rgb8, Rgb16, Rgba8, Rgba16};
        let (width, height) = (image.width(), image.height());
        if width == 0 || height == 0 {
            return Err(BitmapError::Empty);
        }
        // 8- and 16-bit images are sRGB-encoded; floating-point ones (EXR, HDR) linear.
        let texels = match image.color() {
            L8 | La8 | Rgb8 | Rgba8 => Texels::Levels8 {
                samples: image.to_rgb8().into_raw(),
                table: level_values::<{ 1 << 8 }>(!raw),
            },
            L16 | La16 | Rgb16 | Rgba16 => Texels::Levels16 {
                samples: image.to_rgb16().into_raw(),
                table: level_values::<{ 1 << 16 }>(!raw),
            },
            _ => Texels::Linear(
                image
                    .to_rgb32f()
                    .pixels()
                    .map(|p| Rgb::new(p[0], p[1], p[2]))
                    .collect(),
            ),
        };
        Ok(Bitmap::with_texels(width, height, texels, filter, wrap, to_uv))
    }

    /// A bitmap from linear texels, row by row from the top.
    pub fn from_texels(
        width: u32,
        height: u32,
        texels: Vec<Rgb>,
        filter: Filter,
        wrap: Wrap,
        to_uv: Affine2,
    ) -> Bitmap {
        Bitmap::with_texels(width, height, Texels::Linear(texels), filter, wrap, to_uv)
    }

    fn with_texels(
        width: u32,
        height: u32,
        texels: Texels,
        filter: Filter,
        wrap: Wrap,
        to_uv: Affine2,
    ) -> Bitmap {
        assert_eq!(
            texels.len() as u64,
            width as u64 * height as u64,
            "one texel per pixel"
        );
        let sum = texels.iter().fold(glam::DVec3::ZERO, |acc, t| {
            acc + glam::DVec3::new(t.x as f64, t.y as f64, t.z as f64)
        });
        let mean = sum / texels.len() as f64;
        Bitmap {
            width,
            height,
            texels,
            filter,
            wrap,
            to_uv,
            mean: Rgb::new(mean.x as f32, mean.y as f32, mean.z as f32),
        }
    }

    /// The mean texel (its luminance is Mitsuba's `mean()`: the mean of the texels' luminances).
    pub fn mean(&self) -> Rgb {
        self.mean
    }

    /// The linear texels, row by row from the top.
    pub fn texels(&self) -> Vec<Rgb> {
        self.texels.iter().collect()
    }

    /// Width and height in texels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn texel(&self, x: i64, y: i64) -> Rgb {
        let x = wrap_index(x, self.width as i64, self.wrap);
        let y = wrap_index(y, self.height as i64, self.wrap);
        self.texels.get((y * self.width as i64 + x) as usize)
    }

    /// The colour at `uv`.
    pub fn eval(&self, uv: Vec2) -> Rgb {
        let uv = self.to_uv.transform_point2(uv);
        let size = Vec2::new(self.width as f32, self.height as f32);
        match self.filter {
            Filter::Nearest => {
                let p = (uv * size).floor();
                self.texel(p.x as i64, p.y as i64)
            }
            Filter::Bilinear => {
                let p = uv * size - 0.5;
                let p0 = p.floor();
                let f = p - p0;
                let (x, y) = (p0.x as i64, p0.y as i64);
                let top = self.texel(x, y) * (1.0 - f.x) + self.texel(x + 1, y) * f.x;
                let bottom = self.texel(x, y + 1) * (1.0 - f.x) + self.texel(x + 1, y + 1) * f.x;
                top * (1.0 - f.y) + bottom * f.y
            }
        }
    }

    /// The gradient of the luminance with respect to (u, v), as Mitsuba's `eval_1_grad` gives
    /// it (a bump map's slope): the derivative of the bilinear interpolant, zero under nearest
    /// filtering, and the texture's resolution applied after `to_uv`'s linear part (exact for
    /// the diagonal `to_uv` scenes use).
    pub fn gradient(&self, uv: Vec2) -> Vec2 {
        if self.filter == Filter::Nearest {
            return Vec2::ZERO;
        }
        let size = Vec2::new(self.width as f32, self.height as f32);
        let p = self.to_uv.transform_point2(uv) * size - 0.5;
        let p0 = p.floor();
        let w1 = p - p0;
        let w0 = Vec2::ONE - w1;
        let (x, y) = (p0.x as i64, p0.y as i64);
        let lum = |x, y| luminance(self.texel(x, y));
        let (f00, f10, f01, f11) = (lum(x, y), lum(x + 1, y), lum(x, y + 1), lum(x + 1, y + 1));
        let d = Vec2::new(
            w0.y * (f10 - f00) + w1.y * (f11 - f01),
            w0.x * (f01 - f00) + w1.x * (f11 - f10),
        );
        let m = self.to_uv.matrix2;
        size * Vec2::new(m.x_axis.dot(d), m.y_axis.dot(d))
    }
}

/// A texel index wrapped into 0..n.
pub(crate) fn wrap_index(i: i64, n: i64, mode: Wrap) -> i64 {
    match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::Clamp => i.clamp(0, n - 1),
        Wrap::Mirror => {
            let period = i.rem_euclid(2 * n);
            if period < n { period } else { 2 * n - 1 - period }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each level's value is the level's fraction of the top one, sRGB-decoded unless raw.
    #[test]
    fn levels_decode_as_srgb_decode() {
        fn check(srgb: &[f32], raw: &[f32]) {
            let levels = srgb.len();
            for i in 0..levels {
                let v = i as f32 / (levels - 1) as f32;
                assert_eq!(srgb[i].to_bits(), crate::color::srgb_decode(v).to_bits());
                assert_eq!(raw[i].to_bits(), v.to_bits());
            }
        }
        check(
            &*level_values::<{ 1 << 8 }>(true),
            &*level_values::<{ 1 << 8 }>(false),
        );
        check(
            &*level_values::<{ 1 << 16 }>(true),
            &*level_values::<{ 1 << 16 }>(false),
        );
    }

    /// 8- and 16-bit images keep their integer samples; each lookup decodes a texel to the
    /// value the table gives its levels, for grey and colour images, sRGB or raw.
    #[test]
    fn integer_images_give_their_levels_decoded() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (5u32, 3u32);
        let level = |x: u32, y: u32, c: u32| (x * 37 + y * 11 + c * 101) % 256;
        let rgb8 = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([0, 1, 2].map(|c| level(x, y, c) as u8)));
        let grey16 = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(w, h, |x, y| {
            image::Luma([(level(x, y, 0) * 257 + x) as u16])
        });
        let p8 = dir.path().join("rgb8.png");
        let p16 = dir.path().join("grey16.png");
        rgb8.save(&p8).unwrap();
        grey16.save(&p16).unwrap();
        for raw in [false, true] {
            let decode = |v: f32| if raw { v } else { crate::color::srgb_decode(v) };
            let load = |p| Bitmap::load(p, raw, Filter::Nearest, Wrap::Clamp, Affine2::IDENTITY).unwrap();
            let (b8, b16) = (load(&p8), load(&p16));
            for y in 0..h {
                for x in 0..w {
                    let uv = Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                    let want8 = Rgb::from_array([0, 1, 2].map(|c| decode(level(x, y, c) as f32 / 255.0)));
                    assert_eq!(
                        b8.eval(uv).to_array().map(f32::to_bits),
                        want8.to_array().map(f32::to_bits)
                    );
                    let g = decode(grey16.get_pixel(x, y)[0] as f32 / 65535.0);
                    assert_eq!(b16.eval(uv).to_array().map(f32::to_bits), [g.to_bits(); 3]);
                }
            }
            assert_eq!(b8.texels().len(), (w * h) as usize);
        }
    }

    fn two_by_one(filter: Filter, wrap: Wrap) -> Bitmap {
        Bitmap::from_texels(2, 1, vec![Rgb::ZERO, Rgb::ONE], filter, wrap, Affine2::IDENTITY)
    }

    #[test]
    fn texel_centres_hold_their_values_and_bilinear_blends_between() {
        let b = two_by_one(Filter::Bilinear, Wrap::Clamp);
        assert_eq!(b.eval(Vec2::new(0.25, 0.5)), Rgb::ZERO);
        assert_eq!(b.eval(Vec2::new(0.75, 0.5)), Rgb::ONE);
        assert!((b.eval(Vec2::new(0.5, 0.5)).x - 0.5).abs() < 1e-6);
        assert_eq!(b.eval(Vec2::new(0.0, 0.5)), Rgb::ZERO, "clamped at the edge");
        let r = two_by_one(Filter::Bilinear, Wrap::Repeat);
        assert!(
            (r.eval(Vec2::new(0.0, 0.5)).x - 0.5).abs() < 1e-6,
            "wraps to the far texel"
        );
        let n = two_by_one(Filter::Nearest, Wrap::Repeat);
        assert_eq!(n.eval(Vec2::new(0.49, 0.0)), Rgb::ZERO);
        assert_eq!(n.eval(Vec2::new(1.51, 0.0)), Rgb::ONE);
        assert!((b.mean().x - 0.5).abs() < 1e-6);
    }

    /// The gradient is the bilinear interpolant's: against central differences of `eval`
    /// inside a texel cell, through a scaling `to_uv` and over a repeated edge.
    #[test]
    fn the_gradient_is_the_interpolants_derivative() {
        let texels = [0.1, 0.7, 0.3, 0.9, 0.2, 0.5].map(Rgb::splat).to_vec();
        let to_uv = Affine2::from_scale(Vec2::new(2.0, 3.0));
        let b = Bitmap::from_texels(3, 2, texels, Filter::Bilinear, Wrap::Repeat, to_uv);
        let lum = |uv: Vec2| luminance(b.eval(uv)) as f64;
        for uv in [Vec2::new(0.07, 0.11), Vec2::new(0.31, 0.02), Vec2::new(0.49, 0.3)] {
            let h = 1e-3;
            let du = (lum(uv + Vec2::new(h, 0.0)) - lum(uv - Vec2::new(h, 0.0))) / (2.0 * h as f64);
            let dv = (lum(uv + Vec2::new(0.0, h)) - lum(uv - Vec2::new(0.0, h))) / (2.0 * h as f64);
            let g = b.gradient(uv);
            assert!(
                (g.x as f64 - du).abs() < 2e-2 * du.abs().max(1.0),
                "{uv}: {g} vs {du}"
            );
            assert!(
                (g.y as f64 - dv).abs() < 2e-2 * dv.abs().max(1.0),
                "{uv}: {g} vs {dv}"
            );
        }
        let n = two_by_one(Filter::Nearest, Wrap::Repeat);
        assert_eq!(n.gradient(Vec2::new(0.3, 0.5)), Vec2::ZERO);
    }

    #[test]
    fn wrap_modes() {
        assert_eq!(
            (-1..5)
                .map(|i| wrap_index(i, 2, Wrap::Repeat))
                .collect::<Vec<_>>(),
            [1, 0, 1, 0, 1, 0]
        );
        assert_eq!(
            (-1..5)
                .map(|i| wrap_index(i, 2, Wrap::Mirror))
                .collect::<Vec<_>>(),
            [0, 0, 1, 1, 0, 0]
        );
        assert_eq!(
            (-1..5).map(|i| wrap_index(i, 2, Wrap::Clamp)).collect::<Vec<_>>(),
            [0, 0, 1, 1, 1, 1]
        );
    }
}
