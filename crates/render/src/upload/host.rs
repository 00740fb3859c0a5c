//! The host half of an upload: the file checked and its sections read or checksummed in
//! place, with no device.

use std::path::Path;
use std::time::Instant;

use rayon::prelude::*;
use slosh_cache::{BvhGrid, CacheFile, Encoding, SectionEntry, Transform, names};

use super::checks::{MAX_BVH_DEPTH, check_tree, mark_missing, mask_layout};
use super::{
    EMPTY_BINDING, HOST_READS, SECTIONS, WIDE_NODE_BYTES, field_buffer_size, invalid, slot_of,
};
use crate::error::Result;

/// What the passes need to know about a step, read from its header and sections.
#[derive(Debug, Clone, PartialEq)]
pub struct StepInfo {
    pub point_count: u32,
    pub sphere_count: u32,
    pub cluster_size: u32,
    /// Depth of the step's BVH (the traversal stack needs one entry more).
    pub bvh_depth: u64,
    /// Nodes of the BVH2 (entries of the 4-wide tree the tracer widens from it) and items
    /// of its item list.
    pub node_count: u32,
    /// The grid the BVH2's boxes are stored on.
    pub bvh_grid: BvhGrid,
    /// The step's h (local units), and whether each ball has its own instead (`ball_h`).
    pub h: f32,
    pub per_point_h: bool,
    /// The degree every ball was fitted at, where the step has no degraded fits (the header's
    /// count, which the verifier holds to the balls' states).
    pub ball_degree: Option<u8>,
    pub item_count: u32,
    /// Candidates of all clusters (the last `cluster_start`).
    pub cluster_id_count: u32,
    /// Words of `cluster_neighbours`: the clusters' runs of candidates.
    pub run_words: u32,
    /// Words of neighbour mask of the largest cluster: its candidates over 32.
    pub mask_words: u32,
    /// Rows of `cluster_size` mask words that hold every cluster's block (see [`mask_row`](crate::mask_row)).
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
    /// How far outside the MLS surface the drawn surface lies, in local units.
    pub surface_offset: f32,
    /// Particles the bake dropped from its input: with a non-finite coordinate, and far
    /// beyond the rest (the header's statistics).
    pub dropped_non_finite: u64,
    pub dropped_far: u64,
}

impl StepInfo {
    /// Bytes of the neighbour masks the tracer derives before a refined frame of the step.
    pub fn mask_bytes(&self) -> u64 {
        (self.mask_rows * u64::from(self.cluster_size) * 4).max(EMPTY_BINDING)
    }

    /// Bytes of the 4-wide tree the tracer widens from the BVH2 before a frame of the step:
    /// an entry per node.
    pub fn wide_bytes(&self) -> u64 {
        (u64::from(self.node_count) * WIDE_NODE_BYTES).max(EMPTY_BINDING)
    }

    /// Bytes of the candidates, one per slot, that the tracer expands from the runs with
    /// the masks.
    pub fn candidate_bytes(&self) -> u64 {
        (u64::from(self.cluster_id_count) * 4).max(EMPTY_BINDING)
    }
}

/// A scalar field's values, ready for the GPU, with their finite range.
#[derive(Debug, Clone, PartialEq)]
pub struct HostField {
    pub name: String,
    /// Little-endian f32s, one per point; [`slosh_cache::FIELD_MISSING`] where the cache's
    /// value is missing (not finite).
    pub bytes: Vec<u8>,
    pub min: f32,
    pub max: f32,
    /// Points whose value is missing: drawn in [`crate::MISSING_FIELD_COLOUR`].
    pub missing: usize,
}

impl HostField {
    /// The range of the values that are not missing; `None` where every value is.
    pub fn range(&self) -> Option<(f32, f32)> {
        (self.missing < self.bytes.len() / 4).then_some((self.min, self.max))
    }

    /// Decodes field view `name` of `file` (a scalar field, or a vector field's magnitude or
    /// component: `slosh_cache::find_field_view`); an error listing the views where it has
    /// none.
    pub fn read(file: &CacheFile, name: &str) -> Result<HostField> {
        let header = file.header();
        let Some(view) = slosh_cache::find_field_view(header, name) else {
            let available = slosh_cache::field_views(header);
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
        let entry = view.section;
        let points = header.points;
        let width = if view.part.is_some() { 16 } else { 4 };
        if entry.raw != points * width {
            return Err(invalid(
                file,
                format!(
                    "field '{name}' holds {} bytes for {points} points ({width} bytes each expected)",
                    entry.raw
                ),
            ));
        }
        let mut decoded = vec![0u8; entry.raw as usize];
        file.decode_into(entry, &mut decoded, &mut Vec::new())?;
        let mut bytes = match view.part {
            None => decoded,
            Some(part) => {
                let mut values = Vec::new();
                slosh_cache::vector_values(&decoded, part, &mut values);
                values
            }
        };
        let (missing, (min, max)) = mark_missing(&mut bytes);
        Ok(HostField {
            name: name.to_string(),
            bytes,
            min,
            max,
            missing,
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

/// Where a section's bytes come from when the GPU half copies them.
#[derive(Debug)]
enum SectionData {
    Absent,
    /// Raw in the file and read by the host half, checksummed in place.
    Stored,
    /// Decoded by the host half, which reads it (the tree, the cluster offsets).
    Decoded(Vec<u8>),
    /// Left to the GPU half, run by run: a raw run is checksummed and copied from the map
    /// into the staging memory; a compressed one decodes into a cache-sized buffer and is
    /// copied on while hot, so the section is never written to and read back from main
    /// memory in full.
    Deferred,
}

/// The host half of an upload: the file checked, the sections it reads decoded (the BVH
/// nodes, the cluster offsets), its raw sections checksummed in place, the tree checked.
/// Needs no device. The other compressed sections are checked and decoded in parallel
/// straight into the staging memory by [`GpuStep::create`](crate::GpuStep::create).
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
    pub(super) fn section_source(&self, slot: usize) -> Source<'_> {
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

    /// The arrays the GPU half uploads, by name: the sections in `SECTIONS`' order.
    pub(super) fn gpu_arrays(&self) -> Vec<(&'static str, Source<'_>)> {
        SECTIONS
            .iter()
            .map(|name| (*name, self.section_source(slot_of(name))))
            .collect()
    }

    /// Every byte the step will hold on the GPU (what [`StepBuffers::bytes`](crate::StepBuffers::bytes) reports once it
    /// is there), known before the upload.
    pub fn gpu_bytes(&self) -> u64 {
        let arrays: u64 = self
            .gpu_arrays()
            .iter()
            .map(|(_, source)| source.len().max(EMPTY_BINDING).next_multiple_of(4))
            .sum();
        let field = self
            .field
            .as_ref()
            .map_or(EMPTY_BINDING, |f| field_buffer_size(&f.bytes));
        arrays + field
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
        // Data normals are optional; a cubic's other coefficients are where cubics are fitted,
        // the balls' own h where h is per point.
        for (name, entry) in SECTIONS.iter().zip(&entries) {
            let optional = [names::NORMALS, names::BALL_CUBIC, names::BALL_H];
            if entry.is_none() && !optional.contains(name) {
                return Err(invalid(f, format!("no section '{name}'")));
            }
        }
        f.check_ball_cubic()?;
        f.check_ball_words()?;
        if !header.bvh_grid.is_valid() {
            return Err(invalid(
                f,
                format!(
                    "the BVH's grid {:?} is not finite with power-of-two steps",
                    header.bvh_grid
                ),
            ));
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
                            Some(e) if e.encoding == Encoding::Raw && HOST_READS.contains(name) => {
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
            node_count: 0,
            bvh_grid: header.bvh_grid,
            h: header.smoothing_length as f32,
            per_point_h: header.mls.per_point_h,
            ball_degree: (header.stats.fit_degraded == 0).then_some(header.mls.degree),
            // Leaves name ranges of items: the balls, then the droplet spheres.
            item_count: (u64::from(point_count) + count(names::SPHERES)) as u32,
            cluster_id_count: 0,
            run_words: 0,
            mask_words: 0,
            mask_rows: 0,
            has_normals: f.section(names::NORMALS).is_some(),
            degree: header.mls.degree,
            covariance: header.mls.normals == "covariance",
            transform: header.transform,
            bounds: header.bounds,
            spacing: header.spacing * header.transform.scale,
            surface_offset: header.surface_offset as f32,
            dropped_non_finite: header.stats.dropped_non_finite,
            dropped_far: header.stats.dropped_far,
        };
        let candidate_words = count(names::CLUSTER_NEIGHBOURS);
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
        let nodes = step.host_bytes(slot_of(names::BVH_NODES));
        step.info.node_count =
            check_tree(nodes, items).map_err(|problem| invalid(step.file(), problem))?;
        let (words, rows, candidates) = mask_layout(
            step.host_bytes(slot_of(names::CLUSTER_START)),
            step.host_bytes(slot_of(names::CLUSTER_BASE)),
            candidate_words,
            step.info.cluster_size,
        )
        .map_err(|problem| invalid(step.file(), problem))?;
        (step.info.mask_words, step.info.mask_rows) = (words, rows);
        step.info.cluster_id_count = candidates;
        step.info.run_words = u32::try_from(candidate_words).map_err(|_| {
            invalid(
                step.file(),
                format!("{candidate_words} words of candidate runs exceed u32"),
            )
        })?;
        step.host_seconds = start.elapsed().as_secs_f64();
        Ok(step)
    }
}

/// The bytes of an array the GPU half uploads: in memory (decoded, the field, or raw in the
/// mapped file), or a compressed section's runs, decoded straight into the staging memory.
#[derive(Debug, Clone, Copy)]
pub(super) enum Source<'a> {
    Bytes(&'a [u8]),
    Runs {
        file: &'a CacheFile,
        entry: &'a SectionEntry,
    },
}

impl Source<'_> {
    pub(super) fn len(&self) -> u64 {
        match self {
            Source::Bytes(b) => b.len() as u64,
            Source::Runs { entry, .. } => entry.raw,
        }
    }
}
