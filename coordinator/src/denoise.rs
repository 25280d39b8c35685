//! Denoising an image with Intel Open Image Denoise (OIDN), guided by its albedo and normal
//! ([`photonfarm::features`]).
//!
//! The denoised image is a preview beside the exact one, never in its place: OIDN picks the
//! newest instruction set the CPU has, so its output is not promised across machines, and it is
//! biased (it smooths what it takes for noise). The raw image's bytes do not depend on it.
//!
//! OIDN is optional at build time (the `denoise` feature, which needs the library that
//! deploy/install-oidn.sh installs): a build without it renders as before and refuses
//! `--denoise` with [`UNAVAILABLE`].

use photonfarm::color::Rgb;
use photonfarm::features::Features;

/// Whether this build can denoise.
pub const AVAILABLE: bool = cfg!(feature = "denoise");

/// What `--denoise` says in a build without OIDN.
pub const UNAVAILABLE: &str = "this coordinator was built without Open Image Denoise: run \
     deploy/install-oidn.sh, then build with `--features denoise` (README, \"Denoising\")";

/// The image denoised by OIDN's `RT` filter (HDR, with albedo and normal), row by row from the
/// top like `image`.
pub fn denoise(image: &[Rgb], features: &Features) -> anyhow::Result<Vec<Rgb>> {
    let (w, h) = (features.albedo.width as usize, features.albedo.height as usize);
    anyhow::ensure!(image.len() == w * h, "the image and its features differ in size");
    let flat = |pixels: &[Rgb]| -> Vec<f32> { pixels.iter().flat_map(|p| [p.x, p.y, p.z]).collect() };
    // Emission seen directly is kept out of the denoiser: the image's own is taken out, and the
    // dense estimate of it added back (smoother where a light covers a pixel in part). Where
    // the image holds less than its own (an integrator that does not count it), the image is
    // kept as it is.
    let own = features.emitted.image()?;
    let dense = features.emitted_dense.image()?;
    let (taken, added): (Vec<Rgb>, Vec<Rgb>) = own
        .iter()
        .zip(&dense)
        .zip(image)
        .map(|((o, d), i)| {
            let counted = o.cmple(*i);
            (o.min(*i), Rgb::select(counted, *d, o.min(*i)))
        })
        .unzip();
    let rest: Vec<Rgb> = image
        .iter()
        .zip(&taken)
        .map(|(i, e)| (*i - *e).max(Rgb::ZERO))
        .collect();
    let albedo = flat(&features.albedo_image()?);
    let normal = flat(&features.normal_image()?);
    let out = run_filter(&flat(&rest), &albedo, &normal, w, h)?;
    Ok(out
        .chunks_exact(3)
        .zip(&added)
        .map(|(c, e)| Rgb::new(c[0], c[1], c[2]) + *e)
        .collect())
}

#[cfg(feature = "denoise")]
fn run_filter(color: &[f32], albedo: &[f32], normal: &[f32], w: usize, h: usize) -> anyhow::Result<Vec<f32>> {
    use anyhow::Context;
    // One filter at a time in a process: OIDN already spreads one over every core, so a second
    // at once only competes for them, and a coordinator may finish checkpoints of several jobs
    // together. (The lock guards no data: a poisoned one is as good.)
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    // The CPU device: the same code on every machine of a kind, whatever GPUs it has.
    let device = oidn::Device::cpu()
        .map_err(oidn_error)
        .context("cannot start Open Image Denoise")?;
    let mut filter = oidn::RayTracing::try_new(&device).map_err(oidn_error)?;
    // Not `cleanAux`: the features carry the antialiasing noise of edges (a light's outline is
    // as noisy in the albedo as in the image), and on cbox at 64 passes it changed the RMSE by
    // 0.1%. (The crate's `clean_aux` would not set it anyway: it names the parameter
    // "clean_aux", which OIDN 2.5.1 ignores with a warning.)
    filter
        .srgb(false)
        .hdr(true)
        .image_dimensions(w, h)
        .albedo_normal(albedo, normal);
    let mut out = vec![0.0; color.len()];
    filter
        .filter(color, &mut out)
        .map_err(oidn_error)
        .context("Open Image Denoise failed")?;
    Ok(out)
}

#[cfg(feature = "denoise")]
fn oidn_error(e: oidn::Error) -> anyhow::Error {
    anyhow::anyhow!("{}: {}", e.kind(), e.message())
}

#[cfg(not(feature = "denoise"))]
fn run_filter(_: &[f32], _: &[f32], _: &[f32], _: usize, _: usize) -> anyhow::Result<Vec<f32>> {
    anyhow::bail!(UNAVAILABLE)
}

/// Where the denoised preview of `out` goes: `x.exr` → `x.denoised.exr`, beside it.
pub fn denoised_path(out: &std::path::Path) -> std::path::PathBuf {
    photonfarm::film::beside(out, ".denoised")
}
