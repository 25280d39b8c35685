//! The commands that render on this machine, with no coordinator: `render` (one image or a
//! frame sequence, resumable) and `converge` (error against a reference over time).

pub mod converge;
pub mod render;
pub mod resume;
