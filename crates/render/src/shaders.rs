//! The WGSL sources, compiled into the binary. mls.wgsl holds the shared MLS maths and the
//! step bindings; each pass is appended to it (WGSL has no includes).

/// The shared MLS maths alone (validated on its own in the tests).
pub const MLS_WGSL: &str = include_str!("../../../shaders/mls.wgsl");

/// The neighbour-mask pass, standalone, entry point `expand`.
pub const EXPAND_WGSL: &str = include_str!("../../../shaders/expand.wgsl");

/// The trace pass and the water pass, which traces secondary rays: mls.wgsl + trace.wgsl +
/// light.wgsl + water.wgsl, entry points `trace_initial`, `trace_refined` and `water`.
pub const TRACE_WGSL: &str = concat!(
    include_str!("../../../shaders/mls.wgsl"),
    include_str!("../../../shaders/trace.wgsl"),
    include_str!("../../../shaders/light.wgsl"),
    include_str!("../../../shaders/water.wgsl")
);

/// The shade pass: mls.wgsl + light.wgsl + shade.wgsl, entry point `shade`.
pub const SHADE_WGSL: &str = concat!(
    include_str!("../../../shaders/mls.wgsl"),
    include_str!("../../../shaders/light.wgsl"),
    include_str!("../../../shaders/shade.wgsl")
);

/// Traversal stack sizes the trace pass is built with. WGSL sizes private arrays by constants
/// only, so each size is a separate module; a smaller stack costs less per-thread memory
/// (about 6 % of the frame time on an H100 going from 64 to 32 entries).
pub const TRACE_STACK_SIZES: [u32; 2] = [32, 64];

/// The trace pass with a traversal stack of `entries` (TRACE_WGSL has 64).
pub fn trace_wgsl(entries: u32) -> String {
    TRACE_WGSL.replace(
        "const STACK_SIZE: u32 = 64u;",
        &format!("const STACK_SIZE: u32 = {entries}u;"),
    )
}
