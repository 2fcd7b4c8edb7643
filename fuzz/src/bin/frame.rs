//! Fuzz target: see `vtfarm_fuzz::frame`.
fn main() {
    afl::fuzz!(|data: &[u8]| vtfarm_fuzz::frame(data));
}
