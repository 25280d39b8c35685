//! Admission limits: the largest job a process agrees to hold in memory.
//!
//! Why: every size a job implies (film pixels, passes, photons per pass) turns into an
//! allocation somewhere, in the coordinator (the exact sums), in `coordinator render`, or in
//! every worker that takes a batch. A scene of 700 bytes can ask for a 100 GB film; checking
//! the sizes before anything is allocated or stored is what keeps one bad job from taking a
//! process (or, once stored, every restart of it) down. The coordinator, `coordinator render`
//! and the worker run the same [`Limits::check_job`], each with limits derived from its own
//! machine's memory unless the operator sets them.

use crate::render::{Method, RenderSettings};

/// Bytes the exact sums take per pixel at most (three i64 channels, and an i64 weight when the
/// film's filter is wider than a box).
pub const SUM_BYTES_PER_PIXEL: u64 = 32;

/// Upper bounds on what one job may ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Film width × height.
    pub max_pixels: u64,
    /// Passes (samples per pixel or SPPM iterations) of one job.
    pub max_passes: u64,
    /// SPPM photons per iteration.
    pub max_photons: u64,
}

/// Why a job was refused: names the limit, the value asked for and how to change it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} is {value}, above the limit of {limit} ({setting})")]
pub struct LimitError {
    /// The size that is too large.
    pub what: &'static str,
    /// What the job asked for.
    pub value: u64,
    /// The limit.
    pub limit: u64,
    /// The setting that raises it.
    pub setting: &'static str,
}

/// Total memory of this machine in bytes, from /proc/meminfo (4 GiB when unknown).
pub fn machine_memory() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("MemTotal:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        })
        .map_or(4 << 30, |kb| kb * 1024)
}

impl Limits {
    /// Limits for a machine with `memory` bytes.
    ///
    /// A film costs up to 32 B per pixel in every sum held (the coordinator may hold a prefix, a few
    /// pending batches and a checkpoint copy at once, and a worker a sum per batch and its
    /// pass), so pixels are capped at memory / 512: 47 Mpx on 24 GiB, never below 1 Mpx.
    /// A photon costs about 100 B over its stored bounces and the photon map: memory / 256.
    /// Passes cost no memory (the radius schedule is computed per batch), only time; ten
    /// million is far beyond any useful render.
    pub fn for_memory(memory: u64) -> Limits {
        Limits {
            max_pixels: (memory / 512).clamp(1 << 20, 1 << 28),
            max_passes: 10_000_000,
            max_photons: (memory / 256).clamp(1 << 20, 1 << 32),
        }
    }

    /// Limits for this machine.
    pub fn for_this_machine() -> Limits {
        Limits::for_memory(machine_memory())
    }

    /// Checks a job's sizes: `passes` is None for an open-ended (time-limited) render.
    pub fn check_job(
        &self,
        width: u32,
        height: u32,
        passes: Option<u64>,
        render: &RenderSettings,
    ) -> Result<(), LimitError> {
        let pixels = width as u64 * height as u64;
        check("the film's pixel count", pixels, self.max_pixels, "--max-pixels")?;
        if let Some(p) = passes {
            check("the pass count", p, self.max_passes, "--max-passes")?;
        }
        if let Method::Sppm(s) = &render.method {
            check(
                "the photon count per iteration",
                s.photons,
                self.max_photons,
                "--max-photons",
            )?;
        }
        Ok(())
    }
}

fn check(what: &'static str, value: u64, limit: u64, setting: &'static str) -> Result<(), LimitError> {
    if value > limit {
        return Err(LimitError {
            what,
            value,
            limit,
            setting,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::path::PathSettings;

    #[test]
    fn refuses_what_is_above_and_names_the_limit() {
        let l = Limits::for_memory(24 << 30);
        assert_eq!(l.max_pixels, (24u64 << 30) / 512);
        let render = RenderSettings {
            seed: 0,
            method: Method::Path(PathSettings {
                max_depth: None,
                rr_depth: 5,
            }),
        };
        assert!(l.check_job(1920, 1080, Some(1024), &render).is_ok());
        let e = l.check_job(65536, 65536, Some(1), &render).unwrap_err();
        assert_eq!(e.value, 1 << 32);
        assert!(e.to_string().contains("--max-pixels"), "{e}");
        let e = l.check_job(8, 8, Some(1_000_000_000_000), &render).unwrap_err();
        assert!(e.to_string().contains("pass count"), "{e}");
        assert!(machine_memory() > 0);
        assert_eq!(Limits::for_memory(0).max_pixels, 1 << 20);
    }
}
