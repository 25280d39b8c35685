//! Mitsuba's `envmap`: radiance from every direction, read from an equirectangular image, and
//! sampled in proportion to its luminance.

use std::f32::consts::PI;

use glam::{Mat3A, Vec2, Vec3A};

use super::distant::SceneSphere;
use super::{EmittedPhoton, LightSample};
use crate::color::{Rgb, luminance};
use crate::engine::lanes::{F8, LANES};
use crate::engine::math;
use crate::sampling::Distribution1D;

/// An environment map.
#[derive(Clone, Debug)]
pub struct EnvmapLight {
    width: usize,
    height: usize,
    /// Linear radiance, `scale` applied, row by row from the top (v = 0, the +y pole).
    texels: Vec<Rgb>,
    to_world: Mat3A,
    to_local: Mat3A,
    /// Sampling cells: a cell spans one texel step in u and one row step in v, between the
    /// texel centres its radiance is interpolated from; (height − 1) rows of width cells.
    rows: Distribution1D,
    cols: Vec<Distribution1D>,
    /// ∫ luminance dω, for choosing lights by power.
    luminance_integral: f32,
    /// Set once the scene is built.
    pub sphere: SceneSphere,
}

/// `f` over `x` in groups of eight lanes, the last group padded with its last value.
///
/// Why lanes: a sample or a lookup takes two sines and cosines, or an arctangent and an arc
/// cosine; libm's take them one by one, through branches, and were 3% of the living room's
/// time. Ours ([`math`]) run eight at once in plain arithmetic, and give the same bits to a
/// scalar call, which is one lane of the same code.
fn in_lanes<const N: usize, T: Copy, U: Copy + Default>(
    x: [T; N],
    f: impl Fn([T; LANES]) -> [U; LANES],
) -> [U; N] {
    let mut out = [U::default(); N];
    for (group, chunk) in x.chunks(LANES).enumerate() {
        let got = f(std::array::from_fn(|i| chunk[i.min(chunk.len() - 1)]));
        out[group * LANES..group * LANES + chunk.len()].copy_from_slice(&got[..chunk.len()]);
    }
    out
}

/// Mitsuba's mapping of each (u, v), u and v in [0, 1], to a local direction (+y up, u = 0
/// towards −z, then +x), with the sine of its polar angle.
fn uv_to_direction_each<const N: usize>(uv: [Vec2; N]) -> [(Vec3A, f32); N] {
    in_lanes(uv, |uv| {
        let (sin_t, cos_t) = math::sincos_turn(F8::from_fn(|i| 0.5 * uv[i].y));
        let (sin_p, cos_p) = math::sincos_turn(F8::from_fn(|i| uv[i].x));
        let (x, z) = (sin_p * sin_t, -cos_p * sin_t);
        std::array::from_fn(|i| (Vec3A::new(x.0[i], cos_t.0[i], z.0[i]), sin_t.0[i]))
    })
}

/// Each local direction's (u, v): the inverse of [`uv_to_direction_each`].
fn direction_to_uv_each<const N: usize>(d: [Vec3A; N]) -> [Vec2; N] {
    in_lanes(d, |d| {
        let turns = math::atan2(F8::from_fn(|i| d[i].x), F8::from_fn(|i| -d[i].z)) * (0.5 / PI);
        let u = turns + turns.lt(F8::splat(0.0)).select(F8::splat(1.0), F8::splat(0.0));
        let v = math::acos(F8::from_fn(|i| d[i].y)) * std::f32::consts::FRAC_1_PI;
        std::array::from_fn(|i| Vec2::new(u.0[i], v.0[i]))
    })
}

impl EnvmapLight {
    /// From linear texels (row by row from the top), Mitsuba's `scale` and `to_world`.
    pub fn new(
        width: usize,
        height: usize,
        mut texels: Vec<Rgb>,
        scale: f32,
        to_world: Mat3A,
    ) -> EnvmapLight {
        assert!(width > 0 && height > 0 && texels.len() == width * height);
        let mut height = height;
        if height == 1 {
            // One row: both poles see it.
            texels.extend_from_within(..);
            height = 2;
        }
        for t in &mut texels {
            *t *= scale;
        }
        let lum = |x: usize, y: usize| luminance(texels[y * width + x % width]);
        let cell_solid_angle = (2.0 * PI / width as f32) * (PI / (height - 1) as f32);
        let mut row_weights = Vec::with_capacity(height - 1);
        let mut cols = Vec::with_capacity(height - 1);
        let mut integral = 0.0f64;
        for j in 0..height - 1 {
            let sin = libm::sinf(PI * (j as f32 + 0.5) / (height - 1) as f32);
            let w: Vec<f32> = (0..width)
                .map(|i| 0.25 * (lum(i, j) + lum(i + 1, j) + lum(i, j + 1) + lum(i + 1, j + 1)) * sin)
                .collect();
            let sum: f64 = w.iter().map(|&x| x as f64).sum();
            integral += sum * cell_solid_angle as f64;
            row_weights.push(sum as f32);
            cols.push(Distribution1D::new(&w));
        }
        EnvmapLight {
            width,
            height,
            texels,
            to_world,
            to_local: to_world.inverse(),
            rows: Distribution1D::new(&row_weights),
            cols,
            luminance_integral: integral as f32,
            sphere: SceneSphere::default(),
        }
    }

    fn texel(&self, x: i64, y: i64) -> Rgb {
        let x = x.rem_euclid(self.width as i64) as usize;
        let y = y.clamp(0, self.height as i64 - 1) as usize;
        self.texels[y * self.width + x]
    }

    /// Radiance arriving from world direction `wi` (pointing away from the scene).
    pub fn eval(&self, wi: Vec3A) -> Rgb {
        self.eval_each([Some(wi)])[0]
    }

    /// Where each world direction given falls: its local direction and its (u, v) in the map.
    fn place_each<const N: usize>(&self, wi: [Option<Vec3A>; N]) -> [Option<(Vec3A, Vec2)>; N] {
        let d = wi.map(|wi| wi.map_or(Vec3A::ZERO, |wi| (self.to_local * wi).normalize_or_zero()));
        let uv = direction_to_uv_each(d);
        std::array::from_fn(|l| wi[l].map(|_| (d[l], uv[l])))
    }

    /// [`EnvmapLight::eval`] of each direction given (black for none).
    fn eval_each<const N: usize>(&self, wi: [Option<Vec3A>; N]) -> [Rgb; N] {
        self.lookup_each(self.place_each(wi).map(|p| p.map(|(_, uv)| uv)))
    }

    /// The radiance at each (u, v) given (black for none), every lookup's place found before
    /// any texel is read, so that the texels' cache misses overlap.
    fn lookup_each<const N: usize>(&self, uv: [Option<Vec2>; N]) -> [Rgb; N] {
        let at = uv.map(|uv| {
            uv.map(|uv| {
                // Mitsuba's lookup: texel-centred and periodic in u, "align corners" in v
                // (row 0 is exactly the pole).
                let x = uv.x * self.width as f32 - 0.5;
                let y = uv.y * (self.height - 1) as f32;
                let (x0, y0) = (x.floor(), y.floor());
                (x0 as i64, y0 as i64, x - x0, y - y0)
            })
        });
        at.map(|at| {
            at.map_or(Rgb::ZERO, |(x0, y0, fx, fy)| {
                let top = self.texel(x0, y0) * (1.0 - fx) + self.texel(x0 + 1, y0) * fx;
                let bottom = self.texel(x0, y0 + 1) * (1.0 - fx) + self.texel(x0 + 1, y0 + 1) * fx;
                top * (1.0 - fy) + bottom * fy
            })
        })
    }

    /// Density per unit solid angle of sampling world direction `wi`.
    pub fn pdf(&self, wi: Vec3A) -> f32 {
        self.place_each([Some(wi)])[0].map_or(0.0, |p| self.pdf_at(p))
    }

    /// [`EnvmapLight::pdf`] of a direction placed by [`EnvmapLight::place_each`].
    fn pdf_at(&self, (d, uv): (Vec3A, Vec2)) -> f32 {
        let sin = (d.x * d.x + d.z * d.z).sqrt();
        if sin <= 0.0 || self.rows.is_empty() {
            return 0.0;
        }
        let x = (uv.x * self.width as f32 - 0.5).rem_euclid(self.width as f32);
        let y = uv.y * (self.height - 1) as f32;
        let i = (x as usize).min(self.width - 1);
        let j = (y as usize).min(self.height - 2);
        let pdf_uv = self.rows.pmf(j) * self.cols[j].pmf(i) * (self.width * (self.height - 1)) as f32;
        pdf_uv / (2.0 * PI * PI * sin)
    }

    /// [`EnvmapLight::eval`] and [`EnvmapLight::pdf`] of each direction given (zeros for
    /// none): each direction placed once for both, and every table read after every place is
    /// found, so that the cache misses overlap.
    pub(super) fn eval_pdf_each<const N: usize>(&self, wi: [Option<Vec3A>; N]) -> [(Rgb, f32); N] {
        let places = self.place_each(wi);
        let radiance = self.lookup_each(places.map(|p| p.map(|(_, uv)| uv)));
        let pdf = places.map(|p| p.map_or(0.0, |p| self.pdf_at(p)));
        std::array::from_fn(|l| (radiance[l], pdf[l]))
    }

    /// A direction towards the map, its radiance and its density per unit solid angle.
    fn sample(&self, u: Vec2) -> Option<(Vec3A, Rgb, f32)> {
        self.sample_each([Some(u)])[0]
    }

    /// [`EnvmapLight::sample`] of each `u` given, step by step over all of them: the row
    /// and the column of every sample ([`Distribution1D::sample_each`]), then every
    /// direction, then every radiance ([`EnvmapLight::eval_each`]). Each step's cache misses
    /// then overlap; one sample after the other, each waits for its chain of three.
    fn sample_each<const N: usize>(&self, u: [Option<Vec2>; N]) -> [Option<(Vec3A, Rgb, f32)>; N] {
        if self.rows.is_empty() {
            return [None; N];
        }
        let at = u.map(|u| u.unwrap_or(Vec2::ZERO));
        let rows = Distribution1D::sample_each([&self.rows; N], at.map(|u| u.y));
        let cols =
            Distribution1D::sample_each(std::array::from_fn(|l| &self.cols[rows[l].0]), at.map(|u| u.x));
        let uv: [Vec2; N] = std::array::from_fn(|l| {
            let ((j, _, uy), (i, _, ux)) = (rows[l], cols[l]);
            let x = i as f32 + ux;
            let y = j as f32 + uy;
            Vec2::new(
                ((x + 0.5) / self.width as f32).fract(),
                y / (self.height - 1) as f32,
            )
        });
        let local = uv_to_direction_each(uv);
        let dirs: [Option<(Vec3A, f32)>; N] = std::array::from_fn(|l| {
            u[l]?;
            let ((_, pj, _), (_, pi, _), (d, sin)) = (rows[l], cols[l], local[l]);
            if sin <= 0.0 {
                return None;
            }
            let pdf = pj * pi * (self.width * (self.height - 1)) as f32 / (2.0 * PI * PI * sin);
            Some(((self.to_world * d).normalize(), pdf))
        });
        let radiance = self.eval_each(dirs.map(|d| d.map(|(wi, _)| wi)));
        std::array::from_fn(|l| {
            let (wi, pdf) = dirs[l]?;
            (pdf > 0.0).then_some((wi, radiance[l], pdf))
        })
    }

    /// Light samples from each point `p[l]` with `u[l]`, where given: [`Light::sample_li`]'s,
    /// several at once ([`EnvmapLight::sample_each`]).
    ///
    /// [`Light::sample_li`]: super::Light::sample_li
    pub(super) fn sample_li_each<const N: usize>(
        &self,
        p: [Vec3A; N],
        u: [Option<Vec2>; N],
    ) -> [Option<LightSample>; N] {
        let s = self.sample_each(u);
        std::array::from_fn(|l| {
            let (wi, radiance, pdf) = s[l]?;
            Some(self.sphere.sample_towards(p[l], wi, radiance, pdf, false))
        })
    }

    pub(super) fn sample_li(&self, p: Vec3A, u: Vec2) -> Option<LightSample> {
        self.sample_li_each([p], [Some(u)])[0]
    }

    pub(super) fn sample_emission(&self, u_pos: Vec2, u_dir: Vec2) -> Option<EmittedPhoton> {
        let (wi, radiance, pdf) = self.sample(u_dir)?;
        Some(self.sphere.photon(-wi, u_pos, radiance / pdf))
    }

    pub(super) fn power(&self) -> f32 {
        self.luminance_integral * self.sphere.disk_area()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uv_to_direction(uv: Vec2) -> Vec3A {
        uv_to_direction_each([uv])[0].0
    }

    fn direction_to_uv(d: Vec3A) -> Vec2 {
        direction_to_uv_each([d])[0]
    }

    fn map() -> EnvmapLight {
        // 8 x 5 texels with a bright spot, rotated.
        let (w, h) = (8, 5);
        let texels = (0..w * h)
            .map(|k| {
                if k == 2 * w + 5 {
                    Rgb::new(40.0, 30.0, 20.0)
                } else {
                    Rgb::new(0.2, 0.3, 0.5)
                }
            })
            .collect();
        EnvmapLight::new(w, h, texels, 1.5, Mat3A::from_rotation_y(0.7))
    }

    #[test]
    fn mapping_round_trips_and_has_mitsubas_axes() {
        assert!((uv_to_direction(Vec2::new(0.0, 0.5)) - Vec3A::new(0.0, 0.0, -1.0)).length() < 1e-6);
        assert!((uv_to_direction(Vec2::new(0.25, 0.5)) - Vec3A::X).length() < 1e-6);
        assert!((uv_to_direction(Vec2::new(0.3, 0.0)) - Vec3A::Y).length() < 1e-6);
        for uv in [Vec2::new(0.1, 0.2), Vec2::new(0.8, 0.9), Vec2::new(0.5, 0.5)] {
            assert!((direction_to_uv(uv_to_direction(uv)) - uv).length() < 1e-5);
        }
    }

    #[test]
    fn sampling_density_matches_pdf_and_integrates_to_one() {
        let m = map();
        let mut s = crate::sampling::Sampler::new(1, crate::sampling::Stream::Camera, 0, 0);
        // E[L / pdf] over samples = ∫ L dω, against a fine quadrature of eval.
        let n = 200_000;
        let mut est = Rgb::ZERO;
        for _ in 0..n {
            let (wi, l, pdf) = m.sample(s.next_2d()).unwrap();
            assert!((m.pdf(wi) - pdf).abs() <= 1e-3 * pdf, "{} vs {pdf}", m.pdf(wi));
            est += l / pdf;
        }
        est /= n as f32;
        let (nu, nv) = (800, 400);
        let mut quad = Rgb::ZERO;
        let mut pdf_sum = 0.0f64;
        for a in 0..nu {
            for b in 0..nv {
                let uv = Vec2::new((a as f32 + 0.5) / nu as f32, (b as f32 + 0.5) / nv as f32);
                let d = m.to_world * uv_to_direction(uv);
                let dw = 2.0 * PI * PI * libm::sinf(PI * uv.y) / (nu * nv) as f32;
                quad += m.eval(d) * dw;
                pdf_sum += (m.pdf(d) * dw) as f64;
            }
        }
        assert!((pdf_sum - 1.0).abs() < 2e-3, "pdf integrates to {pdf_sum}");
        assert!(
            ((est - quad) / quad).abs().max_element() < 0.01,
            "{est} vs {quad}"
        );
    }
}
