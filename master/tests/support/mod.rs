//! Test support shared by the master's integration tests.

pub(crate) mod pair;
