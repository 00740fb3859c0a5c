//! The `.slc` byte layout: preamble, JSON header with the section table, page-aligned
//! sections, footer. `docs/cache-format.md` is the specification; this is its code.

use serde::{Deserialize, Serialize};

/// First 8 bytes of every step file (PNG-style: a high bit, CR LF, ^Z and LF catch text-mode
/// mangling).
pub const MAGIC: [u8; 8] = *b"\x89SLC\r\n\x1a\n";
/// Footer magic.
pub const FOOTER_MAGIC: [u8; 8] = *b"SLC-END\n";
/// Readers refuse files of another major version (older ones with the command that re-bakes
/// them); minor versions only add.
pub const MAJOR: u16 = 9;
pub const MINOR: u16 = 1;
/// The most raw bytes per chunk of a section (the last chunk holds the rest): chunks decode
/// independently, so a section decodes on as many cores as it has chunks. A multiple of every
/// element size.
pub const CHUNK_RAW: u64 = 1 << 20;
/// The fewest raw bytes per chunk: smaller chunks would compress worse and lengthen the
/// table for less than they gain in parallel decoding.
pub const CHUNK_RAW_MIN: u64 = 64 << 10;
/// Chunks a section is cut into where [`CHUNK_RAW_MIN`] and [`CHUNK_RAW`] allow: a small
/// step's sections (a ball section of 100k points is 1.6 MB) would otherwise be one or two
/// chunks, and their upload would wait for one core to decode each.
pub const CHUNKS_PER_SECTION: u64 = 16;
/// Every chunk's raw bytes start on this boundary: a run is decoded straight into its place
/// in a mapped GPU staging buffer, and mapped ranges start on 8 bytes (wgpu's
/// `MAP_ALIGNMENT`).
pub const CHUNK_ALIGN: u64 = 8;
pub const PREAMBLE_LEN: usize = 32;
pub const FOOTER_LEN: usize = 32;
/// Sections start on this boundary, so raw sections can be used in place from the map.
pub const ALIGN: usize = 4096;

/// The fixed 32 bytes at offset 0 (little-endian).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Preamble {
    pub major: u16,
    pub minor: u16,
    pub flags: u32,
    pub header_len: u64,
    pub header_xxh3: u64,
}

impl Preamble {
    pub fn to_bytes(self) -> [u8; PREAMBLE_LEN] {
        let mut b = [0u8; PREAMBLE_LEN];
        b[0..8].copy_from_slice(&MAGIC);
        b[8..10].copy_from_slice(&self.major.to_le_bytes());
        b[10..12].copy_from_slice(&self.minor.to_le_bytes());
        b[12..16].copy_from_slice(&self.flags.to_le_bytes());
        b[16..24].copy_from_slice(&self.header_len.to_le_bytes());
        b[24..32].copy_from_slice(&self.header_xxh3.to_le_bytes());
        b
    }

    /// Parses the fixed fields; the caller has checked the magic and the length.
    pub fn parse(b: &[u8; PREAMBLE_LEN]) -> Preamble {
        let u16_at = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]);
        let u32_at = |o: usize| u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
        let u64_at = |o: usize| {
            let mut w = [0u8; 8];
            w.copy_from_slice(&b[o..o + 8]);
            u64::from_le_bytes(w)
        };
        Preamble {
            major: u16_at(8),
            minor: u16_at(10),
            flags: u32_at(12),
            header_len: u64_at(16),
            header_xxh3: u64_at(24),
        }
    }
}

/// The fixed 32 bytes at the end: magic, total file length, xxh3-64 of every byte before the
/// footer, reserved zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Footer {
    pub file_len: u64,
    pub body_xxh3: u64,
}

impl Footer {
    pub fn to_bytes(self) -> [u8; FOOTER_LEN] {
        let mut b = [0u8; FOOTER_LEN];
        b[0..8].copy_from_slice(&FOOTER_MAGIC);
        b[8..16].copy_from_slice(&self.file_len.to_le_bytes());
        b[16..24].copy_from_slice(&self.body_xxh3.to_le_bytes());
        b
    }
}

/// How a section's bytes are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Encoding {
    /// The element bytes as they are.
    #[serde(rename = "raw")]
    Raw,
    /// One zstd frame of the element bytes.
    #[serde(rename = "zstd")]
    Zstd,
    /// Bytes regrouped by position within each 4-byte word (all first bytes, then all second
    /// bytes, …), then zstd.
    #[serde(rename = "shuffle4+zstd")]
    Shuffle4Zstd,
    /// u32 words replaced by their wrapping difference from the previous word (the first
    /// from 0), then shuffled and compressed as `shuffle4+zstd`. For sorted index lists.
    #[serde(rename = "delta4+shuffle4+zstd")]
    Delta4Shuffle4Zstd,
    /// Bytes regrouped by position within each 16-byte element (byte 0 of every element, then
    /// byte 1, …), then zstd: each field's sign and exponent bytes end up side by side, and a
    /// padding word becomes one run of zeros. Format 3.
    #[serde(rename = "shuffle16+zstd")]
    Shuffle16Zstd,
    /// As `shuffle16+zstd`, within each 20-byte element (format 8's balls). Format 8.
    #[serde(rename = "shuffle20+zstd")]
    Shuffle20Zstd,
    /// As `shuffle16+zstd`, within each 24-byte element (format 5's to 7's balls). Format 5.
    #[serde(rename = "shuffle24+zstd")]
    Shuffle24Zstd,
    /// As `shuffle16+zstd`, within each 32-byte element. Format 3.
    #[serde(rename = "shuffle32+zstd")]
    Shuffle32Zstd,
    /// As `shuffle16+zstd`, within each 64-byte element. Format 3.
    #[serde(rename = "shuffle64+zstd")]
    Shuffle64Zstd,
}

impl Encoding {
    pub fn name(self) -> &'static str {
        match self {
            Encoding::Raw => "raw",
            Encoding::Zstd => "zstd",
            Encoding::Shuffle4Zstd => "shuffle4+zstd",
            Encoding::Delta4Shuffle4Zstd => "delta4+shuffle4+zstd",
            Encoding::Shuffle16Zstd => "shuffle16+zstd",
            Encoding::Shuffle20Zstd => "shuffle20+zstd",
            Encoding::Shuffle24Zstd => "shuffle24+zstd",
            Encoding::Shuffle32Zstd => "shuffle32+zstd",
            Encoding::Shuffle64Zstd => "shuffle64+zstd",
        }
    }

    /// The width bytes are regrouped within, for the shuffled encodings.
    pub fn shuffle_width(self) -> Option<usize> {
        match self {
            Encoding::Raw | Encoding::Zstd => None,
            Encoding::Shuffle4Zstd | Encoding::Delta4Shuffle4Zstd => Some(4),
            Encoding::Shuffle16Zstd => Some(16),
            Encoding::Shuffle20Zstd => Some(20),
            Encoding::Shuffle24Zstd => Some(24),
            Encoding::Shuffle32Zstd => Some(32),
            Encoding::Shuffle64Zstd => Some(64),
        }
    }

    /// What every chunk's raw length is a multiple of: the shuffle width (4 where there is
    /// none) and [`CHUNK_ALIGN`].
    pub fn chunk_step(self) -> u64 {
        let width = self.shuffle_width().unwrap_or(4) as u64;
        let (mut a, mut b) = (width, CHUNK_ALIGN);
        while b != 0 {
            (a, b) = (b, a % b);
        }
        width / a * CHUNK_ALIGN
    }

    /// Raw bytes per chunk of a section of `raw` bytes in this encoding: a sixteenth of the
    /// section ([`CHUNKS_PER_SECTION`]) rounded up to a [`Encoding::chunk_step`], within
    /// [`CHUNK_RAW_MIN`] and the largest such multiple up to [`CHUNK_RAW`] (20- and 24-byte
    /// elements do not divide 1 MiB).
    pub fn chunk_raw(self, raw: u64) -> u64 {
        let step = self.chunk_step();
        let most = CHUNK_RAW - CHUNK_RAW % step;
        raw.div_ceil(CHUNKS_PER_SECTION)
            .max(CHUNK_RAW_MIN)
            .next_multiple_of(step)
            .min(most)
    }

    /// The byte shuffle within whole elements of `size` bytes, then zstd (`shuffle4+zstd`
    /// for sizes without their own encoding).
    pub fn shuffled_elements(size: usize) -> Encoding {
        match size {
            16 => Encoding::Shuffle16Zstd,
            20 => Encoding::Shuffle20Zstd,
            24 => Encoding::Shuffle24Zstd,
            32 => Encoding::Shuffle32Zstd,
            64 => Encoding::Shuffle64Zstd,
            _ => Encoding::Shuffle4Zstd,
        }
    }
}

/// One row of the section table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SectionEntry {
    pub name: String,
    /// An [`crate::Element`] name.
    pub element: String,
    pub count: u64,
    /// Byte offset of the stored bytes from the start of the file (a multiple of 4096).
    pub offset: u64,
    /// Bytes stored in the file.
    pub stored: u64,
    /// Bytes after decoding: `count` × element size.
    pub raw: u64,
    pub encoding: Encoding,
    /// xxh3-64 of the stored bytes, 16 lowercase hex digits.
    pub xxh3: String,
    /// Raw bytes per chunk (format 2; absent in format 1, where a section is one run).
    #[serde(default)]
    pub chunk_raw: u64,
    /// The chunks, in order: chunk k decodes to raw bytes `k·chunk_raw ..` (format 2).
    #[serde(default)]
    pub chunks: Vec<ChunkEntry>,
}

/// One independently decodable run of a section's stored bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChunkEntry {
    /// Stored bytes of the chunk.
    pub stored: u64,
    /// xxh3-64 of those bytes, 16 lowercase hex digits.
    pub xxh3: String,
}

impl SectionEntry {
    /// Each chunk's stored byte range (relative to the section's offset) and raw byte range;
    /// one run over the whole section where the table has no chunks (format 1).
    pub fn chunk_spans(&self) -> Vec<(std::ops::Range<usize>, std::ops::Range<usize>)> {
        if self.chunks.is_empty() {
            return vec![(0..self.stored as usize, 0..self.raw as usize)];
        }
        let (mut stored, mut raw) = (0usize, 0usize);
        self.chunks
            .iter()
            .map(|c| {
                let s = stored..stored + c.stored as usize;
                let end = raw.saturating_add(usize::try_from(self.chunk_raw).unwrap_or(usize::MAX));
                let r = raw..end.min(self.raw as usize);
                stored = s.end;
                raw = r.end;
                (s, r)
            })
            .collect()
    }
}

/// World coordinates of a stored (local) point: `origin + scale × local`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    pub origin: [f64; 3],
    pub scale: f64,
}

impl Transform {
    pub fn to_world(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| self.origin[a] + self.scale * p[a])
    }

    pub fn to_local(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| (p[a] - self.origin[a]) / self.scale)
    }
}

/// The MLS settings the balls were fitted with (mirrors `slosh_mls::SurfaceParams`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MlsSettings {
    pub k: usize,
    pub h_scale: f64,
    pub support: f64,
    pub neighbour_cap: usize,
    pub degree: u8,
    /// "mean" (data normals) or "covariance" (PCA).
    pub normals: String,
    pub per_point_h: bool,
    pub droplet_below: usize,
    /// The drawn surface's offset outside the MLS surface, in particle radii (absent before
    /// bake revision 7: none).
    #[serde(default)]
    pub offset: f64,
}

/// Where the step came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Source {
    pub path: String,
    pub step: usize,
    pub time: f64,
    /// What the input files were when the step was baked (their paths, sizes and modification
    /// times, hashed): a resumed bake re-bakes a step whose input changed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<String>,
}

/// The steps one bake into a directory was asked for (`first ..= last` of its source, every
/// one of them), recorded in every step file it writes: a directory can then be checked as a
/// whole, gaps included, with or without its manifest. Absent in files of earlier bakes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SeriesRecord {
    pub first: usize,
    pub last: usize,
}

impl SeriesRecord {
    pub fn count(&self) -> usize {
        self.last.saturating_sub(self.first) + 1
    }

    pub fn contains(&self, index: usize) -> bool {
        (self.first..=self.last).contains(&index)
    }
}

impl std::fmt::Display for SeriesRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "steps {}..={} ({} steps)",
            self.first,
            self.last,
            self.count()
        )
    }
}

/// Counts the bake records about a step.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct StepStats {
    /// Particles in the input step.
    pub input_points: u64,
    /// Dropped for non-finite coordinates.
    pub dropped_non_finite: u64,
    /// Dropped as far beyond the rest (a solver's sentinel; `docs/bake.md`, "Select").
    pub dropped_far: u64,
    /// Dropped as not on the surface.
    pub dropped_interior: u64,
    /// Left after selection but too few (one) to size a surface by: dropped, the step kept
    /// empty.
    pub dropped_too_few: u64,
    /// Points whose neighbour list was cut at the cap.
    pub capped: u64,
    /// Normals the bake reversed because their neighbourhood contradicted them, in all, and
    /// the patches reversed as a whole with their points (`docs/algorithm.md`).
    pub orientation_flipped: u64,
    pub orientation_patches: u64,
    pub orientation_patch_points: u64,
    pub fit_full: u64,
    pub fit_degraded: u64,
    pub fit_none: u64,
    pub droplets: u64,
    pub droplet_points: u64,
    pub bvh_nodes: u64,
    pub bvh_depth: u64,
    /// Seconds per bake stage, in pipeline order.
    pub stage_seconds: Vec<(String, f64)>,
}

/// The JSON header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub source: Source,
    pub points: u64,
    pub transform: Transform,
    /// World bounds of the points.
    pub bounds: [[f64; 3]; 2],
    /// Global smoothing length and mean nearest-neighbour spacing, in local units.
    pub smoothing_length: f64,
    pub spacing: f64,
    /// How far outside the MLS surface the drawn surface lies along its normal, in local
    /// units (`mls.offset` particle radii; absent before bake revision 7: none).
    #[serde(default)]
    pub surface_offset: f64,
    /// The grid the `bvh_nodes` boxes are stored on (format 9).
    #[serde(default)]
    pub bvh_grid: crate::BvhGrid,
    /// Points per neighbour cluster: `cluster_neighbours` holds one candidate list per run of
    /// this many consecutive points.
    pub neighbour_cluster: u32,
    pub mls: MlsSettings,
    /// Everything that shaped the output, as the bake recorded it, and its hash.
    pub bake: serde_json::Value,
    pub params_hash: String,
    /// The series the step was baked as part of (format 3.1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub series: Option<SeriesRecord>,
    pub stats: StepStats,
    pub sections: Vec<SectionEntry>,
    /// The unit axis that is up in this step's data (`slosh_mls::guess_up`), where the data
    /// says; renderers frame with it unless told otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f64; 3]>,
    /// Each field view's range, missing values left out (`field_view_ranges`; format 9.1): a
    /// view with no value that is not missing has none, and a step of format 9.0 none at all.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub field_ranges: std::collections::BTreeMap<String, crate::FieldRange>,
}

pub fn hex64(v: u64) -> String {
    format!("{v:016x}")
}

pub fn align_up(v: usize) -> usize {
    v.div_ceil(ALIGN) * ALIGN
}
