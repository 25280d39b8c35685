//! Textures: colours and numbers that vary over a surface, looked up by its (u, v) coordinates
//! or, for Mitsuba's `mesh_attribute`, by a value the mesh carries at its vertices or faces.
//!
//! A material parameter is a [`Param`]: a fixed value, which costs a scene nothing beyond a
//! branch, or a texture. Textures are evaluated where a BSDF needs the value, as Mitsuba does,
//! so that every BSDF sees the same parameters whichever integrator calls it.

mod bitmap;
mod texels;

use std::sync::Arc;

use glam::{Affine2, Vec2};

pub(crate) use bitmap::wrap_index;
pub use bitmap::{Bitmap, BitmapError, Filter, Wrap};

use crate::color::{Rgb, luminance};

/// A texture.
#[derive(Clone, Debug)]
pub enum Texture {
    /// An image (Mitsuba's `bitmap`).
    Bitmap(Bitmap),
    /// A mesh's vertex or face attribute (Mitsuba's `mesh_attribute`), times `scale`. The
    /// scene builder bakes the named attribute into the triangles of each mesh whose material
    /// reads it, so a lookup is the interpolated value already in [`TexAt::attr`].
    Attribute {
        /// The attribute's name, `vertex_…` or `face_…`.
        name: String,
        /// Mitsuba's `scale`.
        scale: f32,
    },
    /// One value everywhere, taken as given (Mitsuba's `rawconstant`: no reflectance range and no
    /// spectral upsampling, as for a normal map's (0.5, 0.5, 1)).
    Constant(Rgb),
    /// Two colours in a 2 × 2 checkerboard over the unit square (Mitsuba's `checkerboard`).
    Checkerboard {
        /// The colour where ⌊2u⌋ + ⌊2v⌋ is even.
        color0: Rgb,
        /// The other colour.
        color1: Rgb,
        /// Applied to (u, v) first.
        to_uv: Affine2,
    },
}

/// Where a texture is looked up: the surface's (u, v), and the value of the mesh attribute its
/// material reads there (zero where there is none).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TexAt {
    /// Texture coordinates.
    pub uv: Vec2,
    /// The interpolated mesh attribute (a one-channel attribute in every channel).
    pub attr: Rgb,
}

impl From<Vec2> for TexAt {
    fn from(uv: Vec2) -> TexAt {
        TexAt { uv, attr: Rgb::ZERO }
    }
}

impl From<&TexAt> for TexAt {
    #[inline]
    fn from(at: &TexAt) -> TexAt {
        *at
    }
}

impl Texture {
    /// The colour at `at`.
    pub fn eval(&self, at: TexAt) -> Rgb {
        let uv = at.uv;
        match self {
            Texture::Bitmap(b) => b.eval(uv),
            Texture::Attribute { scale, .. } => at.attr * *scale,
            Texture::Constant(v) => *v,
            Texture::Checkerboard {
                color0,
                color1,
                to_uv,
            } => {
                let p = to_uv.transform_point2(uv);
                let a = p.x - p.x.floor() > 0.5;
                let b = p.y - p.y.floor() > 0.5;
                if a == b { *color0 } else { *color1 }
            }
        }
    }

    /// The value at `uv` of a texture used as a number (roughness, a blend weight, opacity), as
    /// Mitsuba's `eval_1` gives it: a bitmap's luminance; for a checkerboard the mean of the
    /// colour's channels, with the two colours swapped (Mitsuba 3 swaps them in `eval_1`, and
    /// scenes such as its textured carbon fibre are rendered that way).
    /// An attribute gives its first channel: a one-channel attribute's value, as Mitsuba's
    /// `eval_1` does (Mitsuba refuses a three-channel one there).
    pub fn eval_float(&self, at: TexAt) -> f32 {
        match self {
            Texture::Bitmap(b) => luminance(b.eval(at.uv)),
            Texture::Attribute { scale, .. } => at.attr.x * *scale,
            // Mitsuba's eval_1 of a one-value rawconstant (it refuses three values there).
            Texture::Constant(v) => v.x,
            Texture::Checkerboard { color0, color1, .. } => {
                let first = self.eval(at) == *color0;
                crate::color::mean(if first { *color1 } else { *color0 })
            }
        }
    }

    /// The mean as Mitsuba's `mean()` gives it (BSDFs choose lobe probabilities from it): a
    /// bitmap's mean luminance, a checkerboard's mean of its colours' channel means. Mitsuba
    /// has none for an attribute, and the scene builder refuses it where a mean is needed.
    pub fn mean(&self) -> f32 {
        match self {
            Texture::Bitmap(b) => luminance(b.mean()),
            Texture::Attribute { .. } => 0.0,
            Texture::Constant(v) => crate::color::mean(*v),
            Texture::Checkerboard { color0, color1, .. } => {
                0.5 * (crate::color::mean(*color0) + crate::color::mean(*color1))
            }
        }
    }

    /// The mesh attribute this texture reads, if it is one.
    pub fn attribute(&self) -> Option<&str> {
        match self {
            Texture::Attribute { name, .. } => Some(name),
            _ => None,
        }
    }
}

/// A material parameter: fixed, or read from a texture at the surface's (u, v).
#[derive(Clone, Debug)]
pub enum Param<T> {
    /// The same everywhere.
    Fixed(T),
    /// From a texture.
    Textured(Arc<Texture>),
}

impl<T> From<T> for Param<T> {
    fn from(v: T) -> Self {
        Param::Fixed(v)
    }
}

impl Param<Rgb> {
    /// The colour at `at` (a [`TexAt`], or just (u, v)).
    #[inline]
    pub fn at(&self, at: impl Into<TexAt>) -> Rgb {
        match self {
            Param::Fixed(v) => *v,
            Param::Textured(t) => t.eval(at.into()),
        }
    }

    /// Mitsuba's `mean()`: the mean of a fixed colour's channels, or the texture's mean.
    pub fn mean(&self) -> f32 {
        match self {
            Param::Fixed(v) => crate::color::mean(*v),
            Param::Textured(t) => t.mean(),
        }
    }

    /// A light's weight for choosing it: a fixed colour's luminance, a texture's mean.
    pub fn light_weight(&self) -> f32 {
        match self {
            Param::Fixed(v) => luminance(*v),
            Param::Textured(t) => t.mean(),
        }
    }
}

impl Param<f32> {
    /// The number at `at` (a [`TexAt`], or just (u, v)).
    #[inline]
    pub fn at(&self, at: impl Into<TexAt>) -> f32 {
        match self {
            Param::Fixed(v) => *v,
            Param::Textured(t) => t.eval_float(at.into()),
        }
    }
}
