//! A render job's settings, shared by the command line and the farm's API, and their
//! resolution against a scene into exactly what the renderer runs.
//!
//! Both `coordinator render` and a farm job go through [`JobSettings::resolve`], so the same
//! settings give the same [`RenderSettings`] (the default radius included) and the same bytes.

use serde::{Deserialize, Serialize};

use crate::integrator::direct_illumination::DirectSettings;
use crate::integrator::path::PathSettings;
use crate::integrator::sppm::{SppmError, SppmSettings, VolumeEstimate};
use crate::render::{Method, RenderSettings};
use crate::scene::{MethodParams, Scene};

/// The rendering method. Its names (the job API's JSON, `--integrator`, the logs) are the
/// variants' own, lowercased, by serde and clap alike; [`Integrator::name`] spells them for the
/// rest, and a test holds the three together. (The variants' doc comments are `--help`'s.)
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    /// Unidirectional path tracing with next-event estimation and MIS.
    Path,
    /// Mitsuba's `direct`: emitters seen directly and one bounce of light, nothing more.
    Direct,
    /// Stochastic progressive photon mapping (Knaus and Zwicker): caustics and light seen
    /// through glass or in mirrors.
    Sppm,
    /// Mitsuba's particle tracer: light paths connected to the camera at every diffuse
    /// bounce; caustics on what the camera sees directly, nothing seen through glass or in
    /// mirrors.
    Ptracer,
    /// The path tracer for all light but caustics, and the particle tracer for caustics
    /// (light whose first bounce off the light is specular, landing on something the camera
    /// sees directly): caustics of point and spot lights at the particle tracer's speed, the
    /// rest at the path tracer's.
    Hybrid,
}

impl Integrator {
    /// Every method.
    pub const ALL: [Integrator; 5] = [
        Integrator::Path,
        Integrator::Direct,
        Integrator::Sppm,
        Integrator::Ptracer,
        Integrator::Hybrid,
    ];

    /// The method's name.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Path => "path",
            Integrator::Direct => "direct",
            Integrator::Sppm => "sppm",
            Integrator::Ptracer => "ptracer",
            Integrator::Hybrid => "hybrid",
        }
    }

    /// The method named `name`.
    pub fn from_name(name: &str) -> Option<Integrator> {
        Integrator::ALL.into_iter().find(|i| i.name() == name)
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
    /// SPPM volume estimator.
    #[serde(default)]
    pub volume_estimate: Option<VolumeEstimate>,
    /// `-D name=value` scene parameters.
    #[serde(default)]
    pub defines: Vec<(String, String)>,
    /// Seed of every random number.
    #[serde(default)]
    pub seed: u64,
    /// Write a checkpoint every this many passes.
    #[serde(default)]
    pub checkpoint_every: Option<u64>,
    /// A sequence: the frames in Flamenco's syntax ([`crate::frames::parse_frames`]), each
    /// rendered with [`JobSettings::for_frame`]'s settings. None: one image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<String>,
    /// A sequence given as scene files: frame i is the i-th of these (paths inside the
    /// bundle), and `frames` lists as many frames. Empty: every frame is the job's scene.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scenes: Vec<String>,
    /// Sum the denoiser's features (albedo, normal; [`crate::features`]) and write them into
    /// the EXR as channels.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub aovs: bool,
    /// Also make a denoised preview of the image (with the features, whether or not `aovs`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub denoise: bool,
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
    /// The scene's `<integrator>` declares an iteration count that is not a positive integer.
    #[error("the scene's SPPM iterations must be a positive integer, not {0}")]
    DeclaredIterations(f64),
    /// Too many or too long `-D` parameters.
    #[error("defines: {0}")]
    Defines(String),
}

/// Most `-D name=value` parameters a job may carry: each is substituted into the scene.
pub const MAX_DEFINES: usize = 256;
/// Longest `-D` name or value, in bytes.
pub const MAX_DEFINE_LEN: usize = 4096;

/// Settings resolved against a scene.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// What the renderer runs.
    pub render: RenderSettings,
    /// Passes to render; None when only a time limit ends the render.
    pub passes: Option<u64>,
}

/// A scene's `iterations`: a float in the XML, so a negative, fractional or huge value must
/// be refused here rather than cast (−5 would become 0 passes, 1e30 would saturate).
fn declared_iterations(v: f64) -> Result<u64, JobError> {
    if v >= 1.0 && v.fract() == 0.0 && v <= u64::MAX as f64 / 2.0 {
        Ok(v as u64)
    } else {
        Err(JobError::DeclaredIterations(v))
    }
}

impl JobSettings {
    /// Whether the render sums the denoiser's features.
    pub fn features(&self) -> bool {
        self.aovs || self.denoise
    }

    /// The settings of `frame` of the sequence `frames`: its parameters (the frame number and
    /// the ramps) and its seed, from [`crate::frames`]; one image, so no frame list.
    pub fn for_frame(&self, frames: &[u32], frame: u32) -> Result<JobSettings, crate::frames::FrameError> {
        Ok(JobSettings {
            defines: crate::frames::frame_defines(&self.defines, frames, frame)?,
            seed: crate::frames::frame_seed(self.seed, frame),
            frames: None,
            scenes: Vec::new(),
            ..self.clone()
        })
    }

    /// Checks the number and length of the `-D` parameters (they are stored with the job and
    /// sent with every batch).
    pub fn check_defines(&self) -> Result<(), JobError> {
        if self.defines.len() > MAX_DEFINES {
            return Err(JobError::Defines(format!(
                "{} parameters, above the limit of {MAX_DEFINES}",
                self.defines.len()
            )));
        }
        if let Some((k, _)) = self
            .defines
            .iter()
            .find(|(k, v)| k.len() > MAX_DEFINE_LEN || v.len() > MAX_DEFINE_LEN)
        {
            let shown: String = k.chars().take(40).collect();
            return Err(JobError::Defines(format!(
                "parameter \"{shown}\" has a name or value longer than {MAX_DEFINE_LEN} bytes"
            )));
        }
        Ok(())
    }

    /// Resolves against `scene`. `open_ended` allows no pass count (a time-limited render);
    /// otherwise the scene's sample count is the default.
    pub fn resolve(&self, scene: &Scene, open_ended: bool) -> Result<Resolved, JobError> {
        if self.passes == Some(0) {
            return Err(JobError::Zero("the pass or iteration count"));
        }
        if self.checkpoint_every == Some(0) {
            return Err(JobError::Zero("the checkpoint interval"));
        }
        self.check_defines()?;
        let integrator = self.integrator.unwrap_or(scene.integrator.kind);
        let (method, declared) = match integrator {
            Integrator::Path | Integrator::Direct | Integrator::Ptracer | Integrator::Hybrid => {
                for (name, given) in [
                    ("photons", self.photons.is_some()),
                    ("radius", self.radius.is_some()),
                    ("alpha", self.alpha.is_some()),
                    ("k", self.k.is_some()),
                    ("volume_radius_ratio", self.volume_radius_ratio.is_some()),
                    ("volume_estimate", self.volume_estimate.is_some()),
                ] {
                    if given {
                        return Err(JobError::NotForPath(name));
                    }
                }
                let method = match integrator {
                    Integrator::Path => Method::Path(PathSettings::from_scene(scene)),
                    Integrator::Direct => Method::Direct(DirectSettings::from_scene(scene)),
                    Integrator::Hybrid => Method::Hybrid(PathSettings::from_scene(scene)),
                    _ => Method::Ptracer(PathSettings::from_scene(scene)),
                };
                (method, None)
            }
            Integrator::Sppm => {
                let mut s = SppmSettings::from_scene(scene);
                s.photons = self.photons.unwrap_or(s.photons);
                s.initial_radius = self.radius.unwrap_or(s.initial_radius);
                s.alpha = self.alpha.unwrap_or(s.alpha);
                s.k = self.k.unwrap_or(s.k);
                if let Some(e) = self.volume_estimate {
                    let declared = matches!(&scene.integrator.params,
                        MethodParams::Sppm(p) if p.volume_radius_ratio.is_some());
                    if !declared {
                        s = s.with_volume_estimate(e);
                    }
                    s.volume_estimate = e;
                }
                s.volume_radius_ratio = self.volume_radius_ratio.unwrap_or(s.volume_radius_ratio);
                s.validate()?;
                s.validate_for(scene)?;
                let declared = match &scene.integrator.params {
                    MethodParams::Sppm(p) => p.iterations.map(declared_iterations).transpose()?,
                    _ => None,
                };
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
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn scene_with_iterations(v: &str) -> Scene {
        let text = format!(
            r#"<scene version="3.0.0">
            <integrator type="sppm"><integer name="iterations" value="{v}"/></integrator>
            <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
                <integer name="height" value="4"/><rfilter type="box"/></film></sensor>
            <shape type="sphere"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
            </scene>"#
        );
        Scene::from_str(&text, Path::new("t.xml"), &[]).unwrap()
    }

    /// One spelling of each method: `name`, the job API's JSON and `--integrator`.
    #[test]
    fn methods_have_one_name_each() {
        for i in Integrator::ALL {
            assert_eq!(serde_json::to_string(&i).unwrap(), format!("\"{}\"", i.name()));
            assert_eq!(Integrator::from_name(i.name()), Some(i));
            #[cfg(feature = "cli")]
            assert_eq!(
                clap::ValueEnum::to_possible_value(&i).unwrap().get_name(),
                i.name()
            );
        }
        assert_eq!(Integrator::from_name("volpath"), None);
    }

    /// A heterogeneous medium gets SPPM's default beam estimate; photon beams, which follow
    /// photon flights in closed form, are refused for it with a message saying what to use.
    #[test]
    fn photon_beams_are_refused_where_density_varies() {
        let scene = Scene::from_str(
            r#"<scene version="3.0.0">
            <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
                <integer name="height" value="4"/><rfilter type="box"/></film></sensor>
            <medium type="heterogeneous" id="m"><float name="sigma_t" value="2"/></medium>
            <shape type="cube"><bsdf type="null"/><ref name="interior" id="m"/></shape>
            <shape type="sphere"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
            </scene>"#,
            Path::new("t.xml"),
            &[],
        )
        .unwrap();
        let sppm = |estimate| JobSettings {
            integrator: Some(Integrator::Sppm),
            volume_estimate: estimate,
            ..JobSettings::default()
        };
        let resolved = sppm(None).resolve(&scene, false).unwrap();
        let Method::Sppm(s) = resolved.render.method else {
            panic!("not SPPM");
        };
        assert_eq!(s.volume_estimate, VolumeEstimate::Beam);
        let e = sppm(Some(VolumeEstimate::PhotonBeams))
            .resolve(&scene, false)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("use --volume-estimate beam (the default) or point"),
            "{e}"
        );
        for estimate in [VolumeEstimate::Beam, VolumeEstimate::Point] {
            assert!(sppm(Some(estimate)).resolve(&scene, false).is_ok());
        }
    }

    #[test]
    fn declared_iterations_must_be_positive() {
        let sppm = JobSettings {
            integrator: Some(Integrator::Sppm),
            ..JobSettings::default()
        };
        for bad in ["0", "-5"] {
            let e = sppm.resolve(&scene_with_iterations(bad), false).unwrap_err();
            assert!(matches!(e, JobError::DeclaredIterations(_)), "{bad}: {e}");
        }
        let ok = sppm.resolve(&scene_with_iterations("12"), false).unwrap();
        assert_eq!(ok.passes, Some(12));
    }

    #[test]
    fn too_many_defines_are_refused() {
        let many = JobSettings {
            defines: (0..MAX_DEFINES + 1)
                .map(|i| (format!("d{i}"), "1".into()))
                .collect(),
            ..JobSettings::default()
        };
        assert!(matches!(many.check_defines(), Err(JobError::Defines(_))));
        let long = JobSettings {
            defines: vec![("x".into(), "y".repeat(MAX_DEFINE_LEN + 1))],
            ..JobSettings::default()
        };
        assert!(long.check_defines().is_err());
    }
}
