//! A cache step streamed into GPU storage buffers: each section's bytes go, unconverted, into
//! a `mapped_at_creation` staging buffer (raw sections straight from the mapped file,
//! compressed ones through a reused decode buffer, since wgpu's mapped views are write-only),
//! then `copy_buffer_to_buffer` into device-local storage.

use std::time::Instant;

use rayon::prelude::*;
use slosh_cache::{CacheFile, Encoding, SectionEntry, Transform, names};

use bytemuck::Zeroable;

use crate::bindings::needs_split;
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::expand::ExpandInputs;
use crate::layout::ExpandSettings;
use crate::shaders::{EXPAND_ARRAYS, RangedArray, STEP_ARRAYS};

/// The deepest BVH the trace shader's largest traversal stack (96 entries) holds: the wide
/// tree has 31 levels, each stacking up to three slots.
pub const MAX_BVH_DEPTH: u64 = 62;

/// The traversal stack packs a node as `first | count << 28` (trace.wgsl: `link`), so a
/// leaf holds at most this many items and `first` stays below 2^28.
pub const MAX_LEAF_LINK_COUNT: u32 = 15;
pub const MAX_LINK_FIRST: u32 = (1 << 28) - 1;

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
    /// Written by the neighbour-mask pass at upload: `mask_words` u32s per point.
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
}

/// Where the time of an upload went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UploadStats {
    /// Decoded bytes placed on the GPU.
    pub bytes: u64,
    /// Bytes read from the file (compressed where the section is).
    pub stored_bytes: u64,
    /// Checksums, decompression and copies into the mapped staging buffers.
    pub host_seconds: f64,
    /// Staging to device-local copies and the neighbour-mask pass, from submit to
    /// completion.
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

/// A step on the GPU, with what the passes need to know about it.
#[derive(Debug)]
pub struct GpuStep {
    pub buffers: StepBuffers,
    pub point_count: u32,
    pub sphere_count: u32,
    pub cluster_size: u32,
    /// Depth of the step's BVH (the traversal stack needs one entry more).
    pub bvh_depth: u64,
    /// Entries of the BVH's node buffer (the blank lead node included) and item list.
    pub node_count: u32,
    pub item_count: u32,
    /// Whether an array spans more than one storage binding (see shaders.rs).
    pub split: bool,
    /// Words of neighbour mask per point: the most candidates of any cluster, over 32.
    pub mask_words: u32,
    pub has_normals: bool,
    /// The degree the balls were fitted at, and "mean" or "covariance".
    pub degree: u8,
    pub covariance: bool,
    /// Local = (world − origin) / scale.
    pub transform: Transform,
    pub bounds: [[f64; 3]; 2],
    /// Mean nearest-neighbour spacing in world units.
    pub spacing: f64,
    /// The shaded field's name and its finite range.
    pub field: Option<(String, f32, f32)>,
    pub upload: UploadStats,
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

/// wgpu refuses zero-sized bindings; absent or empty sections bind this many zero bytes.
const EMPTY_BINDING: u64 = 16;

/// Bytes of an entry of the 4-wide tree (`struct Wide` in mls.wgsl).
const WIDE_NODE_BYTES: u64 = 128;

/// Bytes of the blank node before a step's BVH nodes on the GPU (one `GpuBvhNode`).
const NODE_LEAD: u64 = 32;

/// How the passes bind each section of `SECTIONS` (and the field).
fn array_of(name: &str) -> &'static RangedArray {
    match name {
        names::POINTS => &STEP_ARRAYS[0],
        names::NORMALS => &STEP_ARRAYS[1],
        names::REACH => &EXPAND_ARRAYS[2],
        names::CLUSTER_START => &STEP_ARRAYS[3],
        names::CLUSTER_NEIGHBOURS => &STEP_ARRAYS[4],
        names::BALLS => &STEP_ARRAYS[5],
        names::SPHERES => &STEP_ARRAYS[6],
        names::BVH_NODES => &STEP_ARRAYS[7],
        names::BVH_ITEMS => &STEP_ARRAYS[8],
        _ => &STEP_ARRAYS[9],
    }
}

/// Whether an array of `bytes` needs more than one binding; an error naming it where it
/// cannot be bound.
fn fits(gpu: &Gpu, file: &CacheFile, what: &str, array: &RangedArray, bytes: u64) -> Result<bool> {
    needs_split(gpu, gpu.max_binding(), array, what, bytes)
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

fn invalid(file: &CacheFile, problem: String) -> Error {
    Error::Step {
        path: file.path().to_path_buf(),
        problem,
    }
}

/// Words of neighbour mask per point: one bit per candidate of the largest cluster.
fn mask_words(cluster_start: &[u8]) -> u32 {
    let starts: Vec<u32> = cluster_start
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let most = starts
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]))
        .max()
        .unwrap_or(0);
    most.div_ceil(32)
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

impl GpuStep {
    /// Uploads `file`'s GPU sections (and `field`'s values, if named).
    pub fn upload(gpu: &Gpu, file: &CacheFile, field: Option<&str>) -> Result<GpuStep> {
        let start = Instant::now();
        let header = file.header();
        if header.stats.bvh_depth > MAX_BVH_DEPTH {
            return Err(invalid(
                file,
                format!(
                    "BVH depth {} exceeds the tracer's stack ({MAX_BVH_DEPTH})",
                    header.stats.bvh_depth
                ),
            ));
        }
        let field_name = field.map(|f| format!("{}{f}", names::FIELD_PREFIX));
        if let Some(name) = &field_name
            && file.section(name).is_none()
        {
            let available: Vec<&str> = header
                .sections
                .iter()
                .filter_map(|s| s.name.strip_prefix(names::FIELD_PREFIX))
                .collect();
            return Err(invalid(
                file,
                format!(
                    "no field '{}' in this cache; baked fields: {}",
                    field.unwrap_or_default(),
                    if available.is_empty() {
                        "none (bake with --fields NAME)".to_string()
                    } else {
                        available.join(", ")
                    }
                ),
            ));
        }
        let wanted: Vec<&str> = SECTIONS
            .iter()
            .copied()
            .chain(field_name.as_deref())
            .collect();
        let entries: Vec<Option<&SectionEntry>> = wanted.iter().map(|n| file.section(n)).collect();
        for (name, entry) in wanted.iter().zip(&entries) {
            match entry {
                None if *name != names::NORMALS => {
                    return Err(invalid(file, format!("no section '{name}'")));
                }
                _ => {}
            }
        }
        // Compressed sections are decoded in parallel; raw ones are used in place.
        let decoded: Vec<Option<Vec<u8>>> = entries
            .par_iter()
            .map(|entry| -> Result<Option<Vec<u8>>> {
                match entry {
                    Some(e) if e.encoding != Encoding::Raw => {
                        let mut out = vec![0u8; e.raw as usize];
                        file.decode_into(e, &mut out, &mut Vec::new())?;
                        Ok(Some(out))
                    }
                    _ => Ok(None),
                }
            })
            .collect::<Result<_>>()?;
        let point_count = u32::try_from(header.points)
            .map_err(|_| invalid(file, format!("{} points exceed u32", header.points)))?;
        let cluster_slot = SECTIONS
            .iter()
            .position(|n| *n == names::CLUSTER_START)
            .unwrap_or_default();
        // Each section's bytes, checksummed once: decoded, raw in place, or absent.
        let section_bytes: Vec<&[u8]> = entries
            .iter()
            .zip(&decoded)
            .map(|(entry, decoded)| match (entry, decoded) {
                (_, Some(d)) => Ok(d.as_slice()),
                (Some(e), None) => file.checked_stored(e),
                (None, None) => Ok(&[][..]),
            })
            .collect::<std::result::Result<_, _>>()?;
        let nodes_slot = SECTIONS
            .iter()
            .position(|n| *n == names::BVH_NODES)
            .unwrap_or_default();
        let items = file.section(names::BVH_ITEMS).map_or(0, |e| e.count);
        check_tree(section_bytes[nodes_slot], items).map_err(|problem| invalid(file, problem))?;
        let mask_words = mask_words(section_bytes[cluster_slot]);
        let mask_bytes = u64::from(point_count) * u64::from(mask_words) * 4;
        let count = |name: &str| file.section(name).map_or(0, |e| e.count);
        let item_count = count(names::BVH_ITEMS) as u32;
        // Every array, sections and the two the upload derives, within RANGES bindings.
        let mut split = false;
        for (name, bytes) in wanted.iter().zip(&section_bytes) {
            split |= fits(
                gpu,
                file,
                name,
                array_of(name),
                lead(name) + bytes.len() as u64,
            )?;
        }
        split |= fits(gpu, file, "neighbour masks", &STEP_ARRAYS[2], mask_bytes)?;
        let leaf_bytes = u64::from(item_count) * 16;
        split |= fits(gpu, file, "leaf spheres", &STEP_ARRAYS[10], leaf_bytes)?;
        let node_count = count(names::BVH_NODES) as u32;
        let wide_bytes = u64::from(node_count) * WIDE_NODE_BYTES;
        split |= fits(gpu, file, "wide nodes", &STEP_ARRAYS[11], wide_bytes)?;
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("upload"),
            });
        let mut buffers = Vec::with_capacity(wanted.len());
        let mut stats = UploadStats::default();
        let mut field_range = None;
        for ((name, entry), &bytes) in wanted.iter().zip(&entries).zip(&section_bytes) {
            if let Some(e) = entry {
                stats.stored_bytes += e.stored;
            }
            if Some(*name) == field_name.as_deref() {
                field_range = Some(finite_range(bytes));
            }
            let size = (bytes.len() as u64).max(EMPTY_BINDING).next_multiple_of(4);
            let lead = lead(name);
            let target = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(name),
                size: lead + size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            if !bytes.is_empty() {
                let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("staging"),
                    size,
                    usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: true,
                });
                {
                    let mut view = staging
                        .slice(..)
                        .get_mapped_range_mut()
                        .map_err(|e| Error::Readback(e.to_string()))?;
                    view.slice(..bytes.len()).copy_from_slice(bytes);
                }
                staging.unmap();
                encoder.copy_buffer_to_buffer(&staging, 0, &target, lead, size);
                stats.bytes += bytes.len() as u64;
            }
            buffers.push(target);
        }
        if field_name.is_none() {
            buffers.push(gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("no field"),
                size: EMPTY_BINDING,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }));
        }
        let mut it = buffers.into_iter();
        let mut next = || {
            it.next()
                .ok_or_else(|| Error::Validation("upload produced too few buffers".into()))
        };
        let (points, normals, reach) = (next()?, next()?, next()?);
        let (cluster_start, cluster_ids) = (next()?, next()?);
        let (balls, spheres, bvh_nodes, bvh_items, field_values) =
            (next()?, next()?, next()?, next()?, next()?);
        let masks = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("neighbour masks"),
            size: mask_bytes.max(EMPTY_BINDING),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let leaf_spheres = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("leaf spheres"),
            size: leaf_bytes.max(EMPTY_BINDING),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let wide_nodes = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("wide nodes"),
            size: wide_bytes.max(WIDE_NODE_BYTES),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let has_normals = file.section(names::NORMALS).is_some();
        let cluster_size = header.neighbour_cluster.max(1);
        let sphere_count = count(names::SPHERES) as u32;
        gpu.expander().encode(
            gpu,
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
                point_count,
                cluster_size,
                mask_words,
                has_normals: u32::from(has_normals),
                sphere_count,
                item_count,
                cluster_id_count: count(names::CLUSTER_NEIGHBOURS) as u32,
                node_count,
                ..ExpandSettings::zeroed()
            },
            split,
            &mut encoder,
        )?;
        stats.host_seconds = start.elapsed().as_secs_f64();
        let submitted = Instant::now();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        gpu.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Validation(e.to_string()));
        }
        gpu.wait()?;
        stats.gpu_seconds = submitted.elapsed().as_secs_f64();
        stats.total_seconds = start.elapsed().as_secs_f64();
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
        Ok(GpuStep {
            buffers,
            point_count,
            sphere_count,
            node_count: node_count + 1,
            item_count,
            split,
            cluster_size,
            bvh_depth: header.stats.bvh_depth,
            mask_words,
            has_normals,
            degree: header.mls.degree,
            covariance: header.mls.normals == "covariance",
            transform: header.transform,
            bounds: header.bounds,
            spacing: header.spacing * header.transform.scale,
            field: field
                .zip(field_range)
                .map(|(n, (lo, hi))| (n.to_string(), lo, hi)),
            upload: stats,
        })
    }
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
