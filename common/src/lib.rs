//! Photonfarm's shared library: scene loading, geometry, materials, lights, cameras, the
//! renderers and the film. The coordinator and the worker both link it, so that an iteration
//! renders to the same bytes wherever it runs.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod bsdf;
pub mod bundle;
pub mod camera;
pub mod color;
pub mod compression;
pub mod engine;
pub mod features;
pub mod film;
pub mod filter;
pub mod frames;
pub mod geometry;
pub mod integrator;
pub mod job;
pub mod light;
pub mod limits;
pub mod medium;
pub mod parity;
#[cfg(feature = "process")]
pub mod process;
pub mod protocol;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod sobol;
pub mod texture;
pub mod volume;
