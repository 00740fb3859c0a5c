//! The WGSL sources, compiled into the binary. mls.wgsl holds the shared MLS maths and the
//! step bindings; each pass is appended to it (WGSL has no includes).

/// The shared MLS maths alone (validated on its own in the tests).
pub const MLS_WGSL: &str = include_str!("../../../shaders/mls.wgsl");

/// The neighbour-mask pass, standalone, entry point `expand`.
pub const EXPAND_WGSL: &str = include_str!("../../../shaders/expand.wgsl");

/// The trace pass: mls.wgsl + trace.wgsl, entry points `trace_initial` and `trace_refined`.
pub const TRACE_WGSL: &str = concat!(
    include_str!("../../../shaders/mls.wgsl"),
    include_str!("../../../shaders/trace.wgsl")
);

/// The shade pass: mls.wgsl + shade.wgsl, entry point `shade`.
pub const SHADE_WGSL: &str = concat!(
    include_str!("../../../shaders/mls.wgsl"),
    include_str!("../../../shaders/shade.wgsl")
);
