//! The base-frame rasterizer (the paper's OpenGL pass): a multi-threaded
//! z-buffer rasterizer with the camera convention of `vtfarm_scene::Camera`,
//! producing the shaded base frame (per-pixel Phong, no ray tracing) and the
//! ID buffer (object id, triangle id, depth per pixel).
//!
//! Architecture invariant: deterministic; the same scene and camera give the
//! same ID buffer bit for bit on any machine and thread count (workers rebuild
//! it locally instead of receiving it).

use vtfarm_scene::{NONE, ObjectId, TriangleId};

/// Per-pixel visibility: which object and triangle is seen, and at what view
/// depth. `NONE` where nothing is.
#[derive(Clone, Debug, PartialEq)]
pub struct IdBuffer {
    pub width: u32,
    pub height: u32,
    pub object: Vec<ObjectId>,
    pub triangle: Vec<TriangleId>,
    /// View depth (distance along the camera's forward axis); infinity where empty.
    pub depth: Vec<f32>,
}

impl IdBuffer {
    /// An empty buffer.
    pub fn new(width: u32, height: u32) -> Self {
        let n = (width * height) as usize;
        IdBuffer { width, height, object: vec![NONE; n], triangle: vec![NONE; n], depth: vec![f32::INFINITY; n] }
    }

    /// The index of pixel (`x`, `y`).
    pub fn index(&self, x: u32, y: u32) -> usize {
        (y * self.width + x) as usize
    }
}
