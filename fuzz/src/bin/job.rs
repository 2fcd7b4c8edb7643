//! Fuzz target: see `vtfarm_fuzz::job`.
fn main() {
    afl::fuzz!(|data: &[u8]| vtfarm_fuzz::job(data));
}
