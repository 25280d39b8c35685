use std::path::PathBuf;

/// Why a scene could not be loaded. The message names the file, the line and the element, so
/// that a user can go straight to the mistake: `scene.xml:12: <bsdf type="diffuse">: ...`, or
/// without the line when the file itself is the problem (`scene.xml: scene file: cannot read`).
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}{}: {element}: {message}", file.display(), at_line(*line))]
pub struct SceneError {
    /// The scene (or mesh) file.
    pub file: PathBuf,
    /// 1-based line of the offending element (0 when the file itself is the problem).
    pub line: u32,
    /// The element, as written (`<bsdf type="diffuse">`).
    pub element: String,
    /// What is wrong.
    pub message: String,
}

/// `:LINE`, or nothing for line 0 (no line: the whole file is meant).
fn at_line(line: u32) -> String {
    if line == 0 {
        String::new()
    } else {
        format!(":{line}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error(line: u32) -> SceneError {
        SceneError {
            file: PathBuf::from("scene.xml"),
            line,
            element: "scene file".into(),
            message: "cannot read".into(),
        }
    }

    #[test]
    fn the_message_names_the_line_when_there_is_one() {
        assert_eq!(error(12).to_string(), "scene.xml:12: scene file: cannot read");
        assert_eq!(error(0).to_string(), "scene.xml: scene file: cannot read");
    }

    #[test]
    fn a_missing_file_has_no_line_number() {
        let msg = crate::scene::Scene::load(std::path::Path::new("/nonexistent/scene.xml"), &[])
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("/nonexistent/scene.xml: scene file: cannot read"),
            "{msg}"
        );
    }
}
