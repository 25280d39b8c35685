//! Admission control: every size a request can imply, checked before anything is stored or
//! allocated for it, against limits the operator sets (`coordinator serve` flags) with
//! defaults derived from the machine's memory.
//!
//! Why here and not deeper: a job that is stored is reloaded at every start, and an upload
//! that is read is in memory. So the coordinator refuses, with a 4xx naming the limit, before
//! either: the upload by its length (and the lease's expected size for results), the bundle
//! by its file count and unpacked bytes, the geometry by its files' bytes before the scene is
//! loaded, and the job by its film, passes and photons once the scene is loaded.

use photonfarm::bundle::UnpackLimits;
use photonfarm::limits::Limits;

use crate::serving::ServingLimits;

/// The coordinator's limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Admission {
    /// Film pixels, passes and photons of one job.
    pub job: Limits,
    /// Largest request body: a bundle upload (a batch result is also held to its lease's
    /// size), bytes.
    pub max_upload: u64,
    /// Files and unpacked bytes of one bundle.
    pub bundle: UnpackLimits,
    /// Bytes of a bundle's files (the scene and its meshes). Loading a mesh takes up to ~30
    /// times its file's size, so this bounds what checking a scene can take.
    pub max_geometry: u64,
    /// Uploads (bundles and batch results) read at the same time: each is held in memory
    /// or on disk while it is checked, so this bounds their sum.
    pub max_uploads: usize,
    /// Scenes loaded at the same time to check a submission.
    pub max_scene_checks: usize,
    /// Connections, their timeouts and the body timeout (as for a relay).
    pub serving: ServingLimits,
    /// Seconds a submitted scene may take to load and check.
    pub scene_check_timeout_s: u64,
}

impl Admission {
    /// Defaults for a machine with `memory` bytes.
    pub fn for_memory(memory: u64) -> Admission {
        Admission {
            job: Limits::for_memory(memory),
            max_upload: 512 << 20,
            bundle: UnpackLimits {
                max_files: 10_000,
                max_bytes: (memory / 16).clamp(64 << 20, 8 << 30),
            },
            max_geometry: (memory / 128).clamp(16 << 20, 4 << 30),
            max_uploads: 4,
            max_scene_checks: 2,
            serving: ServingLimits::default(),
            scene_check_timeout_s: 120,
        }
    }

    /// Defaults for this machine.
    pub fn for_this_machine() -> Admission {
        Admission::for_memory(photonfarm::limits::machine_memory())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_follow_memory_within_bounds() {
        let small = Admission::for_memory(1 << 30);
        let big = Admission::for_memory(64 << 30);
        assert!(small.max_geometry < big.max_geometry);
        assert!(small.job.max_pixels <= big.job.max_pixels);
        assert_eq!(small.max_geometry, 16 << 20);
        assert_eq!(big.bundle.max_bytes, 4 << 30);
    }
}
