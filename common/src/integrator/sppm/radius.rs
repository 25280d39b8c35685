//! Knaus and Zwicker's radius schedule: a function of the iteration index alone.
//!
//! r_i² = r_1² · Π_{j=1}^{i-1} (j + α) / (j + 1) for surfaces (and the same for r_i³ in
//! volumes). The product is evaluated in f64, one factor at a time in a fixed order, so every
//! machine computes the same bits; the farm's coordinator computes it once anyway and sends
//! the radii with each batch.

/// The schedule of one render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RadiusSchedule {
    /// Radius of the first iteration (index 0).
    pub initial: f64,
    /// Knaus and Zwicker's α in (0, 1): the fraction of new photons kept.
    pub alpha: f64,
    /// 2 for surfaces (the area r² shrinks), 3 for volumes (r³ shrinks).
    pub dimension: u32,
}

impl RadiusSchedule {
    /// Radii of iterations `range` (0-based: iteration 0 has the initial radius).
    pub fn radii(&self, range: std::ops::Range<u64>) -> Vec<f32> {
        let mut measure = 1.0f64; // r_i^d / r_1^d
        let mut out = Vec::with_capacity((range.end - range.start) as usize);
        for i in 0..range.end {
            if i >= range.start {
                out.push((self.initial * libm::pow(measure, 1.0 / self.dimension as f64)) as f32);
            }
            // From iteration i (1-based j = i + 1) to the next.
            let j = (i + 1) as f64;
            measure *= (j + self.alpha) / (j + 1.0);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_the_recurrence_and_depends_on_the_index_only() {
        let s = RadiusSchedule {
            initial: 0.1,
            alpha: 2.0 / 3.0,
            dimension: 2,
        };
        let all = s.radii(0..100);
        assert_eq!(all[0], 0.1);
        for i in 1..100usize {
            let expect = (all[i - 1] as f64).powi(2) * (i as f64 + s.alpha) / (i as f64 + 1.0);
            assert!(((all[i] as f64).powi(2) - expect).abs() < 1e-8);
        }
        assert_eq!(s.radii(40..60), all[40..60].to_vec());
        // r² ~ i^(α-1) for large i.
        let big = s.radii(100_000..100_001)[0] as f64;
        let ratio = big.powi(2) / s.radii(10_000..10_001)[0].powi(2) as f64;
        assert!((ratio - libm::pow(10f64, s.alpha - 1.0)).abs() < 0.01, "{ratio}");
    }
}
