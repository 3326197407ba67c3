//! What can be wrong with camera input.

/// Problems with camera input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// Intrinsics that cannot describe a camera.
    #[error("invalid intrinsics: {0}")]
    Intrinsics(String),
    /// A matrix that is not a rigid world-to-camera transform.
    #[error("world_to_camera is not a rigid transform: {0}")]
    NotRigid(String),
    /// A look-at whose direction is undefined.
    #[error("look-at is degenerate: {0}")]
    DegenerateLookAt(String),
}
