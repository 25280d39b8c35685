//! Closed-form checks: results that no eyeballing could confirm, known exactly.

use photonfarm_tests::{channel_means, load, render_path, scenes_dir};

/// pbrt's sphere: radiance 1 everywhere (albedo 0.5, intensity π at the centre of a unit
/// sphere): the sum of all bounces, 0.5 + 0.25 + ...
#[test]
fn lit_sphere_has_radiance_one() {
    let scene = load(&scenes_dir().join("lit-sphere.xml"), &[]);
    let film = render_path(&scene, 256, 3);
    let img = film.image().unwrap();
    let mean = channel_means(&img);
    eprintln!("lit sphere, path tracer: mean radiance {mean:?}");
    for c in mean {
        assert!((c - 1.0).abs() < 0.01, "mean radiance {c}, expected 1 within 1%");
    }
    // Every pixel converges to 1 too (no pixel-dependent bias such as acne).
    let worst = img.iter().map(|p| (p.x - 1.0).abs()).fold(0.0f32, f32::max);
    assert!(worst < 0.25, "a pixel is off by {worst}");
}

/// Mitsuba's depth meaning: max_depth 2 is direct light only (exactly 0.5 here, noise-free
/// because light sampling of a point light is exact), 3 adds one bounce (0.75 in expectation).
#[test]
fn max_depth_counts_like_mitsuba() {
    let direct = load(&scenes_dir().join("lit-sphere.xml"), &[("max_depth", "2")]);
    let img = render_path(&direct, 4, 3).image().unwrap();
    for p in &img {
        assert!((p.x - 0.5).abs() < 1e-4, "direct only: {p}");
    }
    let one_bounce = load(&scenes_dir().join("lit-sphere.xml"), &[("max_depth", "3")]);
    let mean = channel_means(&render_path(&one_bounce, 64, 3).image().unwrap());
    assert!((mean[0] - 0.75).abs() < 0.005, "one bounce: {mean:?}");
    let emitters_only = load(&scenes_dir().join("lit-sphere.xml"), &[("max_depth", "1")]);
    let img = render_path(&emitters_only, 2, 3).image().unwrap();
    assert!(
        img.iter().all(|p| p.max_element() == 0.0),
        "a point light is never seen directly"
    );
}

/// No light leaks through thin geometry: under a slab 1e-4 thick with a bright point light
/// 2e-4 above its top face, the floor stays exactly black, while without the slab it is lit.
#[test]
fn thin_slab_does_not_leak_light() {
    let scene = load(&scenes_dir().join("thin-slab.xml"), &[]);
    let img = render_path(&scene, 16, 1).image().unwrap();
    let worst = img.iter().map(|p| p.max_element()).fold(0.0f32, f32::max);
    assert_eq!(worst, 0.0, "light leaked through the slab: {worst}");
    // The same slab, 100 times thinner than the light's distance; still sealed.
    let thinner = load(&scenes_dir().join("thin-slab.xml"), &[("thickness", "0.00001")]);
    let img = render_path(&thinner, 16, 1).image().unwrap();
    assert!(
        img.iter().all(|p| p.max_element() == 0.0),
        "light leaked through a 1e-5 slab"
    );
    // Control: the light just below the slab does light the floor.
    let below = load(&scenes_dir().join("thin-slab.xml"), &[("light_y", "0.4997")]);
    let img = render_path(&below, 4, 1).image().unwrap();
    assert!(
        img.iter().all(|p| p.max_element() > 0.0),
        "the control scene should be lit everywhere"
    );
}
