use std::path::PathBuf;

/// Why a scene could not be loaded. The message names the file, the line and the element, so
/// that a user can go straight to the mistake.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}:{line}: {element}: {message}", file.display())]
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
