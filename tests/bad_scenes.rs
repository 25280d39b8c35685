//! Bad scene files: each gives one clear line naming the file, line and element, never a panic.

use std::path::{Path, PathBuf};

use photonfarm::scene::Scene;

/// A scene around `body`, with a sensor so that only the body can be wrong. The body starts on
/// line 8.
fn scene_text(body: &str, film: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm">{film}<rfilter type="box"/></film>
    </sensor>
    <bsdf type="diffuse" id="grey"/>
    <emitter type="point"><point name="position" x="0" y="0" z="0"/></emitter>
{body}
</scene>"#
    )
}

const FILM: &str = r#"<integer name="width" value="8"/><integer name="height" value="8"/>"#;

/// Writes the scene into a fresh folder (with a sibling folder holding a mesh outside it).
fn write_scene(text: &str) -> (tempfile::TempDir, PathBuf) {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("scene");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(
        root.path().join("outside.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    std::fs::write(dir.join("inside.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let path = dir.join("bad.xml");
    std::fs::write(&path, text).unwrap();
    (root, path)
}

/// Loads and expects an error at `line` whose message contains `needle`.
fn expect_error(text: &str, line: u32, needle: &str) {
    let (_guard, path) = write_scene(text);
    let err = Scene::load(&path, &[]).expect_err("the scene should be rejected");
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(!msg.contains('\n'), "one line: {msg}");
    assert!(
        msg.starts_with(&format!("{}:{line}: ", path.display())),
        "file and line {line}: {msg}"
    );
    assert!(msg.contains(needle), "expected \"{needle}\" in: {msg}");
}

#[test]
fn malformed_xml() {
    expect_error(&scene_text("<shape type=\"sphere\">", FILM), 9, "malformed XML");
}

#[test]
fn unknown_element() {
    expect_error(
        &scene_text("<volume type=\"gridvolume\"/>", FILM),
        8,
        "<volume> is not supported",
    );
    expect_error(
        &scene_text("<texture type=\"bitmap\"/>", FILM),
        8,
        "a top-level <texture> needs an id",
    );
    expect_error(
        &scene_text("<texture type=\"noise\" id=\"t\"/>", FILM),
        8,
        "texture type \"noise\" is not supported",
    );
    expect_error(
        &scene_text("<shape type=\"teapot\"/>", FILM),
        8,
        "shape type \"teapot\" is not supported",
    );
    expect_error(
        &scene_text(
            "<shape type=\"sphere\"><float name=\"radios\" value=\"1\"/></shape>",
            FILM,
        ),
        8,
        "unknown parameter 'radios'",
    );
    expect_error(
        &scene_text(
            "<shape type=\"sphere\"><bsdf type=\"roughconductor\">\n<string name=\"distribution\" value=\"phong\"/></bsdf></shape>",
            FILM,
        ),
        9,
        "distribution \"phong\" is not supported (beckmann, ggx)",
    );
    // An unsupported value of a supported parameter, and an unsupported element type.
    expect_error(
        &scene_text("<integrator type=\"bdpt\"/>", FILM),
        8,
        "integrator type \"bdpt\" is not supported",
    );
}

#[test]
fn missing_mesh() {
    expect_error(
        &scene_text(
            "<shape type=\"obj\"><string name=\"filename\" value=\"nope.obj\"/></shape>",
            FILM,
        ),
        8,
        "not found",
    );
    // The mesh that is present loads.
    let (_guard, path) = write_scene(&scene_text(
        "<shape type=\"obj\"><string name=\"filename\" value=\"inside.obj\"/></shape>",
        FILM,
    ));
    Scene::load(&path, &[]).unwrap();
}

/// A local render resolves files as Mitsuba does (`..` and absolute names allowed, since
/// Mitsuba's own scenes keep meshes in `../../common`); inside a job's bundle every file must
/// stay in the bundle's folder, however it is named or linked.
#[test]
fn mesh_path_leaving_the_folder() {
    let (guard, path) = write_scene("");
    let absolute = guard.path().join("outside.obj");
    let bundle = path.parent().unwrap();
    for name in ["../outside.obj".to_string(), absolute.display().to_string()] {
        std::fs::write(
            &path,
            scene_text(
                &format!("<shape type=\"obj\"><string name=\"filename\" value=\"{name}\"/></shape>"),
                FILM,
            ),
        )
        .unwrap();
        let local = Scene::load(&path, &[]).unwrap();
        assert_eq!(local.files, vec![absolute.canonicalize().unwrap()]);
        let msg = Scene::load_inside(&path, &[], bundle).unwrap_err().to_string();
        assert!(
            msg.starts_with(&format!("{}:8: ", path.display())) && msg.contains("outside the job's bundle"),
            "{msg}"
        );
    }
}

#[cfg(unix)]
#[test]
fn symlink_leaving_the_folder() {
    let (guard, path) = write_scene(&scene_text(
        "<shape type=\"obj\"><string name=\"filename\" value=\"link.obj\"/></shape>",
        FILM,
    ));
    std::os::unix::fs::symlink(
        guard.path().join("outside.obj"),
        path.parent().unwrap().join("link.obj"),
    )
    .unwrap();
    let msg = Scene::load_inside(&path, &[], path.parent().unwrap())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("outside the job's bundle"), "{msg}");
}

/// Mitsuba's file structure: an `<include>` (a fragment with a `<scene>` root and one with a
/// single object), defaults declared in the included file, a `<path>` folder, and a top-level
/// area emitter that a shape refers to; errors in an included file name that file.
#[test]
fn includes_paths_and_referenced_emitters() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("scenes");
    std::fs::create_dir_all(dir.join("fragments")).unwrap();
    std::fs::create_dir_all(root.path().join("common")).unwrap();
    std::fs::write(
        root.path().join("common/tri.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("fragments/base.xml"),
        r#"<scene version="3.0.0"><default name="res" value="8"/>
            <emitter type="area" id="light"><rgb name="radiance" value="2"/></emitter></scene>"#,
    )
    .unwrap();
    std::fs::write(
        dir.join("fragments/grey.xml"),
        r#"<bsdf version="3.0.0" type="diffuse" id="grey"/>"#,
    )
    .unwrap();
    let text = r#"<scene version="3.0.0">
    <path value="../common"/>
    <include filename="fragments/base.xml"/>
    <include filename="fragments/grey.xml"/>
    <sensor type="perspective"><float name="fov" value="45"/><float name="focus_distance" value="3"/>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/></film>
    </sensor>
    <shape type="obj"><string name="filename" value="tri.obj"/><ref id="grey"/><ref id="light"/></shape>
</scene>"#;
    let path = dir.join("scene.xml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::load(&path, &[]).unwrap();
    assert_eq!((scene.width(), scene.lights.len()), (8, 1));
    assert_eq!(scene.files.len(), 3, "{:?}", scene.files);
    // The same from a bundle of the common folder: everything lies inside it.
    Scene::load_inside(&path, &[], root.path()).unwrap();
    // ... but not from a bundle of the scene's folder alone.
    assert!(Scene::load_inside(&path, &[], &dir).is_err());
    // An unused -D is an error, as in Mitsuba.
    let msg = Scene::load(&path, &[("spp".into(), "4".into())])
        .unwrap_err()
        .to_string();
    assert!(msg.contains("spp=4"), "{msg}");
    // An error inside an included file names that file and its line.
    std::fs::write(
        dir.join("fragments/grey.xml"),
        "<bsdf version=\"3.0.0\" type=\"diffuse\" id=\"grey\">\n<float name=\"nonsense\" value=\"1\"/></bsdf>",
    )
    .unwrap();
    let msg = Scene::load(&path, &[]).unwrap_err().to_string();
    assert!(
        msg.contains("fragments/grey.xml:2: ") && msg.contains("nonsense"),
        "{msg}"
    );
    // Includes that include each other stop at Mitsuba's depth limit.
    std::fs::write(
        dir.join("fragments/grey.xml"),
        r#"<scene version="3.0.0"><include filename="grey.xml"/></scene>"#,
    )
    .unwrap();
    let msg = Scene::load(&path, &[]).unwrap_err().to_string();
    assert!(msg.contains("nest more than 15"), "{msg}");
}

#[test]
fn nonsense_values() {
    expect_error(
        &scene_text(
            "<shape type=\"sphere\"><float name=\"radius\" value=\"nan\"/></shape>",
            FILM,
        ),
        8,
        "not a finite number",
    );
    expect_error(
        &scene_text(
            "<shape type=\"sphere\"><float name=\"radius\" value=\"-1\"/></shape>",
            FILM,
        ),
        8,
        "must be positive",
    );
    expect_error(
        &scene_text(
            "<bsdf type=\"diffuse\" id=\"x\"><rgb name=\"reflectance\" value=\"0.5, -0.1, 0.2\"/></bsdf>",
            FILM,
        ),
        8,
        "must lie in [0, 1]",
    );
    expect_error(
        &scene_text(
            "<shape type=\"sphere\"><emitter type=\"area\"><rgb name=\"radiance\" value=\"-3\"/></emitter></shape>",
            FILM,
        ),
        8,
        "cannot be negative",
    );
    expect_error(
        &scene_text("<shape type=\"sphere\"><ref id=\"nothing\"/></shape>", FILM),
        8,
        "no <bsdf> with id",
    );
}

#[test]
fn bad_bump_and_normal_maps() {
    expect_error(
        &scene_text(
            "<bsdf type=\"normalmap\" id=\"n\"><bsdf type=\"diffuse\"/></bsdf>",
            FILM,
        ),
        8,
        "normalmap needs a <texture name=\"normalmap\">",
    );
    expect_error(
        &scene_text(
            "<bsdf type=\"bumpmap\" id=\"b\">\n<texture type=\"checkerboard\"/><bsdf type=\"diffuse\"/></bsdf>",
            FILM,
        ),
        9,
        "bumpmap needs a bitmap texture",
    );
    expect_error(
        &scene_text(
            "<bsdf type=\"bumpmap\" id=\"b\"><bsdf type=\"diffuse\"/></bsdf>",
            FILM,
        ),
        8,
        "bumpmap needs one nested texture, not 0",
    );
    expect_error(
        &scene_text(
            "<bsdf type=\"normalmap\" id=\"n\"><texture type=\"checkerboard\" name=\"normalmap\"/></bsdf>",
            FILM,
        ),
        8,
        "normalmap needs one nested bsdf, not 0",
    );
}

#[test]
fn bad_shape_groups_and_instances() {
    let sphere = "<shape type=\"sphere\"/>";
    expect_error(
        &scene_text(&format!("<shape type=\"shapegroup\">{sphere}</shape>"), FILM),
        8,
        "a shapegroup needs an id",
    );
    expect_error(
        &scene_text(
            "<shape type=\"shapegroup\" id=\"g\"><shape type=\"sphere\"><emitter type=\"area\"/></shape></shape>",
            FILM,
        ),
        8,
        "an emitter cannot be part of a shapegroup",
    );
    expect_error(
        &scene_text("<shape type=\"shapegroup\" id=\"g\"/>", FILM),
        8,
        "a shapegroup needs at least one shape",
    );
    expect_error(
        &scene_text(
            &format!(
                "<shape type=\"shapegroup\" id=\"g\">{sphere}</shape>\n<shape type=\"instance\"><ref id=\"h\"/></shape>"
            ),
            FILM,
        ),
        9,
        "no shapegroup with id \"h\"",
    );
    expect_error(
        &scene_text(
            &format!(
                "<shape type=\"shapegroup\" id=\"g\">{sphere}</shape>\n<shape type=\"instance\"><ref id=\"g\"/><transform name=\"to_world\"><matrix value=\"1 0 0 0 1 0 0 0 0 0 0 0 0 0 0 1\"/></transform></shape>"
            ),
            FILM,
        ),
        9,
        "cannot be inverted",
    );
    expect_error(
        &scene_text("<shape type=\"instance\"/>", FILM),
        8,
        "an instance needs one <ref> to a shapegroup",
    );
    expect_error(
        &scene_text(
            &format!(
                "<shape type=\"shapegroup\" id=\"g\"><shape type=\"shapegroup\" id=\"h\">{sphere}</shape></shape>"
            ),
            FILM,
        ),
        8,
        "a shapegroup belongs at the top level",
    );
}

#[test]
fn an_orthographic_sensor_takes_no_field_of_view() {
    let text = format!(
        r#"<scene version="3.0.0">
    <sensor type="orthographic">
        <float name="fov" value="45"/>
        <film type="hdrfilm">{FILM}</film>
    </sensor>
</scene>"#
    );
    expect_error(&text, 2, "an orthographic sensor takes no fov or focal_length");
}

/// Mitsuba refuses `stokes` outside its polarized variants; so do we, saying why.
#[test]
fn the_stokes_integrator_is_refused_as_in_mitsuba() {
    expect_error(
        &scene_text(
            "<integrator type=\"stokes\"><integrator type=\"path\"/></integrator>",
            FILM,
        ),
        8,
        "This integrator should only be used in polarized mode!",
    );
}

#[test]
fn bad_media() {
    expect_error(
        &scene_text(
            "<medium type=\"homogeneous\" id=\"m\"><phase type=\"hg\"><float name=\"g\" value=\"1.5\"/></phase></medium>",
            FILM,
        ),
        8,
        "g must lie strictly between -1 and 1",
    );
    expect_error(
        &scene_text("<medium type=\"inhomogeneous\" id=\"m\"/>", FILM),
        8,
        "medium type \"inhomogeneous\" is not supported (homogeneous, heterogeneous)",
    );
    let grid = |medium: &str, volume: &str| {
        format!("<medium type=\"{medium}\" id=\"m\"><volume name=\"sigma_t\" {volume}</volume></medium>")
    };
    expect_error(
        &scene_text(&grid("homogeneous", "type=\"constvolume\">"), FILM),
        8,
        "a homogeneous medium's sigma_t is a constant; a medium whose density varies is type=\"heterogeneous\"",
    );
    expect_error(
        &scene_text(&grid("heterogeneous", "type=\"noisevolume\">"), FILM),
        8,
        "volume type \"noisevolume\" is not supported (gridvolume, constvolume)",
    );
    // A file that is not a .vol file, and one that does not exist.
    let file = |name: &str| format!("type=\"gridvolume\"><string name=\"filename\" value=\"{name}\"/>");
    expect_error(
        &scene_text(&grid("heterogeneous", &file("inside.obj")), FILM),
        8,
        "not a Mitsuba volume file",
    );
    expect_error(
        &scene_text(&grid("heterogeneous", &file("smoke.vol")), FILM),
        8,
        "smoke.vol",
    );
    expect_error(
        &scene_text(
            "<medium type=\"homogeneous\" id=\"m\"/><shape type=\"sphere\"><ref name=\"inside\" id=\"m\"/></shape>",
            FILM,
        ),
        8,
        "name=\"interior\"",
    );
    expect_error(
        &scene_text(
            "<emitter type=\"beam\"><float name=\"radius\" value=\"0\"/></emitter>",
            FILM,
        ),
        8,
        "must be positive",
    );
}

#[test]
fn zero_size_film() {
    let film = r#"<integer name="width" value="0"/><integer name="height" value="8"/>"#;
    expect_error(&scene_text("", film), 4, "width must be between 1 and 65536");
}

#[test]
fn missing_scene_file() {
    let msg = Scene::load(Path::new("/nonexistent/scene.xml"), &[])
        .unwrap_err()
        .to_string();
    assert!(
        msg.starts_with("/nonexistent/scene.xml: ") && msg.contains("cannot read"),
        "{msg}"
    );
}

#[test]
fn every_shipped_scene_loads() {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for dir in [
        photonfarm_tests::refs_dir(),
        photonfarm_tests::scenes_dir(),
        shipped,
    ] {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "xml") {
                Scene::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
            }
        }
    }
}

/// Rough materials and projectors refuse what Mitsuba refuses or what they cannot place.
#[test]
fn roughness_and_projector_mistakes() {
    let rough = |params: &str| {
        format!("<shape type=\"sphere\"><bsdf type=\"roughconductor\">{params}</bsdf></shape>")
    };
    expect_error(
        &scene_text(&rough("<float name=\"alpha_u\" value=\"0.1\"/>"), FILM),
        8,
        "give both alpha_u and alpha_v",
    );
    expect_error(
        &scene_text(
            &rough(
                "<float name=\"alpha\" value=\"0.1\"/><float name=\"alpha_u\" value=\"0.1\"/><float name=\"alpha_v\" value=\"0.2\"/>",
            ),
            FILM,
        ),
        8,
        "give alpha, or alpha_u and alpha_v, not both",
    );
    expect_error(
        &scene_text(
            "<shape type=\"sphere\"><bsdf type=\"roughplastic\"><float name=\"alpha_u\" value=\"0.1\"/></bsdf></shape>",
            FILM,
        ),
        8,
        "roughplastic takes one alpha",
    );
    expect_error(
        &scene_text("<emitter type=\"projector\"/>", FILM),
        8,
        "a projector needs an irradiance",
    );
    expect_error(
        &scene_text(
            "<emitter type=\"projector\"><rgb name=\"irradiance\" value=\"1\"/>\n<transform name=\"to_world\"><scale value=\"2\"/></transform></emitter>",
            FILM,
        ),
        9,
        "a projector's to_world places and turns it",
    );
}

#[test]
fn a_curve_file_must_hold_control_points() {
    expect_error(
        &scene_text(
            "<shape type=\"linearcurve\"><string name=\"filename\" value=\"inside.obj\"/></shape>",
            FILM,
        ),
        8,
        "inside.obj: line 1: expected \"x y z radius\"",
    );
}

#[test]
fn a_raw_constant_needs_a_value() {
    let raw = |value: &str| {
        scene_text(
            &format!(
                "<shape type=\"sphere\"><bsdf type=\"normalmap\"><texture name=\"normalmap\" type=\"rawconstant\">{value}</texture><bsdf type=\"diffuse\"/></bsdf></shape>"
            ),
            FILM,
        )
    };
    expect_error(
        &raw(""),
        8,
        "missing the value parameter (a <float> or a <vector>)",
    );
    expect_error(
        &raw("<string name=\"value\" value=\"up\"/>"),
        8,
        "parameter 'value' must be given as <float> or <integer>",
    );
}

#[test]
fn mesh_attribute_mistakes() {
    let attr = |name: &str, param: &str| {
        format!(
            "<texture type=\"mesh_attribute\" name=\"{param}\"><string name=\"name\" value=\"{name}\"/></texture>"
        )
    };
    let obj = |bsdf: &str| {
        format!("<shape type=\"obj\"><string name=\"filename\" value=\"inside.obj\"/>{bsdf}</shape>")
    };
    expect_error(
        &scene_text(
            &obj(&format!(
                "<bsdf type=\"diffuse\">{}</bsdf>",
                attr("color", "reflectance")
            )),
            FILM,
        ),
        8,
        "a mesh attribute's name starts with vertex_ or face_, not \"color\"",
    );
    expect_error(
        &scene_text(
            &obj(&format!(
                "<bsdf type=\"diffuse\">{}</bsdf>",
                attr("vertex_color", "reflectance")
            )),
            FILM,
        ),
        8,
        "its material reads mesh attribute \"vertex_color\", which the mesh has not (it has: none)",
    );
    expect_error(
        &scene_text(
            &format!(
                "<shape type=\"sphere\"><bsdf type=\"diffuse\">{}</bsdf></shape>",
                attr("vertex_color", "reflectance")
            ),
            FILM,
        ),
        8,
        "a sphere is not a mesh with attributes",
    );
    expect_error(
        &scene_text(
            &obj(&format!(
                "<bsdf type=\"blendbsdf\">{}<bsdf type=\"diffuse\">{}</bsdf><bsdf type=\"diffuse\"/></bsdf>",
                attr("face_weight", "weight"),
                attr("vertex_color", "reflectance")
            )),
            FILM,
        ),
        8,
        "reads mesh attributes face_weight, vertex_color: one per shape is supported",
    );
    expect_error(
        &scene_text(
            &obj(&format!(
                "<bsdf type=\"plastic\">{}</bsdf>",
                attr("vertex_color", "diffuse_reflectance")
            )),
            FILM,
        ),
        8,
        "plastic's diffuse_reflectance cannot be a mesh_attribute",
    );
    expect_error(
        &scene_text(
            &obj(&format!(
                "<emitter type=\"area\">{}</emitter>",
                attr("vertex_color", "radiance")
            )),
            FILM,
        ),
        8,
        "a light's radiance cannot be a mesh_attribute",
    );
}
