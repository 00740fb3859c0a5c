//! The processor this binary was built for. `.cargo/config.toml` builds for x86-64-v3 (AVX2,
//! FMA, BMI1/2, F16C, LZCNT, MOVBE: every x86-64 server and desktop processor since 2015):
//! the bake's host work took 5 % less CPU so (`docs/results-bake.md`, stop 68). A processor
//! without them would stop the process at its first such instruction with nothing said, so
//! the binary asks the processor first and says what is missing and how to build for it.

/// The features this build needs that the processor (or its operating system) lacks.
#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
pub fn missing_features() -> Vec<&'static str> {
    use std::arch::x86_64::{__cpuid, __cpuid_count};
    // (CPUID leaf 1 ECX, leaf 7 EBX, leaf 0x8000_0001 ECX) bits; leaf 7 only where the
    // processor has it (others answer an unknown leaf with another's bits).
    #[allow(unused_unsafe)]
    let (basic, extended, more) = unsafe {
        (
            __cpuid(1).ecx,
            if __cpuid(0).eax >= 7 {
                __cpuid_count(7, 0).ebx
            } else {
                0
            },
            __cpuid(0x8000_0001).ecx,
        )
    };
    let bit = |word: u32, n: u32| word >> n & 1 == 1;
    // The operating system saves the vector registers' upper halves (XCR0 bits 1 and 2): read
    // only where it says it has XCR0 (OSXSAVE).
    let os_saves_ymm = bit(basic, 27) && {
        #[allow(unused_unsafe)]
        let xcr0 = unsafe { std::arch::x86_64::_xgetbv(0) };
        xcr0 & 6 == 6
    };
    [
        ("AVX", bit(basic, 28)),
        ("AVX2", bit(extended, 5)),
        ("FMA", bit(basic, 12)),
        ("BMI1", bit(extended, 3)),
        ("BMI2", bit(extended, 8)),
        ("F16C", bit(basic, 29)),
        ("MOVBE", bit(basic, 22)),
        ("LZCNT", bit(more, 5)),
        ("the operating system's AVX state", os_saves_ymm),
    ]
    .into_iter()
    .filter_map(|(name, present)| (!present).then_some(name))
    .collect()
}

/// A build for another target needs nothing it does not check for itself.
#[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
pub fn missing_features() -> Vec<&'static str> {
    Vec::new()
}

#[cfg(test)]
mod tests {
    /// This machine runs the tests, so it has what the build needs: a check that read the
    /// wrong bits would name a feature missing here.
    #[test]
    fn the_processor_running_the_tests_lacks_nothing() {
        assert_eq!(super::missing_features(), Vec::<&str>::new());
    }
}
