//! Per-vertex reflection and refraction, PVRR (Kakimoto et al.).
