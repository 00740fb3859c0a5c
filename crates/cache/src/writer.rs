//! Assembling a step file: encode sections (in parallel), lay them out page-aligned after the
//! JSON header, close with the footer, write atomically.

use std::path::Path;

use rayon::prelude::*;
use xxhash_rust::xxh3::xxh3_64;

use crate::error::Result;
use crate::format::{
    ALIGN, ChunkEntry, Encoding, Footer, Header, MAJOR, MINOR, PREAMBLE_LEN, Preamble,
    SectionEntry, align_up, hex64,
};
use crate::layout::Element;

/// One section to write: its element bytes, the encoding to try, and whether it is stored
/// raw where the step's budget allows ([`RAW_BUDGET_BYTES_PER_POINT`]).
#[derive(Debug, Clone)]
pub struct SectionInput {
    pub name: String,
    pub element: Element,
    pub bytes: Vec<u8>,
    pub encoding: Encoding,
    /// Stored raw, in ascending order of this rank, while the step's sections stay within
    /// the budget; `None`: stored with `encoding` wherever that saves 10 %.
    pub raw_rank: Option<u8>,
}

/// The stored bytes per point a step's sections may take when the bake compresses: sections
/// with a [`SectionInput::raw_rank`] are stored raw, rank by rank, while the sections' total,
/// each padded to its page as the file lays it out, stays within this many bytes per point.
/// A raw section loads as a checksummed copy from the map, with no decoding on the player's
/// hot path; the budget keeps a step's file within 48 bytes per point (issue 27) with room
/// for its header and table.
pub const RAW_BUDGET_BYTES_PER_POINT: u64 = 46;

impl SectionInput {
    /// Raw bytes per chunk of this section ([`Encoding::chunk_raw`]), whether it ends up
    /// compressed or raw.
    fn chunk_raw(&self) -> u64 {
        self.encoding.chunk_raw(self.bytes.len() as u64)
    }

    pub fn new<T: bytemuck::Pod>(
        name: &str,
        element: Element,
        items: &[T],
        encoding: Encoding,
    ) -> SectionInput {
        debug_assert_eq!(size_of::<T>(), element.size());
        // Copied in parallel, without zeroing first: a 1M-point step's sections are some
        // 200 MB, which one thread would take long to zero and fault in.
        let from: &[u8] = bytemuck::cast_slice(items);
        let mut bytes = Vec::with_capacity(from.len());
        bytes.par_extend(from.par_iter().copied());
        SectionInput {
            name: name.to_string(),
            element,
            bytes,
            encoding,
            raw_rank: None,
        }
    }

    /// The section stored raw where the budget allows, before those of higher `rank`.
    pub fn raw_within_budget(mut self, rank: u8) -> SectionInput {
        self.raw_rank = Some(rank);
        self
    }
}

/// How hard to compress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// Every section raw.
    None,
    /// zstd at this level; a section keeps its encoding only where it saves at least 10 %
    /// (otherwise raw, usable in place from the map).
    Level(i32),
}

/// Encodes a whole step file. `header.sections` is filled in here.
pub fn encode_step(
    mut header: Header,
    sections: &[SectionInput],
    compression: Compression,
) -> Result<Vec<u8>, std::io::Error> {
    // Every chunk of every section encoded in parallel; a section keeps its encoding only
    // where that saves at least 10 % over all its chunks, and is stored raw instead where its
    // raw rank comes up within the budget.
    let jobs: Vec<(usize, &[u8])> = sections
        .iter()
        .enumerate()
        .flat_map(|(i, s)| s.bytes.chunks(s.chunk_raw() as usize).map(move |c| (i, c)))
        .collect();
    let packed: Vec<Option<Vec<u8>>> = jobs
        .par_iter()
        .map(|&(i, raw)| {
            let s = &sections[i];
            match compression {
                Compression::Level(level) if s.encoding != Encoding::Raw => {
                    crate::codec::encode(raw, s.encoding, level).map(Some)
                }
                _ => Ok(None),
            }
        })
        .collect::<std::io::Result<_>>()?;
    // Each section's chunks among the jobs, and whether its encoding saves 10 %.
    let mut at = 0;
    let spans: Vec<std::ops::Range<usize>> = sections
        .iter()
        .map(|s| {
            let n = s.bytes.len().div_ceil(s.chunk_raw() as usize);
            at += n;
            at - n..at
        })
        .collect();
    let packed_len = |k: usize| -> usize {
        packed[spans[k].clone()]
            .iter()
            .flatten()
            .map(Vec::len)
            .sum()
    };
    let mut keep: Vec<bool> = sections
        .iter()
        .enumerate()
        .map(|(k, s)| {
            packed[spans[k].clone()].iter().all(Option::is_some)
                && packed_len(k) * 10 <= s.bytes.len() * 9
        })
        .collect();
    // Sections with a raw rank go raw, rank by rank, while the total stays within budget.
    // Each counts as the file lays it out, to whole pages: in a small step the pages a raw
    // section adds are what passes the budget.
    let stored_len = |k: usize, keep: &[bool]| {
        align_up(if keep[k] {
            packed_len(k)
        } else {
            sections[k].bytes.len()
        })
    };
    let mut total: usize = (0..sections.len()).map(|k| stored_len(k, &keep)).sum();
    let budget = (header.points.saturating_mul(RAW_BUDGET_BYTES_PER_POINT)) as usize;
    let mut ranked: Vec<usize> = (0..sections.len())
        .filter(|&k| sections[k].raw_rank.is_some() && keep[k])
        .collect();
    ranked.sort_by_key(|&k| sections[k].raw_rank);
    for k in ranked {
        // `k` is still kept compressed here.
        let raw_total = total - stored_len(k, &keep) + align_up(sections[k].bytes.len());
        if raw_total <= budget {
            keep[k] = false;
            total = raw_total;
        }
    }
    let mut encoded: Vec<(Encoding, Vec<u8>, Vec<ChunkEntry>)> = Vec::new();
    for (k, s) in sections.iter().enumerate() {
        let chunks = &packed[spans[k].clone()];
        let raws = &jobs[spans[k].clone()];
        let keep = keep[k];
        let parts: Vec<&[u8]> = if keep {
            chunks.iter().flatten().map(Vec::as_slice).collect()
        } else {
            raws.iter().map(|(_, raw)| *raw).collect()
        };
        let table = parts
            .iter()
            .map(|p| ChunkEntry {
                stored: p.len() as u64,
                xxh3: hex64(xxh3_64(p)),
            })
            .collect();
        let encoding = if keep { s.encoding } else { Encoding::Raw };
        encoded.push((encoding, parts.concat(), table));
    }

    // The header records offsets, which depend on the header's length: lay out with a guess,
    // then again until the length settles (twice at most in practice).
    let mut header_len_guess = 0usize;
    let (header_bytes, offsets) = loop {
        let mut offset = align_up(PREAMBLE_LEN + header_len_guess);
        let mut offsets = Vec::with_capacity(sections.len());
        header.sections = sections
            .iter()
            .zip(&encoded)
            .map(|(s, (encoding, bytes, chunks))| {
                offsets.push(offset);
                let entry = SectionEntry {
                    name: s.name.clone(),
                    element: s.element.name().to_string(),
                    count: (s.bytes.len() / s.element.size()) as u64,
                    offset: offset as u64,
                    stored: bytes.len() as u64,
                    raw: s.bytes.len() as u64,
                    encoding: *encoding,
                    xxh3: hex64(xxh3_64(bytes)),
                    chunk_raw: s.chunk_raw(),
                    chunks: chunks.clone(),
                };
                offset = align_up(offset + bytes.len());
                entry
            })
            .collect();
        let json = serde_json::to_vec(&header).map_err(std::io::Error::other)?;
        if align_up(PREAMBLE_LEN + json.len()) == align_up(PREAMBLE_LEN + header_len_guess) {
            break (json, offsets);
        }
        header_len_guess = json.len();
    };

    let body_end = offsets
        .last()
        .zip(encoded.last())
        .map_or(PREAMBLE_LEN + header_bytes.len(), |(o, (_, b, _))| {
            o + b.len()
        });
    let mut out = Vec::with_capacity(body_end + ALIGN);
    out.extend_from_slice(
        &Preamble {
            major: MAJOR,
            minor: MINOR,
            flags: 0,
            header_len: header_bytes.len() as u64,
            header_xxh3: xxh3_64(&header_bytes),
        }
        .to_bytes(),
    );
    out.extend_from_slice(&header_bytes);
    for (offset, (_, bytes, _)) in offsets.iter().zip(&encoded) {
        out.resize(*offset, 0);
        out.extend_from_slice(bytes);
    }
    let footer = Footer {
        file_len: (out.len() + crate::format::FOOTER_LEN) as u64,
        body_xxh3: xxh3_64(&out),
    };
    out.extend_from_slice(&footer.to_bytes());
    Ok(out)
}

/// Encodes and writes a step file atomically.
pub fn write_step(
    path: &Path,
    header: Header,
    sections: &[SectionInput],
    compression: Compression,
) -> Result<u64> {
    let bytes = encode_step(header, sections, compression)
        .map_err(|e| slosh_fileio::IoError::new(path, e))?;
    slosh_fileio::atomic_write(path, &bytes)?;
    Ok(bytes.len() as u64)
}
