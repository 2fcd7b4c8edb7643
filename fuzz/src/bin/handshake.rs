//! Fuzz target: see `vtfarm_fuzz::handshake`.
fn main() {
    afl::fuzz!(|data: &[u8]| vtfarm_fuzz::handshake(data));
}
