//! A cache step streamed into GPU storage buffers, in two halves. The host half
//! ([`HostStep`]) opens and checks the file, checksums its raw sections, decodes the sections
//! it reads and checks the tree; it needs no device and runs on any thread. The GPU half
//! ([`GpuStep::create`]) creates the buffers, fills one `mapped_at_creation` staging buffer in
//! parallel (raw sections straight from the mapped file, compressed ones decoded run by run
//! straight into it), and records the copies and the per-step passes into the caller's
//! encoder without waiting. The colour field has its own buffer, so switching fields uploads
//! only the field.

use std::path::Path;
use std::time::Instant;

use rayon::prelude::*;
use slosh_cache::{CacheFile, Encoding, SectionEntry, Transform, names};

use bytemuck::Zeroable;

use crate::bindings::{bind_entries, needs_split};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::expand::ExpandInputs;
use crate::layout::ExpandSettings;
use crate::shaders::{EXPAND_ARRAYS, RangedArray, STEP_ARRAYS, step_array};
use crate::staging::StagingPool;

/// The deepest BVH the trace shader's largest traversal stack (96 entries) holds: the wide
/// tree has 31 levels, each stacking up to three slots.
pub const MAX_BVH_DEPTH: u64 = 62;

/// The traversal stack packs a node as `first | count << 28` (trace.wgsl: `link`), so a
/// leaf holds at most this many items and `first` stays below 2^28.
pub const MAX_LINK_FIRST: u32 = (1 << 28) - 1;
pub const MAX_LEAF_LINK_COUNT: u32 = u32::MAX >> MAX_LINK_FIRST.count_ones();

/// Checks that the `bvh_nodes` section is a tree the trace pass can walk: every node packs
/// into a stack link, a leaf's items lie in the item list, and an inner node's children come
/// after it (so every descent ends: trace.wgsl is compiled without loop guards,
/// `Tracer`'s `trace_module`).
fn check_tree(nodes: &[u8], items: u64) -> std::result::Result<(), String> {
    let word = |c: &[u8], at: usize| u32::from_le_bytes([c[at], c[at + 1], c[at + 2], c[at + 3]]);
    let node_count = (nodes.len() / 32) as u64;
    for (i, node) in nodes.chunks_exact(32).enumerate() {
        let (count, first) = (word(node, 12), word(node, 28));
        let (wide, first64) = (u64::from(count), u64::from(first));
        let problem = if count > MAX_LEAF_LINK_COUNT || first > MAX_LINK_FIRST {
            format!(
                "has count {count} and first {first}; the tracer takes leaves of at most {MAX_LEAF_LINK_COUNT} items and indices below {}",
                MAX_LINK_FIRST + 1
            )
        } else if count > 0 && first64 + wide > items {
            format!(
                "holds items {first}..{} of a list of {items}",
                first64 + wide
            )
        } else if count == 0 && (first64 <= i as u64 || first64 + 1 >= node_count) {
            format!(
                "has children {first} and {} in a tree of {node_count} nodes (children must follow their parent)",
                first64 + 1
            )
        } else {
            continue;
        };
        return Err(format!(
            "BVH node {i} (byte {} of section '{}') {problem}",
            i * 32,
            names::BVH_NODES
        ));
    }
    Ok(())
}

/// The storage buffers of one step.
#[derive(Debug)]
pub struct StepBuffers {
    pub points: wgpu::Buffer,
    pub normals: wgpu::Buffer,
    /// Read by the neighbour-mask pass only.
    pub reach: wgpu::Buffer,
    /// Written by the neighbour-mask pass at upload: a block of words per cluster (see
    /// [`mask_row`]).
    pub masks: wgpu::Buffer,
    pub cluster_start: wgpu::Buffer,
    pub cluster_ids: wgpu::Buffer,
    pub balls: wgpu::Buffer,
    pub spheres: wgpu::Buffer,
    pub bvh_nodes: wgpu::Buffer,
    pub bvh_items: wgpu::Buffer,
    pub field: wgpu::Buffer,
    /// Written by the leaf-sphere pass at upload: each BVH item's sphere, 16 bytes.
    pub leaf_spheres: wgpu::Buffer,
    /// Written by the widening pass at upload: the 4-wide tree the walk descends, one
    /// `WIDE_NODE_BYTES` entry per BVH2 node (a leaf's unused).
    pub wide_nodes: wgpu::Buffer,
}

impl StepBuffers {
    /// The buffers of the trace and shade passes' step bind group, in `STEP_ARRAYS`' order.
    pub fn in_binding_order(&self) -> [&wgpu::Buffer; STEP_ARRAYS.len()] {
        [
            &self.points,
            &self.normals,
            &self.masks,
            &self.cluster_start,
            &self.cluster_ids,
            &self.balls,
            &self.spheres,
            &self.bvh_nodes,
            &self.bvh_items,
            &self.field,
            &self.leaf_spheres,
            &self.wide_nodes,
        ]
    }

    /// Every byte the step holds on the GPU: sections, field and derived buffers.
    pub fn bytes(&self) -> u64 {
        self.in_binding_order()
            .iter()
            .map(|b| b.size())
            .sum::<u64>()
            + self.reach.size()
    }
}

/// Where the time of an upload went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UploadStats {
    /// Decoded bytes placed on the GPU.
    pub bytes: u64,
    /// Bytes read from the file (compressed where the section is).
    pub stored_bytes: u64,
    /// The host half: checksums of the raw sections, the tree check and the sections it
    /// reads.
    pub host_seconds: f64,
    /// The GPU half's recording: buffers created, the staging buffer filled (compressed
    /// sections decoded into it), passes recorded.
    pub record_seconds: f64,
    /// Staging to device-local copies and the per-step passes, from submit to completion
    /// (zero where the caller submits).
    pub gpu_seconds: f64,
    /// Open to ready, everything included.
    pub total_seconds: f64,
}

impl UploadStats {
    /// Decoded bytes per second of the whole upload, in GB/s.
    pub fn gigabytes_per_second(&self) -> f64 {
        self.bytes as f64 / self.total_seconds.max(1e-12) / 1e9
    }
}

/// What the passes need to know about a step, read from its header and sections.
#[derive(Debug, Clone, PartialEq)]
pub struct StepInfo {
    pub point_count: u32,
    pub sphere_count: u32,
    pub cluster_size: u32,
    /// Depth of the step's BVH (the traversal stack needs one entry more).
    pub bvh_depth: u64,
    /// Entries of the BVH's node buffer (the blank lead node included) and item list.
    pub node_count: u32,
    pub item_count: u32,
    /// Entries of the cluster candidate list.
    pub cluster_id_count: u32,
    /// Words of neighbour mask of the largest cluster: its candidates over 32.
    pub mask_words: u32,
    /// Rows of `cluster_size` mask words that hold every cluster's block (see [`mask_row`]).
    pub mask_rows: u64,
    pub has_normals: bool,
    /// The degree the balls were fitted at, and "mean" or "covariance".
    pub degree: u8,
    pub covariance: bool,
    /// Local = (world − origin) / scale.
    pub transform: Transform,
    pub bounds: [[f64; 3]; 2],
    /// Mean nearest-neighbour spacing in world units.
    pub spacing: f64,
}

impl StepInfo {
    /// Bytes of the neighbour masks, leaf spheres and wide nodes the per-step passes derive.
    pub fn derived_bytes(&self) -> [u64; 3] {
        let masks = self.mask_rows * u64::from(self.cluster_size) * 4;
        let leaves = u64::from(self.item_count) * 16;
        let wide = u64::from(self.node_count - 1) * WIDE_NODE_BYTES;
        [
            masks.max(EMPTY_BINDING),
            leaves.max(EMPTY_BINDING),
            wide.max(WIDE_NODE_BYTES),
        ]
    }
}

/// A scalar field's values, ready for the GPU, with their finite range.
#[derive(Debug, Clone, PartialEq)]
pub struct HostField {
    pub name: String,
    /// Little-endian f32s, one per point.
    pub bytes: Vec<u8>,
    pub min: f32,
    pub max: f32,
}

impl HostField {
    /// Decodes field `name` of `file`; an error listing the baked fields where it has none.
    pub fn read(file: &CacheFile, name: &str) -> Result<HostField> {
        let section = format!("{}{name}", names::FIELD_PREFIX);
        let Some(entry) = file.section(&section) else {
            let available: Vec<&str> = file
                .header()
                .sections
                .iter()
                .filter_map(|s| s.name.strip_prefix(names::FIELD_PREFIX))
                .collect();
            return Err(invalid(
                file,
                format!(
                    "no field '{name}' in this cache; baked fields: {}",
                    if available.is_empty() {
                        "none (bake with --fields NAME)".to_string()
                    } else {
                        available.join(", ")
                    }
                ),
            ));
        };
        let points = file.header().points;
        if entry.raw != points * 4 {
            return Err(invalid(
                file,
                format!(
                    "field '{name}' holds {} bytes for {points} points (4 bytes each expected)",
                    entry.raw
                ),
            ));
        }
        let mut bytes = vec![0u8; entry.raw as usize];
        file.decode_into(entry, &mut bytes, &mut Vec::new())?;
        let (min, max) = finite_range(&bytes);
        Ok(HostField {
            name: name.to_string(),
            bytes,
            min,
            max,
        })
    }
}

/// The cache file a host step reads its raw sections from: owned (a prefetched step) or
/// borrowed (a caller that keeps the file).
#[derive(Debug)]
enum HeldFile<'a> {
    Owned(Box<CacheFile>),
    Borrowed(&'a CacheFile),
}

impl HeldFile<'_> {
    fn get(&self) -> &CacheFile {
        match self {
            HeldFile::Owned(f) => f,
            HeldFile::Borrowed(f) => f,
        }
    }
}

/// How [`GpuStep::create_in`] records and where it takes its memory from.
#[derive(Default)]
pub struct UploadOptions<'a> {
    /// Records the per-step passes here instead of after the copies: submitted in that
    /// order, the two can be timed apart.
    pub passes: Option<&'a mut wgpu::CommandEncoder>,
    /// A timestamp query set of 6: each of the three passes writes its begin and end there
    /// (masks 0–1, leaves 2–3, widen 4–5).
    pub timestamps: Option<&'a wgpu::QuerySet>,
    /// Takes the staging memory from this pool; hand it back with
    /// [`GpuStep::take_staging`] and [`StagingPool::recycle`] once the copies are submitted.
    pub staging: Option<&'a StagingPool>,
    /// Asked between pieces of the staging fill: `true` abandons the upload with
    /// [`Error::Cancelled`] (a prefetch that a jump made stale).
    pub cancelled: Option<&'a (dyn Fn() -> bool + Sync)>,
}

impl std::fmt::Debug for UploadOptions<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UploadOptions")
            .field("passes", &self.passes.is_some())
            .field("timestamps", &self.timestamps)
            .field("staging", &self.staging)
            .field("cancelled", &self.cancelled.is_some())
            .finish()
    }
}

/// Where a section's bytes come from when the GPU half copies them.
#[derive(Debug)]
enum SectionData {
    Absent,
    /// Raw in the file, checksummed in place: copied straight from the map.
    Stored,
    /// Decoded by the host half, which reads it (the tree, the cluster offsets).
    Decoded(Vec<u8>),
    /// Compressed, decoded run by run straight into the staging memory by the GPU half: a
    /// run decodes into a cache-sized buffer and is copied on while hot, so the section is
    /// never written to and read back from main memory in full.
    Deferred,
}

/// The host half of an upload: the file checked, the sections it reads decoded (the BVH
/// nodes, the cluster offsets), its raw sections checksummed in place, the tree checked.
/// Needs no device. The other compressed sections are checked and decoded in parallel
/// straight into the staging memory by [`GpuStep::create`].
#[derive(Debug)]
pub struct HostStep<'a> {
    file: HeldFile<'a>,
    /// Each `SECTIONS` slot's bytes, or where they come from.
    sections: Vec<SectionData>,
    pub field: Option<HostField>,
    pub info: StepInfo,
    pub host_seconds: f64,
    pub stored_bytes: u64,
}

impl HostStep<'static> {
    /// Opens `path` and runs the host half on it.
    pub fn open(path: &Path, field: Option<&str>) -> Result<HostStep<'static>> {
        let start = Instant::now();
        let mut step = HostStep::prepare(HeldFile::Owned(Box::new(CacheFile::open(path)?)), field)?;
        step.host_seconds = start.elapsed().as_secs_f64();
        Ok(step)
    }
}

impl<'a> HostStep<'a> {
    /// The host half over a file the caller keeps.
    pub fn read(file: &'a CacheFile, field: Option<&str>) -> Result<HostStep<'a>> {
        HostStep::prepare(HeldFile::Borrowed(file), field)
    }

    pub fn file(&self) -> &CacheFile {
        self.file.get()
    }

    /// Where the bytes of `SECTIONS[slot]` come from.
    fn section_source(&self, slot: usize) -> Source<'_> {
        let file = self.file.get();
        match (&self.sections[slot], file.section(SECTIONS[slot])) {
            (SectionData::Decoded(d), _) => Source::Bytes(d),
            (SectionData::Stored, Some(e)) => Source::Bytes(file.stored(e)),
            (SectionData::Deferred, Some(entry)) => Source::Runs { file, entry },
            _ => Source::Bytes(&[]),
        }
    }

    /// The bytes of a section the host half decoded or found raw (empty otherwise).
    fn host_bytes(&self, slot: usize) -> &[u8] {
        match self.section_source(slot) {
            Source::Bytes(b) => b,
            Source::Runs { .. } => &[],
        }
    }

    /// Every byte the step will hold on the GPU (what [`StepBuffers::bytes`] reports once it
    /// is there), known before the upload.
    pub fn gpu_bytes(&self) -> u64 {
        let sections: u64 = (0..SECTIONS.len())
            .map(|slot| {
                lead(SECTIONS[slot])
                    + self
                        .section_source(slot)
                        .len()
                        .max(EMPTY_BINDING)
                        .next_multiple_of(4)
            })
            .sum();
        let field = self
            .field
            .as_ref()
            .map_or(EMPTY_BINDING, |f| field_buffer_size(&f.bytes));
        sections + field + self.info.derived_bytes().iter().sum::<u64>()
    }

    fn prepare(file: HeldFile<'a>, field: Option<&str>) -> Result<HostStep<'a>> {
        let start = Instant::now();
        let f = file.get();
        let header = f.header();
        if header.stats.bvh_depth > MAX_BVH_DEPTH {
            return Err(invalid(
                f,
                format!(
                    "BVH depth {} exceeds the tracer's stack ({MAX_BVH_DEPTH})",
                    header.stats.bvh_depth
                ),
            ));
        }
        let entries: Vec<Option<&SectionEntry>> = SECTIONS.iter().map(|n| f.section(n)).collect();
        for (name, entry) in SECTIONS.iter().zip(&entries) {
            if entry.is_none() && *name != names::NORMALS {
                return Err(invalid(f, format!("no section '{name}'")));
            }
        }
        let point_count = u32::try_from(header.points)
            .map_err(|_| invalid(f, format!("{} points exceed u32", header.points)))?;
        // Raw sections are checksummed in place and those the host reads decoded, all in
        // parallel; the field alongside.
        let (sections, field) = rayon::join(
            || {
                SECTIONS
                    .par_iter()
                    .zip(&entries)
                    .map(|(name, entry)| -> Result<SectionData> {
                        match entry {
                            Some(e) if e.encoding == Encoding::Raw => {
                                f.checked_stored(e)?;
                                Ok(SectionData::Stored)
                            }
                            Some(e) if HOST_READS.contains(name) => {
                                let mut out = vec![0u8; e.raw as usize];
                                f.decode_into(e, &mut out, &mut Vec::new())?;
                                Ok(SectionData::Decoded(out))
                            }
                            Some(_) => Ok(SectionData::Deferred),
                            None => Ok(SectionData::Absent),
                        }
                    })
                    .collect::<Result<Vec<_>>>()
            },
            || field.map(|name| HostField::read(f, name)).transpose(),
        );
        let (sections, field) = (sections?, field?);
        let count = |name: &str| f.section(name).map_or(0, |e| e.count);
        let info = StepInfo {
            point_count,
            sphere_count: count(names::SPHERES) as u32,
            cluster_size: header.neighbour_cluster.max(1),
            bvh_depth: header.stats.bvh_depth,
            node_count: count(names::BVH_NODES) as u32 + 1,
            item_count: count(names::BVH_ITEMS) as u32,
            cluster_id_count: count(names::CLUSTER_NEIGHBOURS) as u32,
            mask_words: 0,
            mask_rows: 0,
            has_normals: f.section(names::NORMALS).is_some(),
            degree: header.mls.degree,
            covariance: header.mls.normals == "covariance",
            transform: header.transform,
            bounds: header.bounds,
            spacing: header.spacing * header.transform.scale,
        };
        let stored_bytes = entries.iter().flatten().map(|e| e.stored).sum::<u64>()
            + field
                .as_ref()
                .and_then(|fd| f.section(&format!("{}{}", names::FIELD_PREFIX, fd.name)))
                .map_or(0, |e| e.stored);
        let mut step = HostStep {
            file,
            sections,
            field,
            info,
            host_seconds: 0.0,
            stored_bytes,
        };
        let items = u64::from(step.info.item_count);
        check_tree(step.host_bytes(slot_of(names::BVH_NODES)), items)
            .map_err(|problem| invalid(step.file(), problem))?;
        let (words, rows) = mask_layout(
            step.host_bytes(slot_of(names::CLUSTER_START)),
            step.info.cluster_size,
            u64::from(step.info.cluster_id_count),
        )
        .map_err(|problem| invalid(step.file(), problem))?;
        (step.info.mask_words, step.info.mask_rows) = (words, rows);
        step.host_seconds = start.elapsed().as_secs_f64();
        Ok(step)
    }
}

/// A step on the GPU, with what the passes need to know about it and its bind group.
#[derive(Debug)]
pub struct GpuStep {
    pub buffers: StepBuffers,
    pub info: StepInfo,
    /// Whether an array spans more than one storage binding (see shaders.rs).
    pub split: bool,
    /// The shaded field's name and its finite range.
    pub field: Option<(String, f32, f32)>,
    pub upload: UploadStats,
    /// The trace and shade passes' group 0, made for `binding_limit`.
    bind_group: wgpu::BindGroup,
    binding_limit: u64,
    /// The pooled staging buffer of the upload, until taken back.
    staging: Option<wgpu::Buffer>,
}

const SECTIONS: [&str; 9] = [
    names::POINTS,
    names::NORMALS,
    names::REACH,
    names::CLUSTER_START,
    names::CLUSTER_NEIGHBOURS,
    names::BALLS,
    names::SPHERES,
    names::BVH_NODES,
    names::BVH_ITEMS,
];

/// The sections the host half reads (the tree check, the mask layout), so decodes itself.
const HOST_READS: [&str; 2] = [names::BVH_NODES, names::CLUSTER_START];

fn slot_of(name: &str) -> usize {
    SECTIONS.iter().position(|n| *n == name).unwrap_or_default()
}

/// Bytes of an entry of the 4-wide tree (`struct Wide` in mls.wgsl).
const WIDE_NODE_BYTES: u64 = 128;

/// wgpu refuses zero-sized bindings, and a binding must hold one element of its array:
/// absent or empty sections (a step without particles) bind this many zero bytes, the
/// largest element any binding holds (the wide node).
const EMPTY_BINDING: u64 = WIDE_NODE_BYTES;

/// Bytes of the blank node before a step's BVH nodes on the GPU (one `GpuBvhNode`).
const NODE_LEAD: u64 = 32;

/// How the passes bind each section of `SECTIONS`: the reach is read only by the per-step
/// passes; a name that is no section is an error, never a guess.
fn array_of(file: &CacheFile, name: &str) -> Result<&'static RangedArray> {
    Ok(match name {
        names::POINTS => &step_array::POINTS,
        names::NORMALS => &step_array::NORMALS,
        names::REACH => &EXPAND_ARRAYS[2],
        names::CLUSTER_START => &step_array::CLUSTER_START,
        names::CLUSTER_NEIGHBOURS => &step_array::CLUSTER_IDS,
        names::BALLS => &step_array::BALLS,
        names::SPHERES => &step_array::SPHERES,
        names::BVH_NODES => &step_array::BVH_NODES,
        names::BVH_ITEMS => &step_array::BVH_ITEMS,
        other => {
            return Err(invalid(
                file,
                format!("no GPU binding for section '{other}'"),
            ));
        }
    })
}

/// Whether an array of `bytes` needs more than one binding (split into ranges); an error
/// naming it where it cannot be bound at all.
fn needs_ranges(
    gpu: &Gpu,
    file: &CacheFile,
    what: &str,
    array: &RangedArray,
    bytes: u64,
) -> Result<bool> {
    needs_split(
        &gpu.device,
        &gpu.describe(),
        gpu.max_binding(),
        array,
        what,
        bytes,
    )
    .map_err(|problem| invalid(file, problem))
}

/// Bytes before a section's data in its GPU buffer: trace.wgsl reads the nodes after one
/// blank node, which aligns sibling pairs.
fn lead(name: &str) -> u64 {
    if name == names::BVH_NODES {
        NODE_LEAD
    } else {
        0
    }
}

fn field_buffer_size(bytes: &[u8]) -> u64 {
    (bytes.len() as u64).max(EMPTY_BINDING).next_multiple_of(4)
}

fn invalid(file: &CacheFile, problem: String) -> Error {
    Error::Step {
        path: file.path().to_path_buf(),
        problem,
    }
}

/// The first row of cluster `cluster`'s neighbour-mask words, `first` being its first
/// candidate slot: `mask_row` in shaders/step.wgsl, which explains the layout.
pub fn mask_row(cluster: u64, first: u64) -> u64 {
    (first + 31 * cluster) / 32
}

/// The neighbour masks' layout: the most words any cluster needs, and the rows of
/// `cluster_size` words that hold every cluster's. An error where the cluster offsets are not
/// monotone from 0 to the candidate count (the shaders rely on it) or the masks would not be
/// indexable by u32.
fn mask_layout(
    cluster_start: &[u8],
    cluster_size: u32,
    candidates: u64,
) -> std::result::Result<(u32, u64), String> {
    let starts: Vec<u64> = cluster_start
        .chunks_exact(4)
        .map(|c| u64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]])))
        .collect();
    if starts.first().is_some_and(|&s| s != 0)
        || starts.windows(2).any(|w| w[0] > w[1])
        || starts.last().is_some_and(|&s| s != candidates)
    {
        return Err(format!(
            "section '{}' is not monotone from 0 to the {candidates} candidates of '{}'",
            names::CLUSTER_START,
            names::CLUSTER_NEIGHBOURS
        ));
    }
    let most = starts.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    let clusters = starts.len().saturating_sub(1) as u64;
    let rows = mask_row(clusters, starts.last().copied().unwrap_or(0));
    if rows * u64::from(cluster_size) > u64::from(u32::MAX) {
        return Err(format!(
            "{rows} rows of neighbour masks exceed the tracer's 32-bit indices"
        ));
    }
    Ok((most.div_ceil(32) as u32, rows))
}

/// Finite minimum and maximum of little-endian f32s (0, 0 when there are none).
fn finite_range(bytes: &[u8]) -> (f32, f32) {
    let (lo, hi) = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo <= hi { (lo, hi) } else { (0.0, 0.0) }
}

/// The bytes of an array the GPU half uploads: in memory (decoded, the field, or raw in the
/// mapped file), or a compressed section's runs, decoded straight into the staging memory.
#[derive(Debug, Clone, Copy)]
enum Source<'a> {
    Bytes(&'a [u8]),
    Runs {
        file: &'a CacheFile,
        entry: &'a SectionEntry,
    },
}

impl Source<'_> {
    fn len(&self) -> u64 {
        match self {
            Source::Bytes(b) => b.len() as u64,
            Source::Runs { entry, .. } => entry.raw,
        }
    }
}

/// One task of filling the staging buffer: a mapped range and what goes there.
enum Piece<'a> {
    Copy(&'a [u8]),
    Run {
        file: &'a CacheFile,
        entry: &'a SectionEntry,
        spans: &'a [(std::ops::Range<usize>, std::ops::Range<usize>)],
        k: usize,
    },
}

/// Device-local storage buffers for `arrays` (label, bytes, blank lead bytes), all filled
/// through one staging buffer (one allocation per step, not one per section), whose pieces
/// are copied or decoded in parallel; the copies are recorded into `encoder`.
fn storage_buffers(
    gpu: &Gpu,
    file: &CacheFile,
    arrays: &[(&str, Source<'_>, u64)],
    encoder: &mut wgpu::CommandEncoder,
    pool: Option<&StagingPool>,
    cancelled: Option<&(dyn Fn() -> bool + Sync)>,
) -> Result<(Vec<wgpu::Buffer>, Option<wgpu::Buffer>)> {
    // Each array's place in the staging buffer, 256-byte aligned.
    let mut offsets = Vec::with_capacity(arrays.len());
    let mut total = 0u64;
    for (_, source, _) in arrays {
        offsets.push(total);
        total += source.len().next_multiple_of(256);
    }
    let targets: Vec<wgpu::Buffer> = arrays
        .iter()
        .map(|(label, source, lead)| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: lead + source.len().max(EMPTY_BINDING).next_multiple_of(4),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .collect();
    if total == 0 {
        return Ok((targets, None));
    }
    let staging = match pool {
        Some(pool) => pool.take(gpu, total),
        None => gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("staging"),
            size: total,
            usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: true,
        }),
    };
    // Each compressed array's runs, and every array's pieces, each its own mapped range,
    // filled on rayon's threads.
    let spans: Vec<Vec<(std::ops::Range<usize>, std::ops::Range<usize>)>> = arrays
        .iter()
        .map(|(_, source, _)| match source {
            Source::Runs { entry, .. } => entry.chunk_spans(),
            Source::Bytes(_) => Vec::new(),
        })
        .collect();
    let mut pieces = Vec::new();
    let view = |start: u64, len: usize| {
        let end = start + (len as u64).next_multiple_of(4);
        staging
            .slice(start..end)
            .get_mapped_range_mut()
            .map_err(|e| Error::Readback(e.to_string()))
    };
    for (((_, source, _), &offset), spans) in arrays.iter().zip(&offsets).zip(&spans) {
        match *source {
            Source::Bytes(bytes) => {
                for (k, piece) in bytes.chunks(COPY_PIECE).enumerate() {
                    let at = offset + (k * COPY_PIECE) as u64;
                    pieces.push((view(at, piece.len())?, Piece::Copy(piece)));
                }
            }
            Source::Runs { file, entry } => {
                for (k, (_, raw)) in spans.iter().enumerate() {
                    let at = offset + raw.start as u64;
                    let piece = Piece::Run {
                        file,
                        entry,
                        spans,
                        k,
                    };
                    pieces.push((view(at, raw.len())?, piece));
                }
            }
        }
    }
    let filled = pieces.into_par_iter().try_for_each_init(
        || (Vec::new(), Vec::new()),
        |(run, scratch), (mut view, piece)| -> Result<()> {
            if cancelled.is_some_and(|c| c()) {
                return Err(Error::Cancelled);
            }
            match piece {
                Piece::Copy(bytes) => view.slice(..bytes.len()).copy_from_slice(bytes),
                Piece::Run {
                    file,
                    entry,
                    spans,
                    k,
                } => {
                    // Staging memory may be write-combined: decoding reads its own output
                    // (matches, the filters), so it decodes here and is copied on once.
                    run.resize(spans[k].1.len(), 0);
                    file.decode_run_into(entry, spans, k, run, scratch)?;
                    view.slice(..run.len()).copy_from_slice(run);
                }
            }
            Ok(())
        },
    );
    // Raw pieces were copied straight from the map, which may have gone to zeros under them.
    let filled = filled.and_then(|()| file.unchanged().map_err(Error::from));
    if let Err(e) = filled {
        // Still mapped and never submitted: ready for the next upload as it is.
        if let Some(pool) = pool {
            pool.restore(staging);
        }
        return Err(e);
    }
    staging.unmap();
    for (((_, source, lead), offset), target) in arrays.iter().zip(&offsets).zip(&targets) {
        if source.len() > 0 {
            let size = source.len().next_multiple_of(4);
            encoder.copy_buffer_to_buffer(&staging, *offset, target, *lead, size);
        }
    }
    Ok((targets, pool.map(|_| staging)))
}

/// Bytes copied per task into a staging buffer.
const COPY_PIECE: usize = 1 << 20;

/// A storage buffer a per-step pass writes (readable back for tests and tools).
fn derived(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

impl GpuStep {
    /// Opens, uploads and waits: both halves in one call, `file`'s GPU sections and `field`'s
    /// values, if named.
    pub fn upload(gpu: &Gpu, file: &CacheFile, field: Option<&str>) -> Result<GpuStep> {
        let start = Instant::now();
        let host = HostStep::read(file, field)?;
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("upload"),
            });
        let mut step = GpuStep::create(gpu, &host, &mut encoder)?;
        let submitted = Instant::now();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        gpu.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Validation(e.to_string()));
        }
        gpu.wait()?;
        step.upload.gpu_seconds = submitted.elapsed().as_secs_f64();
        step.upload.total_seconds = start.elapsed().as_secs_f64();
        Ok(step)
    }

    /// The GPU half: buffers created and filled through staging, the copies and the per-step
    /// passes recorded into `encoder`. Nothing is submitted or waited for; the step is ready
    /// for frames recorded after it in the same or a later submission.
    pub fn create(
        gpu: &Gpu,
        host: &HostStep<'_>,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<GpuStep> {
        GpuStep::create_in(gpu, host, encoder, UploadOptions::default())
    }

    /// [`GpuStep::create`] with the copies recorded into `copies`, and `options`.
    pub fn create_in(
        gpu: &Gpu,
        host: &HostStep<'_>,
        copies: &mut wgpu::CommandEncoder,
        options: UploadOptions<'_>,
    ) -> Result<GpuStep> {
        let UploadOptions {
            passes,
            timestamps,
            staging,
            cancelled,
        } = options;
        let encoder = copies;
        let start = Instant::now();
        let file = host.file();
        let info = host.info.clone();
        // Every array, sections and the three the passes derive, within RANGES bindings.
        let mut split = false;
        for (slot, name) in SECTIONS.iter().enumerate() {
            let bytes = lead(name) + host.section_source(slot).len();
            split |= needs_ranges(gpu, file, name, array_of(file, name)?, bytes)?;
        }
        if let Some(field) = &host.field {
            split |= needs_ranges(
                gpu,
                file,
                "field",
                &step_array::FIELD,
                field.bytes.len() as u64,
            )?;
        }
        let [mask_bytes, leaf_bytes, wide_bytes] = info.derived_bytes();
        split |= needs_ranges(
            gpu,
            file,
            "neighbour masks",
            &step_array::NEIGHBOUR_MASKS,
            mask_bytes,
        )?;
        split |= needs_ranges(
            gpu,
            file,
            "leaf spheres",
            &step_array::LEAF_SPHERES,
            leaf_bytes,
        )?;
        split |= needs_ranges(gpu, file, "wide nodes", &step_array::WIDE_NODES, wide_bytes)?;
        let mut stats = UploadStats {
            stored_bytes: host.stored_bytes,
            host_seconds: host.host_seconds,
            ..UploadStats::default()
        };
        let mut arrays: Vec<(&str, Source<'_>, u64)> = SECTIONS
            .iter()
            .enumerate()
            .map(|(slot, name)| (*name, host.section_source(slot), lead(name)))
            .collect();
        if let Some(f) = &host.field {
            arrays.push(("field", Source::Bytes(&f.bytes), 0));
        }
        stats.bytes = arrays.iter().map(|(_, b, _)| b.len()).sum();
        let (mut sections, staging) =
            storage_buffers(gpu, file, &arrays, encoder, staging, cancelled)?;
        let field_values = match &host.field {
            Some(_) => sections
                .pop()
                .ok_or_else(|| Error::Validation("upload produced too few buffers".into()))?,
            None => derived(gpu, "no field", EMPTY_BINDING),
        };
        let mut it = sections.into_iter();
        let mut next = || {
            it.next()
                .ok_or_else(|| Error::Validation("upload produced too few buffers".into()))
        };
        let (points, normals, reach) = (next()?, next()?, next()?);
        let (cluster_start, cluster_ids) = (next()?, next()?);
        let (balls, spheres, bvh_nodes, bvh_items) = (next()?, next()?, next()?, next()?);
        let masks = derived(gpu, "neighbour masks", mask_bytes);
        let leaf_spheres = derived(gpu, "leaf spheres", leaf_bytes);
        let wide_nodes = derived(gpu, "wide nodes", wide_bytes);
        gpu.expander().encode(
            &gpu.device,
            &ExpandInputs {
                points: &points,
                normals: &normals,
                reach: &reach,
                cluster_start: &cluster_start,
                cluster_ids: &cluster_ids,
                masks: &masks,
                bvh_items: &bvh_items,
                spheres: &spheres,
                leaf_spheres: &leaf_spheres,
                bvh_nodes: &bvh_nodes,
                wide_nodes: &wide_nodes,
            },
            ExpandSettings {
                point_count: info.point_count,
                cluster_size: info.cluster_size,
                mask_words: info.mask_words,
                has_normals: u32::from(info.has_normals),
                sphere_count: info.sphere_count,
                item_count: info.item_count,
                cluster_id_count: info.cluster_id_count,
                node_count: info.node_count - 1,
                ..ExpandSettings::zeroed()
            },
            split,
            match passes {
                Some(passes) => passes,
                None => encoder,
            },
            timestamps,
        )?;
        let buffers = StepBuffers {
            points,
            normals,
            reach,
            masks,
            cluster_start,
            cluster_ids,
            balls,
            spheres,
            bvh_nodes,
            bvh_items,
            field: field_values,
            leaf_spheres,
            wide_nodes,
        };
        let binding_limit = gpu.max_binding();
        let bind_group = step_group(gpu, &buffers, binding_limit);
        stats.record_seconds = start.elapsed().as_secs_f64();
        stats.total_seconds = stats.host_seconds + stats.record_seconds;
        Ok(GpuStep {
            buffers,
            info,
            split,
            field: host.field.as_ref().map(|f| (f.name.clone(), f.min, f.max)),
            upload: stats,
            bind_group,
            binding_limit,
            staging,
        })
    }

    /// The pooled staging buffer the upload's copies read, to recycle once they are
    /// submitted.
    pub fn take_staging(&mut self) -> Option<wgpu::Buffer> {
        self.staging.take()
    }

    /// Replaces the colour field (or drops it with `None`): only the field's buffer is
    /// uploaded (through `queue.write_buffer`, ordered before the next submission) and the
    /// bind group remade.
    pub fn set_field(&mut self, gpu: &Gpu, field: Option<&HostField>) -> Result<()> {
        let buffer = match field {
            Some(f) => {
                if f.bytes.len() as u64 != u64::from(self.info.point_count) * 4 {
                    return Err(Error::Validation(format!(
                        "field '{}' has {} bytes for a step of {} points",
                        f.name,
                        f.bytes.len(),
                        self.info.point_count
                    )));
                }
                needs_split(
                    &gpu.device,
                    &gpu.describe(),
                    self.binding_limit,
                    &step_array::FIELD,
                    "field",
                    f.bytes.len() as u64,
                )
                .map_err(Error::Validation)?;
                let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("field"),
                    size: field_buffer_size(&f.bytes),
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                gpu.queue.write_buffer(&buffer, 0, &f.bytes);
                buffer
            }
            None => derived(gpu, "no field", EMPTY_BINDING),
        };
        self.buffers.field = buffer;
        self.field = field.map(|f| (f.name.clone(), f.min, f.max));
        self.bind_group = step_group(gpu, &self.buffers, self.binding_limit);
        Ok(())
    }

    /// The trace and shade passes' group 0 for this step.
    pub fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }

    /// The binding limit the step's bind group was made for.
    pub fn binding_limit(&self) -> u64 {
        self.binding_limit
    }

    /// Every byte the step holds on the GPU.
    pub fn gpu_bytes(&self) -> u64 {
        self.buffers.bytes()
    }
}

/// The step bind group of `buffers`, under the device's shared layout.
fn step_group(gpu: &Gpu, buffers: &StepBuffers, limit: u64) -> wgpu::BindGroup {
    let entries = bind_entries(&STEP_ARRAYS, &buffers.in_binding_order(), None, limit);
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("step"),
        layout: gpu.step_layout(),
        entries: &entries,
    })
}

#[cfg(test)]
mod tests {
    use super::check_tree;

    /// A node as the `bvh_nodes` section stores it: lo, count, hi, first.
    fn node(count: u32, first: u32) -> Vec<u8> {
        let mut out = Vec::new();
        for v in [0.0f32, 0.0, 0.0] {
            out.extend(v.to_le_bytes());
        }
        out.extend(count.to_le_bytes());
        for v in [1.0f32, 1.0, 1.0] {
            out.extend(v.to_le_bytes());
        }
        out.extend(first.to_le_bytes());
        out
    }

    #[test]
    fn trees_the_walk_could_not_finish_are_refused() {
        let tree = |nodes: &[(u32, u32)]| -> Vec<u8> {
            nodes.iter().flat_map(|&(c, f)| node(c, f)).collect()
        };
        // Root with two leaves of 3 and 2 items.
        assert_eq!(check_tree(&tree(&[(0, 1), (3, 0), (2, 3)]), 5), Ok(()));
        let cycle = check_tree(&tree(&[(0, 1), (0, 0), (2, 3)]), 5).unwrap_err();
        assert!(
            cycle.contains("BVH node 1 (byte 32") && cycle.contains("follow"),
            "{cycle}"
        );
        let outside = check_tree(&tree(&[(0, 1), (3, 0), (2, 4)]), 5).unwrap_err();
        assert!(outside.contains("items 4..6 of a list of 5"), "{outside}");
        let wide = check_tree(&tree(&[(16, 0)]), 16).unwrap_err();
        assert!(wide.contains("at most 15 items"), "{wide}");
        let dangling = check_tree(&tree(&[(0, 1), (3, 0)]), 5).unwrap_err();
        assert!(
            dangling.contains("children 1 and 2 in a tree of 2 nodes"),
            "{dangling}"
        );
    }
}
