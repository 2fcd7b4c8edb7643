//! The farm worker: runs task packages with the vertex tracer (the farm issue fills this crate).
