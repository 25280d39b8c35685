//! The lane engine (issue 27; design in docs/engine.md): paths traced eight at a time, one per
//! lane, in arithmetic that gives the same bits on every instruction set.
//!
//! [`path`] path-traces scenes made mostly of Lambertian and GGX rough plastic
//! triangles ([`plastic`]), under any lights, on the lane types ([`lanes`]) and our own
//! transcendentals ([`math`]); the design's speed is measured by `cargo bench -p
//! photonfarm-common --bench engine`. The path tracer hands it the scenes it models
//! (`render::Renderer`).

pub mod lanes;
pub mod math;
pub mod path;
mod plastic;

use std::fmt;

/// An instruction set the lane kernels are compiled for, picked at run time
/// (`PHOTONFARM_SIMD`). Every one gives the same bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// x86-64's baseline: two SSE2 registers per lane group.
    Sse2,
    /// AVX2 (x86-64-v3): one register per lane group.
    Avx2,
    /// AVX-512 (x86-64-v4).
    Avx512,
}

/// `PHOTONFARM_SIMD` names no backend, or one this machine lacks.
#[derive(Debug, thiserror::Error)]
#[error("PHOTONFARM_SIMD={given}: {why} (this machine has: {})", Backend::names(&Backend::available()))]
pub struct BackendError {
    given: String,
    why: &'static str,
}

impl Backend {
    /// Every backend, narrowest first.
    pub const ALL: [Backend; 3] = [Backend::Sse2, Backend::Avx2, Backend::Avx512];

    /// Its name in `PHOTONFARM_SIMD`.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Sse2 => "sse2",
            Backend::Avx2 => "avx2",
            Backend::Avx512 => "avx512",
        }
    }

    fn names(list: &[Backend]) -> String {
        list.iter().map(|b| b.name()).collect::<Vec<_>>().join(", ")
    }

    /// Whether this machine can run it.
    pub fn is_available(self) -> bool {
        match self {
            Backend::Sse2 => true,
            Backend::Avx2 => pulp::x86::V3::try_new().is_some(),
            Backend::Avx512 => pulp::x86::V4::try_new().is_some(),
        }
    }

    /// The backends this machine can run, narrowest first.
    pub fn available() -> Vec<Backend> {
        Backend::ALL.into_iter().filter(|b| b.is_available()).collect()
    }

    /// The fastest backend this machine runs: AVX2 where it has it. AVX-512 at eight lanes
    /// measured slower than AVX2 on the whole path (docs/engine.md: 1.43–1.50× the scalar
    /// tracer against 1.55–1.58×), so it runs only when pinned.
    pub fn best() -> Backend {
        if Backend::Avx2.is_available() {
            Backend::Avx2
        } else {
            Backend::Sse2
        }
    }

    /// The backend `PHOTONFARM_SIMD` pins, or the best one when it is unset or empty.
    /// Binaries call it at start, so that a bad value is an error before any work.
    pub fn from_env() -> Result<Backend, BackendError> {
        match std::env::var("PHOTONFARM_SIMD") {
            Ok(v) if !v.is_empty() => v.parse(),
            _ => Ok(Backend::best()),
        }
    }

    /// The process's backend: [`Backend::from_env`]'s, read once (the best one if the variable
    /// is invalid: binaries have refused that already).
    pub fn current() -> Backend {
        static CURRENT: std::sync::OnceLock<Backend> = std::sync::OnceLock::new();
        *CURRENT.get_or_init(|| Backend::from_env().unwrap_or_else(|_| Backend::best()))
    }

    /// Runs `op` compiled for this backend's instruction set. Panics if the machine lacks it
    /// (callers pick from [`Backend::available`] or [`Backend::from_env`]).
    #[inline(always)]
    pub fn run<Op: pulp::WithSimd>(self, op: Op) -> Op::Output {
        use pulp::Simd;
        let missing = || -> ! { panic!("the {} backend is not available on this machine", self.name()) };
        match self {
            Backend::Sse2 => Simd::vectorize(pulp::Scalar::new(), op),
            Backend::Avx2 => match pulp::x86::V3::try_new() {
                Some(simd) => Simd::vectorize(simd, op),
                None => missing(),
            },
            Backend::Avx512 => match pulp::x86::V4::try_new() {
                Some(simd) => Simd::vectorize(simd, op),
                None => missing(),
            },
        }
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Backend {
    type Err = BackendError;

    fn from_str(s: &str) -> Result<Backend, BackendError> {
        let error = |why| BackendError {
            given: s.to_string(),
            why,
        };
        let b = Backend::ALL
            .into_iter()
            .find(|b| b.name() == s)
            .ok_or_else(|| error("not one of sse2, avx2, avx512"))?;
        if b.is_available() {
            Ok(b)
        } else {
            Err(error("this CPU lacks it"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backends_parse_by_name_and_refuse_others() {
        assert_eq!("sse2".parse::<Backend>().unwrap(), Backend::Sse2);
        let e = "neon".parse::<Backend>().unwrap_err().to_string();
        assert!(
            e.contains("PHOTONFARM_SIMD=neon: not one of sse2, avx2, avx512"),
            "{e}"
        );
        assert!(e.contains("this machine has: sse2"), "{e}");
    }
}
