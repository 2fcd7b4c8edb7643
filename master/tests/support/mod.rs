//! Test support shared by the master's integration tests.

// Each test file uses a part of the harness.
#[allow(dead_code)]
pub(crate) mod pair;
