//! A render job's settings, shared by the command line and the farm's API, and their
//! resolution against a scene into exactly what the renderer runs.
//!
//! Both `coordinator render` and a farm job go through [`JobSettings::resolve`], so the same
//! settings give the same [`RenderSettings`] (the default radius included) and the same bytes.

use serde::{Deserialize, Serialize};

use crate::integrator::direct_illumination::DirectSettings;
use crate::integrator::path::PathSettings;
use crate::integrator::sppm::{SppmError, SppmSettings};
use crate::render::{Method, RenderSettings};
use crate::scene::Scene;

/// The rendering method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    /// Path tracing.
    Path,
    /// Mitsuba's `direct`: emission and one bounce of light.
    Direct,
    /// Progressive photon mapping.
    Sppm,
}

impl Integrator {
    /// The method that renders a scene's `<integrator>` (already reduced by the scene loader
    /// to `path`, `direct` or `sppm`).
    pub fn of_scene(scene: &Scene) -> Integrator {
        match scene.integrator.kind.as_str() {
            "direct" => Integrator::Direct,
            "sppm" => Integrator::Sppm,
            _ => Integrator::Path,
        }
    }
}

/// What a user asks for. Unset values take the scene's, then the built-in defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct JobSettings {
    /// The method; None renders the scene's `<integrator>`.
    #[serde(default)]
    pub integrator: Option<Integrator>,
    /// Passes: samples per pixel for `path`, iterations for `sppm`.
    #[serde(default)]
    pub passes: Option<u64>,
    /// SPPM photons per iteration.
    #[serde(default)]
    pub photons: Option<u64>,
    /// SPPM initial radius.
    #[serde(default)]
    pub radius: Option<f32>,
    /// SPPM alpha.
    #[serde(default)]
    pub alpha: Option<f64>,
    /// SPPM cone filter k.
    #[serde(default)]
    pub k: Option<f32>,
    /// SPPM initial volume radius over the initial surface radius.
    #[serde(default)]
    pub volume_radius_ratio: Option<f32>,
    /// `-D name=value` scene parameters.
    #[serde(default)]
    pub defines: Vec<(String, String)>,
    /// Seed of every random number.
    #[serde(default)]
    pub seed: u64,
    /// Write a checkpoint every this many passes.
    #[serde(default)]
    pub checkpoint_every: Option<u64>,
}

/// Why settings cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// An SPPM parameter is out of range.
    #[error(transparent)]
    Sppm(#[from] SppmError),
    /// A parameter that does not apply to the method.
    #[error(
        "{0} applies to the sppm integrator only (the method is the scene's <integrator> unless --integrator says otherwise)"
    )]
    NotForPath(&'static str),
    /// Zero passes or a zero checkpoint interval.
    #[error("{0} must be at least 1")]
    Zero(&'static str),
}

/// Settings resolved against a scene.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// What the renderer runs.
    pub render: RenderSettings,
    /// Passes to render; None when only a time limit ends the render.
    pub passes: Option<u64>,
    /// Warnings about unused scene parameters.
    pub warnings: Vec<String>,
}

impl JobSettings {
    /// Resolves against `scene`. `open_ended` allows no pass count (a time-limited render);
    /// otherwise the scene's sample count is the default.
    pub fn resolve(&self, scene: &Scene, open_ended: bool) -> Result<Resolved, JobError> {
        if self.passes == Some(0) {
            return Err(JobError::Zero("the pass or iteration count"));
        }
        if self.checkpoint_every == Some(0) {
            return Err(JobError::Zero("the checkpoint interval"));
        }
        let mut warnings = Vec::new();
        let integrator = self.integrator.unwrap_or_else(|| Integrator::of_scene(scene));
        let (method, declared) = match integrator {
            Integrator::Path | Integrator::Direct => {
                for (name, given) in [
                    ("photons", self.photons.is_some()),
                    ("radius", self.radius.is_some()),
                    ("alpha", self.alpha.is_some()),
                    ("k", self.k.is_some()),
                    ("volume_radius_ratio", self.volume_radius_ratio.is_some()),
                ] {
                    if given {
                        return Err(JobError::NotForPath(name));
                    }
                }
                let method = if integrator == Integrator::Path {
                    Method::Path(PathSettings::from_scene(scene))
                } else {
                    Method::Direct(DirectSettings::from_scene(scene))
                };
                (method, None)
            }
            Integrator::Sppm => {
                let (mut s, w) = SppmSettings::from_scene(scene);
                warnings.extend(w);
                s.photons = self.photons.unwrap_or(s.photons);
                s.initial_radius = self.radius.unwrap_or(s.initial_radius);
                s.alpha = self.alpha.unwrap_or(s.alpha);
                s.k = self.k.unwrap_or(s.k);
                s.volume_radius_ratio = self.volume_radius_ratio.unwrap_or(s.volume_radius_ratio);
                s.validate()?;
                let declared = scene
                    .integrator
                    .params
                    .iter()
                    .find(|(n, _)| n == "iterations")
                    .map(|(_, v)| *v as u64);
                (Method::Sppm(s), declared)
            }
        };
        let passes = match (self.passes.or(declared), open_ended) {
            (Some(n), _) => Some(n),
            (None, true) => None,
            (None, false) => Some(scene.spp as u64),
        };
        Ok(Resolved {
            render: RenderSettings {
                seed: self.seed,
                method,
            },
            passes,
            warnings,
        })
    }
}
