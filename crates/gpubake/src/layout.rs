//! The uniform block the search passes share, mirrored in `shaders/neighbour_grid.wgsl`, and
//! the WGSL modules they are built from.

use bytemuck::{Pod, Zeroable};

/// The most nearest points one query returns (a private array in `shaders/nearest.wgsl`, whose
/// constant this is).
pub const NEAREST_MAX: usize = 32;

/// Threads per workgroup of every search pass (`@workgroup_size(64)`).
pub(crate) const WORKGROUP: u32 = 64;

/// `SearchParams` in `shaders/neighbour_grid.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct SearchParams {
    /// xyz: the grid's low corner; w: cells per unit length.
    pub lo: [f32; 4],
    pub count: u32,
    pub first: u32,
    pub side: u32,
    pub wanted: u32,
    pub flags: u32,
    pub out_base: u32,
    pub row_threads: u32,
    pub margin: f32,
    pub shells: u32,
    /// With `FLAG_PAIRS`: how near its list's reach (or the cut) a member is appended.
    pub band: f32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// `Settings` in `shaders/bake_fit.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct FitSettings {
    pub count: u32,
    pub first: u32,
    pub row_threads: u32,
    pub list_base: u32,
    pub has_normals: u32,
    /// 0: the weighted mean of the data normals; 1: the covariance.
    pub normals_mode: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// `ComponentParams` in `shaders/spray_components.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ComponentParams {
    pub first: u32,
    pub count: u32,
    pub list_base: u32,
    pub row_threads: u32,
}

/// `UnionParams` in `shaders/cluster_unions.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct UnionParams {
    pub first_cluster: u32,
    pub clusters: u32,
    pub points: u32,
    pub size: u32,
    pub list_base: u32,
    pub row_groups: u32,
    /// 0: count each union's ids; 1: write them.
    pub write: u32,
    pub _pad0: u32,
}

/// Words of the bitset a cluster's union is set in (`SPAN_WORDS` in
/// `shaders/cluster_unions.wgsl`): ids spanning up to 64Ki indices, or lying within 32Ki of
/// the lowest or of the highest, in 8 KiB of workgroup memory (of the 16 KiB every adapter
/// gives).
pub const UNION_SPAN_WORDS: u32 = 2048;

/// A cluster's count where an id falls outside the bitset (`SPAN_WIDE`): the host merges it.
pub(crate) const SPAN_WIDE: u32 = u32::MAX;

/// `TreeParams` in `shaders/bvh_build.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TreeParams {
    pub leaves: u32,
    pub row_threads: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// `TreeNode` in `shaders/bvh_build.wgsl`: a `slosh_cache::BvhNode` as the GPU reads it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TreeNode {
    pub lo: [f32; 3],
    pub count: u32,
    pub hi: [f32; 3],
    pub first: u32,
}

/// `MAX_DEPTH` in `shaders/bvh_build.wgsl`: the deepest inner node a build's depth pass
/// measures (64 bits of key and 32 of index bound any chain).
pub(crate) const TREE_MAX_DEPTH: u32 = 96;

/// `SearchParams::flags`: the points have data normals.
pub(crate) const FLAG_NORMALS: u32 = 1;
/// `SearchParams::flags`: links are wanted.
pub(crate) const FLAG_LINKS: u32 = 2;
/// `SearchParams::flags`: the caller's points came in Morton order, so a walk meets them in
/// index order.
pub(crate) const FLAG_SORTED: u32 = 4;
/// `SearchParams::flags`: the dispatch's points are the `todo` list's (the nearest-points pass).
pub(crate) const FLAG_TODO: u32 = 8;

/// `SearchParams::flags`: the lists pass appends each member within `band` of its list's
/// reach, or of the cut where the cap cut the list, with every member it marks
/// [`FAR_BIT`], to the pairs (`FLAG_PAIRS` in `shaders/lists.wgsl`).
pub(crate) const FLAG_PAIRS: u32 = 16;

/// `cut[t].w` of a point the lists pass left to a coarser grid (`DEFERRED` in
/// `shaders/lists.wgsl`).
pub(crate) const DEFERRED: u32 = u32::MAX;

/// Where the nearest-points pass gave up (`UNFINISHED` in `shaders/nearest.wgsl`).
pub(crate) const UNFINISHED: u32 = u32::MAX;

/// Where the lists pass marks a link (`LINK_BIT` in `shaders/lists.wgsl`).
pub(crate) const LINK_BIT: u32 = 0x8000_0000;
/// Where the lists pass marks a member of a cut list whose squared distance lies within
/// [`NEAR_CUT`] of the cut's (`FAR_BIT` in `shaders/lists.wgsl`): only those can be the
/// list's farthest point in f64, which the host measures for its reach.
pub(crate) const FAR_BIT: u32 = 0x4000_0000;
/// The bits of a list word that hold the point's index: a step holds fewer points.
pub(crate) const ID_MASK: u32 = !(LINK_BIT | FAR_BIT);
/// How far below the cut's squared distance, relatively, a member is marked with
/// [`FAR_BIT`]: the pass's squared distances (differences of split positions, in f32) lie
/// within about 5e-7 of f64's, relatively, so a member unmarked lies nearer in f64 than the
/// point the cut fell on. Twenty times that.
pub(crate) const NEAR_CUT: f32 = 1e-5;

/// The list words' constants, for the modules that read or write them.
fn list_word_consts() -> String {
    format!(
        "const LINK_BIT: u32 = {LINK_BIT}u;\nconst FAR_BIT: u32 = {FAR_BIT}u;\n\
         const ID_MASK: u32 = {ID_MASK}u;\nconst NEAR_CUT: f32 = {NEAR_CUT:e};\n\
         const FLAG_PAIRS: u32 = {FLAG_PAIRS}u;\n"
    )
}

const GRID_WGSL: &str = include_str!("../../../shaders/neighbour_grid.wgsl");

/// The bindings of the passes over a batch of lists.
const LIST_BATCH_WGSL: &str = include_str!("../../../shaders/list_batch.wgsl");

/// The nearest-points module: entry point `nearest`.
pub fn nearest_source() -> String {
    format!(
        "const NEAREST_MAX: u32 = {NEAREST_MAX}u;\n{GRID_WGSL}{}",
        include_str!("../../../shaders/nearest.wgsl")
    )
}

/// The orientation votes' module: entry point `orient_votes`.
pub fn orient_votes_source() -> String {
    format!(
        "{}{GRID_WGSL}{}",
        slosh_mls::vote_word_wgsl(),
        include_str!("../../../shaders/orient_votes.wgsl")
    )
}

/// The lists module: entry points `cut_lists` and `write_lists`.
pub fn lists_source() -> String {
    format!(
        "{}{GRID_WGSL}{}",
        list_word_consts(),
        include_str!("../../../shaders/lists.wgsl")
    )
}

/// The cluster unions' module, its bitset `span_words` words wide: entry point
/// `cluster_unions`.
pub fn unions_source(span_words: u32) -> String {
    format!(
        "const ID_MASK: u32 = {ID_MASK}u;\nconst SPAN_WIDE: u32 = {SPAN_WIDE}u;\n\
         const SPAN_WORDS: u32 = {span_words}u;\n{LIST_BATCH_WGSL}{}",
        include_str!("../../../shaders/cluster_unions.wgsl")
    )
}

/// The spray components' module: entry points `join_links` and `flatten`.
pub fn components_source() -> String {
    format!(
        "{}{LIST_BATCH_WGSL}{}",
        list_word_consts(),
        include_str!("../../../shaders/spray_components.wgsl")
    )
}

/// The BVH build's module: entry points `link_nodes`, `measure_depths`, `place_nodes`,
/// `fit_boxes`, `next_depth`.
pub fn tree_source() -> String {
    format!(
        "const MAX_DEPTH: u32 = {TREE_MAX_DEPTH}u;\n{}",
        include_str!("../../../shaders/bvh_build.wgsl")
    )
}

/// The initial-fits module: entry point `initial_fits`, the tracer's fit maths after it.
pub fn fits_source() -> String {
    format!(
        "{}{}{}",
        list_word_consts(),
        include_str!("../../../shaders/bake_fit.wgsl"),
        slosh_render::shaders::FIT_WGSL
    )
}
