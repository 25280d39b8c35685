//! The coordinator program's library: everything but argument parsing lives here, so that
//! tests can drive it directly.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod accumulator;
pub mod admission;
pub mod api;
pub mod cli;
pub mod client;
pub mod connections;
pub mod converge;
pub mod farm;
pub mod loadgen;
pub mod metrics;
pub mod progress;
pub mod relay;
pub mod render_command;
pub mod result_body;
pub mod resume;
pub mod scene_check;
pub mod scheduler;
pub mod serve_command;
pub mod service;
pub mod serving;
pub mod store;
pub mod synthetic;
pub mod web;
pub mod workers;
