//! Reflector cube maps with reflection-point search (Estalella, Martin,
//! Drettakis, Tost, Devillers, Cazals: "Accurate Interactive Specular
//! Reflections on Curved Objects", VMV 2005) and the plain environment map
//! it is compared with.
//!
//! # The cube-map method (`cubemap`, `cubemap-grid`)
//! 1. Pre-process (per reflector, view independent; [`ReflectorMaps`],
//!    §4.1): position and normal cube maps around the reflector, rasterized
//!    from its triangles split `subdivisions` times (Phong tessellation).
//!    [`classify`] tells convex from concave. An open reflector (the cover
//!    glass) gets its centre moved off it to the side of its centres of
//!    curvature and its maps continued beyond the rim by a fitted quadric
//!    (the paper's "accompanying closed object", §6.2, made automatically).
//! 2. The reflected meshes are every scene triangle but the reflector and
//!    the transparent back of its object ([`reflected_triangle_flags`]),
//!    with long triangles split into a lattice (see `mesh`; view
//!    independent, so built in the pre-processing). For each of
//!    their vertices V, [`search`] finds the reflection point R by
//!    following the projected bisector with the midpoint method and an
//!    adaptive step until E = (1 - B·N)/2 < ε (§4.2–4.3); V' lies behind R
//!    along the eye ray at |V - R|. Vertices behind the reflector are
//!    searched with their mirror image (§6.1) and flagged
//!    [`Region::Hidden`]. With the grid (§5) only the corners of a bounding
//!    grid per object are searched and the vertices interpolated in their
//!    cells ([`GridSettings`]).
//! 3. Triangles wholly hidden, or with a failed search, are dropped; the
//!    rest are rasterized with a depth test into the reflector's pixels,
//!    keeping fragments behind the reflector's surface.
//! 4. A covered pixel maps the virtual fragment's barycentrics back to the
//!    original triangle and shades that surface point with the full
//!    Whitted tracer (one level less deep), seen from the pixel's reflector
//!    point. Pixels no virtual triangle covers show an environment map
//!    rendered from the reflector's centroid. `shade_reflector` adds local
//!    and transmitted light.
//!
//! # Deviations from the paper
//! - The bisector field is preconditioned with the inverse of its Jacobian
//!   (see `search`): on a concave piece whose eye and vertex lie beyond the
//!   focal distance (the cockpit's glass up its 0.45 m radius) the paper's
//!   field is not attracting and the search does not converge.
//! - The search runs in a gnomonic chart centred on its start rather than on
//!   cube faces (no seams), starting from the bisector at the centre when
//!   that lies on the reflector and from the reflector's middle otherwise.
//! - Open reflectors are continued by a quadric instead of a modelled
//!   closed object; long reflected triangles are split (§8 names their
//!   edges as a limitation); grid cells leave failed corners out.
//!
//! # Not supported
//! Reflectors that are neither convex nor concave (saddles, torus-like
//! shapes, several pieces at once: [`classify`] says so and
//! [`ReflectorShape::warning`] words it; they are rendered anyway and may
//! be wrong), strongly curved open reflectors a quadric does not continue,
//! interreflections of the reflector in itself, and refraction (the
//! transmitted light is ray traced by `shade_reflector`).
//!
//! # The environment map (`envmap`)
//! [`EnvironmentMap`]: one colour cube map of the scene without the
//! reflector and its back, rendered from the reflector's centroid by the
//! rasterizer (local Phong, no shadows), looked up bilinearly in each
//! pixel's mirror direction; the object comes from the nearest texel.
//!
//! Every part is deterministic: searches depend only on their vertex,
//! rasterization resolves ties by triangle index, and no floating-point sum
//! depends on scheduling.

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
pub use shape::{ReflectorShape, classify, unsupported_reflector_warnings};
pub use vertices::GridSettings;

#[cfg(test)]
mod tests;
