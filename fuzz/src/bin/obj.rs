//! Fuzz target: see `vtfarm_fuzz::obj`.
fn main() {
    afl::fuzz!(|data: &[u8]| vtfarm_fuzz::obj(data));
}
