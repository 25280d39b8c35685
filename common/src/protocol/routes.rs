//! The farm's routes, spelled once. The coordinator's and the relay's routers take the
//! patterns; every client (submit and the job commands, the worker, the relay going upstream,
//! loadgen) builds its paths with the functions beside them, so a route renamed on one side
//! cannot be missed on the other.

use std::fmt::Display;

/// Liveness.
pub const HEALTH: &str = "/healthz";
/// Prometheus metrics.
pub const METRICS: &str = "/metrics";
/// Submit (POST) and list (GET) jobs.
pub const JOBS: &str = "/api/jobs";
/// A job's status (GET) and cancel (DELETE).
pub const JOB: &str = "/api/jobs/{id}";
/// A job's noise estimates.
pub const JOB_NOISE: &str = "/api/jobs/{id}/noise";
/// A job's latest image (`image.exr`, `image.png`).
pub const JOB_FILE: &str = "/api/jobs/{id}/{file}";
/// The workers seen lately.
pub const WORKERS: &str = "/api/workers";
/// A job bundle, by hash.
pub const BUNDLE: &str = "/api/bundles/{hash}";
/// Ask for a batch.
pub const LEASE: &str = "/api/lease";
/// Extend a lease.
pub const HEARTBEAT: &str = "/api/leases/{id}/heartbeat";
/// Deliver a lease's result.
pub const RESULT: &str = "/api/leases/{id}/result";
/// Give a lease back.
pub const RELEASE: &str = "/api/leases/{id}/release";

/// Whether `path` is one of the workers' routes (the workers' token is asked of these).
pub fn is_workers(path: &str) -> bool {
    path == LEASE || path.starts_with(prefix(HEARTBEAT)) || path.starts_with(prefix(BUNDLE))
}

/// A pattern's part before its first parameter.
fn prefix(pattern: &str) -> &str {
    pattern.split('{').next().unwrap_or(pattern)
}

/// `pattern` with its `{...}` parameters replaced by `values`, in order.
fn fill(pattern: &str, values: &[&dyn Display]) -> String {
    let mut out = String::with_capacity(pattern.len() + 16);
    let mut values = values.iter();
    let mut rest = pattern;
    while let Some(open) = rest.find('{') {
        let close = rest[open..].find('}').map_or(rest.len(), |c| open + c + 1);
        out.push_str(&rest[..open]);
        if let Some(v) = values.next() {
            out.push_str(&v.to_string());
        }
        rest = &rest[close..];
    }
    out.push_str(rest);
    out
}

/// [`JOB`] of job `id`.
pub fn job(id: u64) -> String {
    fill(JOB, &[&id])
}

/// [`JOB_FILE`]: `file` of job `id`.
pub fn job_file(id: u64, file: &str) -> String {
    fill(JOB_FILE, &[&id, &file])
}

/// [`BUNDLE`] of `hash`.
pub fn bundle(hash: &str) -> String {
    fill(BUNDLE, &[&hash])
}

/// [`LEASE`], waiting up to `wait_ms` for work (0: answer at once).
pub fn lease(wait_ms: u64) -> String {
    if wait_ms == 0 {
        LEASE.to_string()
    } else {
        format!("{LEASE}?wait_ms={wait_ms}")
    }
}

/// [`HEARTBEAT`] of lease `id`.
pub fn heartbeat(id: u64) -> String {
    fill(HEARTBEAT, &[&id])
}

/// [`RESULT`] of lease `id`.
pub fn result(id: u64) -> String {
    fill(RESULT, &[&id])
}

/// [`RELEASE`] of lease `id`.
pub fn release(id: u64) -> String {
    fill(RELEASE, &[&id])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_fill_their_patterns() {
        assert_eq!(job(7), "/api/jobs/7");
        assert_eq!(job_file(7, "image.exr"), "/api/jobs/7/image.exr");
        assert_eq!(bundle("ab12"), "/api/bundles/ab12");
        assert_eq!(lease(0), "/api/lease");
        assert_eq!(lease(5000), "/api/lease?wait_ms=5000");
        assert_eq!(heartbeat(3), "/api/leases/3/heartbeat");
        assert_eq!(result(3), "/api/leases/3/result");
        assert_eq!(release(3), "/api/leases/3/release");
        for p in [LEASE, &heartbeat(1), &result(1), &release(1), &bundle("x")] {
            assert!(is_workers(p), "{p}");
        }
        for p in [JOBS, &job(1), WORKERS, METRICS, HEALTH, "/api/leasesX"] {
            assert!(!is_workers(p), "{p}");
        }
    }
}
