//! Vertex normals: angle-weighted smoothing with a crease angle (filled in by the loader work).
