//! The WGSL sources, compiled into the binary, and the modules assembled from them. mls.wgsl
//! holds the shared MLS maths; each pass is appended to it, and every module begins with
//! step.wgsl's types and the generated bindings (WGSL has no includes).
//!
//! Storage arrays are bound in ranges: an adapter caps each storage binding (lavapipe at
//! 128 MiB, which a 2M-point step's balls reach), so every array has [`RANGES`] bindings over
//! consecutive slices of its buffer, and the shaders read it through a generated accessor,
//! `NAME_at(i)` (`NAME_set(i, v)` to write). A module built with `split` picks the range from
//! the index's high bits; one built without reads range 0 alone, as a plain array.

/// The step data types (Point, normals, candidates, Sphere) every module but the widening
/// and present passes' begins with.
pub const STEP_WGSL: &str = include_str!("../../../shaders/step.wgsl");

/// The 4-wide tree's entry (Wide, stack links): the widening pass writes it, the trace walk
/// reads it.
pub const WIDE_WGSL: &str = include_str!("../../../shaders/wide.wgsl");

/// The shared MLS maths alone: the step's side and the fit.
pub const MLS_WGSL: &str = concat!(
    include_str!("../../../shaders/mls.wgsl"),
    include_str!("../../../shaders/fit.wgsl")
);

/// The MLS fit over an abstract neighbourhood (the bake's initial fits include it too).
pub const FIT_WGSL: &str = include_str!("../../../shaders/fit.wgsl");

/// The neighbour-mask pass, entry point `expand`, run by the tracer before a step's first
/// refined frame (masks.rs).
pub const EXPAND_WGSL: &str = include_str!("../../../shaders/expand.wgsl");

/// The widening pass, entry point `widen`, run by the tracer before the first frame of a step
/// whose tree it does not hold (widen.rs).
pub const WIDEN_WGSL: &str = include_str!("../../../shaders/widen.wgsl");

/// The trace pass and the water pass, which traces secondary rays: mls.wgsl + fit.wgsl +
/// trace.wgsl + light.wgsl + water.wgsl, entry points `trace_initial`, `trace_refined` and `water`.
pub const TRACE_WGSL: &str = concat!(
    include_str!("../../../shaders/mls.wgsl"),
    include_str!("../../../shaders/fit.wgsl"),
    include_str!("../../../shaders/trace.wgsl"),
    include_str!("../../../shaders/light.wgsl"),
    include_str!("../../../shaders/water.wgsl")
);

/// The shade pass: mls.wgsl + fit.wgsl + light.wgsl + shade.wgsl, entry point `shade`.
pub const SHADE_WGSL: &str = concat!(
    include_str!("../../../shaders/mls.wgsl"),
    include_str!("../../../shaders/fit.wgsl"),
    include_str!("../../../shaders/light.wgsl"),
    include_str!("../../../shaders/shade.wgsl")
);

/// The present pass: the shaded image into an Rgba8Unorm texture, entry point `present`.
pub const PRESENT_WGSL: &str = include_str!("../../../shaders/present.wgsl");

/// The binding of the present pass's texture.
pub const TEXTURE_BINDING: u32 = 101;

/// Traversal stack sizes the trace pass is built with. WGSL sizes private arrays by constants
/// only, so each size is a separate module; a smaller stack costs less per-thread memory
/// (about 6 % of the frame time on an H100 going from 64 to 32 entries).
pub const TRACE_STACK_SIZES: [u32; 3] = [32, 64, 96];

/// Bindings per storage array: an array may span this many of the adapter's largest
/// bindings (3 × 128 MiB on lavapipe: the balls of 16M points). The trace pass's arrays then
/// take `context::STORAGE_BUFFERS_NEEDED` storage bindings per stage (36), within lavapipe's
/// 48.
pub const RANGES: u32 = 3;

/// The binding of a pass's uniform block, after every array's ranges.
pub const UNIFORM_BINDING: u32 = 100;

/// A storage array of a pass: bound at `slot × RANGES + r` for range r of group `group`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RangedArray {
    pub name: &'static str,
    /// The WGSL element type.
    pub element: &'static str,
    /// Its size in bytes (the array stride).
    pub element_size: u64,
    pub group: u32,
    pub slot: u32,
    pub writable: bool,
}

const fn array(
    name: &'static str,
    element: &'static str,
    element_size: u64,
    group: u32,
    slot: u32,
    writable: bool,
) -> RangedArray {
    RangedArray {
        name,
        element,
        element_size,
        group,
        slot,
        writable,
    }
}

/// The step's arrays as the trace, water and shade passes bind them (group 0).
/// A step's arrays by name, so that code binding one says which (their order in
/// `STEP_ARRAYS` is their slot).
pub mod step_array {
    use super::{RangedArray, array};

    pub const POINTS: RangedArray = array("points", "Point", 16, 0, 0, false);
    pub const NORMALS: RangedArray = array("normals", "u32", 4, 0, 1, false);
    pub const CLUSTER_START: RangedArray = array("cluster_start", "u32", 4, 0, 2, false);
    pub const BALLS: RangedArray = array("balls", "Ball", 16, 0, 4, false);
    pub const SPHERES: RangedArray = array("spheres", "Sphere", 16, 0, 5, false);
    pub const FIELD: RangedArray = array("field", "f32", 4, 0, 7, false);
    pub const BALL_CUBIC: RangedArray = array("ball_cubic", "vec2<u32>", 8, 0, 10, false);
    pub const BALL_STATES: RangedArray = array("ball_states", "u32", 4, 0, 8, false);
    pub const BALL_H: RangedArray = array("ball_h", "u32", 4, 0, 9, false);
}

pub const STEP_ARRAYS: [RangedArray; 9] = [
    step_array::POINTS,
    step_array::NORMALS,
    step_array::CLUSTER_START,
    step_array::BALLS,
    step_array::SPHERES,
    step_array::FIELD,
    step_array::BALL_CUBIC,
    step_array::BALL_STATES,
    step_array::BALL_H,
];

/// The neighbour masks and the expanded candidates as the trace and shade passes bind them
/// (group 2): held by the tracer for the step it last refined, not by the step (masks.rs).
pub const MASK_ARRAYS: [RangedArray; 2] = [
    array("neighbour_masks", "u32", 4, 2, 0, false),
    array("candidates", "u32", 4, 2, 1, false),
];

/// The 4-wide tree the trace walk descends, as the trace and water passes bind it (group 3):
/// held by the tracer for the step it last drew, widened from that step's BVH2 (widen.rs).
pub const TREE_ARRAYS: [RangedArray; 1] = [array("wide_nodes", "Wide", 128, 3, 0, false)];

/// The widening pass's arrays (widen.wgsl, group 0): a step's BVH2 in, the wide tree out.
pub const WIDEN_ARRAYS: [RangedArray; 2] = [
    array("bvh_nodes", "BvhNode", 16, 0, 0, false),
    array("wide_nodes", "Wide", 128, 0, 1, true),
];

/// A frame's arrays (group 1): the hits, three 16-byte words per pixel, and the pixels.
pub const FRAME_ARRAYS: [RangedArray; 2] = [
    array("hits", "vec4<u32>", 16, 1, 0, true),
    array("image", "u32", 4, 1, 1, true),
];

/// The present pass's array (present.wgsl, group 0): the shaded image.
pub const PRESENT_ARRAYS: [RangedArray; 1] = [array("image", "u32", 4, 0, 0, false)];

/// The neighbour-mask pass's arrays (expand.wgsl, group 0).
pub const EXPAND_ARRAYS: [RangedArray; 7] = [
    array("points", "Point", 16, 0, 0, false),
    array("normals", "u32", 4, 0, 1, false),
    array("cluster_start", "u32", 4, 0, 2, false),
    array("cluster_ids", "u32", 4, 0, 3, false),
    array("neighbour_masks", "u32", 4, 0, 4, true),
    array("cluster_base", "u32", 4, 0, 5, false),
    array("candidates", "u32", 4, 0, 6, true),
];

/// Elements of `element_size` bytes in one range under a binding limit of `limit` bytes:
/// the largest power of two that fits (a shift and a mask pick the range in the shader).
pub fn elements_per_range(limit: u64, element_size: u64) -> u64 {
    let fit = (limit / element_size.max(1)).max(1);
    (1u64 << fit.ilog2()).min(1 << 31)
}

/// Declarations and accessors of `arrays` for bindings of at most `limit` bytes.
pub fn ranged_wgsl(arrays: &[RangedArray], limit: u64, split: bool) -> String {
    let mut out = String::new();
    for a in arrays {
        let access = if a.writable { "read_write" } else { "read" };
        let ranges = if split { RANGES } else { 1 };
        for r in 0..ranges {
            out += &format!(
                "@group({}) @binding({}) var<storage, {access}> {}_{r}: array<{}>;\n",
                a.group,
                a.slot * RANGES + r,
                a.name,
                a.element
            );
        }
        let (name, ty) = (a.name, a.element);
        if !split {
            out += &format!("fn {name}_at(i: u32) -> {ty} {{\n    return {name}_0[i];\n}}\n");
            if a.writable {
                out += &format!("fn {name}_set(i: u32, v: {ty}) {{\n    {name}_0[i] = v;\n}}\n");
            }
            continue;
        }
        let shift = elements_per_range(limit, a.element_size).ilog2();
        let pick = |body: &dyn Fn(u32) -> String| {
            let mut s = format!(
                "    let j = i & {}u;\n    switch i >> {shift}u {{\n",
                (1u64 << shift) - 1
            );
            for r in 0..RANGES {
                let label = if r + 1 == RANGES {
                    "default".to_string()
                } else {
                    format!("case {r}u")
                };
                s += &format!("        {label}: {{\n            {}\n        }}\n", body(r));
            }
            s + "    }\n"
        };
        out += &format!(
            "fn {name}_at(i: u32) -> {ty} {{\n{}}}\n",
            pick(&|r| format!("return {name}_{r}[j];"))
        );
        if a.writable {
            out += &format!(
                "fn {name}_set(i: u32, v: {ty}) {{\n{}}}\n",
                pick(&|r| format!("{name}_{r}[j] = v;"))
            );
        }
    }
    out
}

/// The constants the shaders share with Rust, written from the Rust definitions so that each
/// has one source: the hit statuses ([`crate::status`]), the shade modes
/// ([`crate::ShadeMode`]), the candidates a ray refines ([`slosh_mls::MAX_CANDIDATES`]) and
/// the stack-link packing ([`crate::MAX_LINK_FIRST`]), the wide tree's empty slot
/// ([`crate::layout::EMPTY_SLOT`]), the octahedral step and the narrow candidates' constants
/// (`slosh_cache::octahedral`, `slosh_cache::candidates`), and the water pass's stage
/// ([`crate::water`]). Prepended to every module.
pub fn shared_constants_wgsl() -> String {
    use crate::{ShadeMode, status};
    let mut out =
        String::from("// Generated by crates/render's shaders.rs from its Rust sources.\n");
    let mut constant = |name: &str, value: u32| {
        out += &format!("const {name}: u32 = {value}u;\n");
    };
    for (name, value) in [
        ("STATUS_MISS", status::MISS),
        ("STATUS_CONVERGED", status::CONVERGED),
        ("STATUS_ITERATION_LIMIT", status::ITERATION_LIMIT),
        ("STATUS_NO_SUPPORT", status::NO_SUPPORT),
        ("STATUS_DEGENERATE_FIT", status::DEGENERATE_FIT),
        ("STATUS_DROPLET", status::DROPLET),
        ("MODE_SHADE", ShadeMode::Shade as u32),
        ("MODE_NORMALS", ShadeMode::Normals as u32),
        ("MODE_STATUS", ShadeMode::Status as u32),
        ("MODE_BACKFACES", ShadeMode::Backfaces as u32),
        ("MAX_CANDIDATES", slosh_mls::MAX_CANDIDATES),
        ("LINK_COUNT_SHIFT", crate::MAX_LINK_FIRST.count_ones()),
        ("LINK_FIRST", crate::MAX_LINK_FIRST),
        (
            "OCTAHEDRAL_STEP_BITS",
            slosh_cache::octahedral::OCTAHEDRAL_STEP.to_bits(),
        ),
        ("WIDE_CLUSTER", slosh_cache::candidates::WIDE_CLUSTER),
        ("NARROW_BIAS", slosh_cache::candidates::NARROW_BIAS),
    ] {
        constant(name, value);
    }
    out += &format!("const EMPTY_SLOT: f32 = {:e};\n", crate::layout::EMPTY_SLOT);
    out += &format!(
        "const SURFACE_COLOUR: vec3<f32> = {};\n",
        crate::colormap::vec3_literal(&crate::colormap::SURFACE_COLOUR)
    );

    out + &crate::water::water_wgsl()
}

/// The trace module (trace, water) with a traversal stack of `entries`.
pub fn trace_wgsl(entries: u32, limit: u64, split: bool) -> String {
    let source = TRACE_WGSL.replace(
        "const STACK_SIZE: u32 = 64u;",
        &format!("const STACK_SIZE: u32 = {entries}u;"),
    );
    frame_module(&source, limit, split)
}

/// The shade module (with the colour maps generated from `colormap.rs`).
pub fn shade_wgsl(limit: u64, split: bool) -> String {
    frame_module(
        &format!("{}{SHADE_WGSL}", crate::colormap::colormap_wgsl()),
        limit,
        split,
    )
}

/// mls.wgsl alone, with the bindings it reads.
pub fn mls_wgsl(limit: u64, split: bool) -> String {
    frame_module(MLS_WGSL, limit, split)
}

/// The neighbour-mask pass's module.
pub fn expand_wgsl(limit: u64, split: bool) -> String {
    format!(
        "{}{STEP_WGSL}{}{EXPAND_WGSL}",
        shared_constants_wgsl(),
        ranged_wgsl(&EXPAND_ARRAYS, limit, split)
    )
}

/// Threads of a widening workgroup: one per BVH2 node.
pub const WIDEN_GROUP: u32 = 64;

/// The widening pass's module.
pub fn widen_wgsl(limit: u64, split: bool) -> String {
    format!(
        "{}const WIDEN_GROUP: u32 = {WIDEN_GROUP}u;\n{WIDE_WGSL}{}{WIDEN_WGSL}",
        shared_constants_wgsl(),
        ranged_wgsl(&WIDEN_ARRAYS, limit, split)
    )
}

/// The present pass's module.
pub fn present_wgsl(limit: u64, split: bool) -> String {
    format!(
        "{}{PRESENT_WGSL}",
        ranged_wgsl(&PRESENT_ARRAYS, limit, split)
    )
}

fn frame_module(source: &str, limit: u64, split: bool) -> String {
    let arrays: Vec<RangedArray> = STEP_ARRAYS
        .iter()
        .chain(&FRAME_ARRAYS)
        .chain(&MASK_ARRAYS)
        .chain(&TREE_ARRAYS)
        .copied()
        .collect();
    format!(
        "{}{STEP_WGSL}{WIDE_WGSL}{}{source}",
        shared_constants_wgsl(),
        ranged_wgsl(&arrays, limit, split)
    )
}
