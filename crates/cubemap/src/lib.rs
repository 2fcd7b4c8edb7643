//! Reflector cube maps with reflection-point search (Estalella, Martin,
//! Drettakis, Tost, Devillers, Cazals: "Accurate Interactive Specular
//! Reflections on Curved Objects", VMV 2005) and the plain environment map
//! it is compared with.
//!
//! # The cube-map method (`cubemap`, `cubemap-grid`)
//! 1. Pre-process (per reflector, view independent; [`ReflectorMaps`],
//!    §4.1): position and normal cube maps around the reflector, rasterized
//!    from its triangles subdivided `subdivisions` times. An open reflector
//!    (the cover glass) gets its centre moved behind it and its maps
//!    continued beyond the rim by a fitted quadric (see `maps`).
//! 2. For every vertex of the reflected meshes (all scene triangles but the
//!    reflector and its transparent back, see [`reflected_triangle_flags`])
//!    [`search`] finds the reflection point R by following the projected
//!    bisector with the midpoint method and an adaptive step until
//!    E = (1 - B·N)/2 < ε (§4.2–4.3); the virtual vertex V' lies behind R
//!    along the eye ray at |V - R|. Vertices behind the reflector are
//!    searched with their mirror image (§6.1). With the grid (§5) only the
//!    corners of a bounding grid per mesh are searched and mesh vertices
//!    interpolated in their cells.
//! 3. Triangles wholly hidden, or with a failed search, are dropped; the
//!    rest are rasterized with a depth test into the reflector's pixels,
//!    keeping fragments behind the reflector's surface.
//! 4. A covered pixel interpolates the original triangle's position and
//!    normal with the virtual fragment's barycentrics and shades that
//!    surface point with the full Whitted tracer (one level less deep),
//!    lit from the direction of the pixel's reflector point. Pixels no
//!    virtual triangle covers fall back to an environment map from the
//!    reflector's centroid. `shade_reflector` adds local and transmitted
//!    light.
//!
//! The search is preconditioned with the inverse Jacobian of the bisector
//! field (see `search`); without it concave pieces such as the cockpit's
//! glass do not converge.
//!
//! # Not supported
//! Reflectors that are neither convex nor concave (saddles, torus-like
//! shapes, several pieces at once: [`classify`] says so and
//! [`ReflectorShape::warning`] words it), interreflections of the reflector
//! in itself, and edges of large triangles, which are reflected as straight
//! lines between their reflected corners (§8).
//!
//! # The environment map (`envmap`)
//! [`EnvironmentMap`]: one colour cube map rendered from the reflector's
//! centroid by the rasterizer, looked up bilinearly in each pixel's mirror
//! direction.

mod cube;
mod envmap;
mod extension;
mod maps;
mod mesh;
mod method;
mod raster;
mod reflected;
mod search;
mod shape;
mod vertices;

pub use cube::CubeLayout;
pub use envmap::{EnvironmentCube, EnvironmentMap};
pub use maps::{ReflectorMaps, SurfaceSample, TexelKind};
pub use method::{CubeMapConfig, CubeMapMethod, PreparedReflector};
pub use reflected::{BACK_SUFFIX, reflected_triangle_flags};
pub use search::{Region, SearchSettings, VirtualVertex, search};
pub use shape::{ReflectorShape, classify};
pub use vertices::GridSettings;

#[cfg(test)]
mod tests;
