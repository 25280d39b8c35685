//! Linear RGB colour, the only colour model: no spectral rendering (no scene of ours needs it).

use glam::Vec3A;

/// A linear RGB triple (radiance, reflectance or a path throughput).
pub type Rgb = Vec3A;

/// Rec. 709 luminance: the scalar used to compare light powers and for Russian roulette.
pub fn luminance(c: Rgb) -> f32 {
    0.212_671 * c.x + 0.715_160 * c.y + 0.072_169 * c.z
}

/// Mean of the three channels (Mitsuba uses it for sampling weights).
pub fn mean(c: Rgb) -> f32 {
    (c.x + c.y + c.z) / 3.0
}

/// The sRGB transfer function, for 8-bit output.
pub fn srgb_encode(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * libm::powf(v, 1.0 / 2.4) - 0.055
    }
}

/// The inverse of [`srgb_encode`]: an sRGB-encoded value to linear.
pub fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        libm::powf((v + 0.055) / 1.055, 2.4)
    }
}
