//! The coordinator program's library: everything but argument parsing lives here, so that
//! tests can drive it directly.
//!
//! One program, four roles, one folder each: [`service`] is the farm (`serve`), [`client`] the
//! commands that talk to it over HTTP (`submit`, the job commands, `loadgen`), [`local`] the
//! commands that render here with no farm (`render`, `converge`), and [`relay`] a relay for
//! workers behind one address. [`serving`] is the network stack the service and a relay share,
//! [`denoise`] the denoiser both the service and `render` call.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod cli;
pub mod client;
pub mod denoise;
pub mod local;
pub mod progress;
pub mod relay;
pub mod service;
pub mod serving;
