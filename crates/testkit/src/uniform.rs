//! A seeded stream of uniform numbers for tests that want varied but repeatable input
//! without a generator crate's state to carry: xorshift64 (13, 7, 17), its top 53 bits.

/// Numbers in [0, 1) from `seed` (not zero), the same stream on every machine.
pub fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}
