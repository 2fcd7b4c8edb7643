//! Wavefront OBJ/MTL import and export (filled in by the loader work).
