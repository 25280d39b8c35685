//! The coordinator program's library: everything but argument parsing lives here, so that
//! tests can drive it directly.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod cli;
pub mod progress;
pub mod render_command;
