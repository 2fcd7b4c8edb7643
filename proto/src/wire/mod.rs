//! Wire mirrors of the domain types and the conversions between them.
//!
//! `From<&Domain> for Wire*` is infallible. `TryFrom<Wire*> for Domain`
//! validates what a peer could get wrong and returns a [`WireError`] naming
//! the field: non-finite floats, indices out of range, sizes that disagree,
//! values outside the ranges the renderer relies on. It never panics, so the
//! receiving side can convert hostile data without further checks.
//!
//! Vectors travel as `[f32; 3]` (glam's types do not derive serde here).
//!
//! - [`scene`]: the scene, camera and lights (`WireScene`, `WireCamera`, ...).
//! - [`setup`]: a frame's settings (`WireFrameSetup`) and a package's counters.
//! - [`bitmap`]: a package's result (`WireBitmap`), the bitmap codec.
//! - [`mesh`]: a progressive stage's reflector meshes (`WireMesh`), for the view.
//! - [`image`]: a finished frame and its components (`WireImage`), the image codec.
//! - `planes`: what both codecs share: byte planes and zstd.

use glam::Vec3;
use vtfarm_scene::{OutOfBounds, TriangleId};

pub mod bitmap;
pub mod image;
pub mod mesh;
mod planes;
pub mod scene;
pub mod setup;
#[cfg(test)]
pub(crate) mod tests;

pub use bitmap::{WireBitmap, WireBitmapParts};
pub use image::{WireImage, WireImageFormat};
pub use mesh::{WireMesh, WireMeshPart};
pub use scene::{
    WireCamera, WireLight, WireLightKind, WireLighting, WireMaterial, WireScene, WireTriangle,
};
pub use setup::{
    WireFrameSetup, WireMethod, WirePackageStats, WireQuality, WireTraceSettings, WireTransmission,
    WireVertexSettings,
};

/// Why wire data does not make a valid domain value.
#[derive(Debug, thiserror::Error)]
pub enum WireError {
    /// A float that must be finite is NaN or infinite.
    #[error("{field} is not finite")]
    NotFinite { field: String },
    /// A domain value outside the bound its type's `validate` documents;
    /// `what` names the value (`camera`, `vertex`).
    #[error("{what} {source}")]
    Bounds {
        what: &'static str,
        source: OutOfBounds,
    },
    /// A value outside its allowed range.
    #[error("{field} = {value}: must be {rule}")]
    OutOfRange {
        field: String,
        value: String,
        rule: &'static str,
    },
    /// An index that names nothing.
    #[error("{field} = {index} is out of range (there are {len})")]
    IndexOutOfRange { field: String, index: u64, len: u64 },
    /// Two sizes that must agree do not.
    #[error("{field} has {actual} entries, expected {expected}")]
    SizeMismatch {
        field: String,
        expected: u64,
        actual: u64,
    },
    /// The same index appears twice where each must be unique.
    #[error("{field} lists {index} twice")]
    Duplicate { field: String, index: u64 },
    /// The scene breaks one of [`vtfarm_scene::Scene::validate`]'s invariants.
    #[error("invalid scene: {0}")]
    InvalidScene(String),
    /// Scene bytes whose SHA-256 is not the announced hash.
    #[error("scene data hash mismatch: announced {announced}, content hashes to {actual}")]
    HashMismatch { announced: String, actual: String },
    /// Nested bincode (scene bytes) that does not decode.
    #[error("cannot decode {what}: {message}")]
    Decode { what: &'static str, message: String },
    /// A progressive frame's stages out of order or too many
    /// ([`crate::check_stages`]).
    #[error("frame stages: {0}")]
    BadStages(String),
}

pub(crate) fn vec3(v: Vec3) -> [f32; 3] {
    v.to_array()
}

/// A finite vector, or the error naming `field`.
pub(crate) fn finite3(field: impl FnOnce() -> String, v: [f32; 3]) -> Result<Vec3, WireError> {
    if v.iter().all(|c| c.is_finite()) {
        Ok(Vec3::from_array(v))
    } else {
        Err(WireError::NotFinite { field: field() })
    }
}

pub(crate) fn finite(field: &str, v: f32) -> Result<f32, WireError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(WireError::NotFinite {
            field: field.to_owned(),
        })
    }
}

pub(crate) fn index(
    field: impl FnOnce() -> String,
    index: u32,
    len: usize,
) -> Result<u32, WireError> {
    if (index as usize) < len {
        Ok(index)
    } else {
        Err(WireError::IndexOutOfRange {
            field: field(),
            index: index.into(),
            len: len as u64,
        })
    }
}

/// Checks a list of triangle ids (reflectors, a package) against a scene of
/// `triangle_count` triangles: every id in range, none twice. Returns them
/// as the scene's triangles, in the list's order.
pub fn check_triangle_ids(
    field: &str,
    ids: &[u32],
    triangle_count: usize,
) -> Result<Vec<TriangleId>, WireError> {
    let mut seen = vec![false; triangle_count];
    for (i, &id) in ids.iter().enumerate() {
        index(|| format!("{field}[{i}]"), id, triangle_count)?;
        let slot = &mut seen[id as usize];
        if *slot {
            return Err(WireError::Duplicate {
                field: field.to_owned(),
                index: id.into(),
            });
        }
        *slot = true;
    }
    Ok(ids.iter().copied().map(TriangleId).collect())
}

/// A list of triangles as the wire carries it (the inverse of
/// [`check_triangle_ids`]).
pub fn wire_triangles(ids: &[TriangleId]) -> Vec<u32> {
    ids.iter().map(|t| t.raw()).collect()
}

/// Wraps a domain bound error, naming the value it is about.
pub(crate) fn bounds(what: &'static str) -> impl FnOnce(OutOfBounds) -> WireError {
    move |source| WireError::Bounds { what, source }
}

/// A value outside its allowed range, as a [`WireError`].
pub(crate) fn out_of_range(field: &str, value: impl ToString, rule: &'static str) -> WireError {
    WireError::OutOfRange {
        field: field.to_owned(),
        value: value.to_string(),
        rule,
    }
}
