//! Assembling a step file: encode sections (in parallel), lay them out page-aligned after the
//! JSON header, close with the footer, write atomically.

use std::path::Path;

use rayon::prelude::*;
use xxhash_rust::xxh3::xxh3_64;

use crate::error::Result;
use crate::format::{
    ChunkEntry, Encoding, Footer, Header, MAJOR, MINOR, PREAMBLE_LEN, Preamble, SectionEntry,
    align_up, hex64,
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
    // Chunks are encoded in parallel; a section keeps its encoding only where that saves at
    // least 10 % over all its chunks, and is stored raw instead where its raw rank comes up
    // within the budget.
    let jobs: Vec<(usize, &[u8])> = sections
        .iter()
        .enumerate()
        .flat_map(|(i, s)| s.bytes.chunks(s.chunk_raw() as usize).map(move |c| (i, c)))
        .collect();
    // Each section's chunks among the jobs.
    let mut at = 0;
    let spans: Vec<std::ops::Range<usize>> = sections
        .iter()
        .map(|s| {
            let n = s.bytes.len().div_ceil(s.chunk_raw() as usize);
            at += n;
            at - n..at
        })
        .collect();
    let level = match compression {
        Compression::Level(level) => Some(level),
        Compression::None => None,
    };
    let compressible = |k: usize| level.is_some() && sections[k].encoding != Encoding::Raw;
    let mut packed: Vec<Option<Vec<u8>>> = vec![None; jobs.len()];
    // The chunks of sections `ks`, encoded.
    let encode = |ks: &[usize], packed: &mut [Option<Vec<u8>>]| -> std::io::Result<()> {
        let todo: Vec<usize> = ks.iter().flat_map(|&k| spans[k].clone()).collect();
        let done: Vec<Vec<u8>> = todo
            .par_iter()
            .map(|&j| {
                let (i, raw) = jobs[j];
                crate::codec::encode(raw, sections[i].encoding, level.unwrap_or(1))
            })
            .collect::<std::io::Result<_>>()?;
        for (j, bytes) in todo.into_iter().zip(done) {
            packed[j] = Some(bytes);
        }
        Ok(())
    };
    let encoded_len = |k: usize, packed: &[Option<Vec<u8>>]| -> Option<usize> {
        packed[spans[k].clone()]
            .iter()
            .map(|p| p.as_ref().map(Vec::len))
            .sum()
    };
    let keeps = |k: usize, packed: &[Option<Vec<u8>>]| {
        encoded_len(k, packed).is_some_and(|len| len * 10 <= sections[k].bytes.len() * 9)
    };
    // Each section counts as the file lays it out, to whole pages: in a small step the pages
    // a raw section adds are what passes the budget.
    let stored_len = |k: usize, keep: bool, packed: &[Option<Vec<u8>>]| {
        align_up(match (keep, encoded_len(k, packed)) {
            (true, Some(len)) => len,
            _ => sections[k].bytes.len(),
        })
    };
    let budget = (header.points.saturating_mul(RAW_BUDGET_BYTES_PER_POINT)) as usize;
    // Sections without a raw rank are encoded; those with one, from the last rank down, only
    // until the rest fit the budget raw: those then go raw whatever they would encode to
    // (at 1M points, 40 of a step's 46 MB), as the rule below decides for them.
    let unranked: Vec<usize> = (0..sections.len())
        .filter(|&k| compressible(k) && sections[k].raw_rank.is_none())
        .collect();
    encode(&unranked, &mut packed)?;
    let mut ranked: Vec<usize> = (0..sections.len())
        .filter(|&k| compressible(k) && sections[k].raw_rank.is_some())
        .collect();
    ranked.sort_by_key(|&k| sections[k].raw_rank);
    let mut unencoded = ranked.len();
    while unencoded > 0 {
        let bound: usize = (0..sections.len())
            .map(|k| stored_len(k, keeps(k, &packed), &packed))
            .sum();
        if bound <= budget {
            break;
        }
        unencoded -= 1;
        encode(&[ranked[unencoded]], &mut packed)?;
    }
    let mut keep: Vec<bool> = (0..sections.len()).map(|k| keeps(k, &packed)).collect();
    // Sections with a raw rank go raw, rank by rank, while the total stays within budget.
    let mut total: usize = (0..sections.len())
        .map(|k| stored_len(k, keep[k], &packed))
        .sum();
    for &k in &ranked {
        if !keep[k] {
            continue;
        }
        // `k` is still kept compressed here.
        let raw_total = total - stored_len(k, true, &packed) + align_up(sections[k].bytes.len());
        if raw_total <= budget {
            keep[k] = false;
            total = raw_total;
        }
    }
    // Each section's stored chunks; their checksums, and each section's, all at once.
    let parts: Vec<Vec<&[u8]>> = (0..sections.len())
        .map(|k| {
            spans[k]
                .clone()
                .map(|j| match (&packed[j], keep[k]) {
                    (Some(bytes), true) => bytes.as_slice(),
                    _ => jobs[j].1,
                })
                .collect()
        })
        .collect();
    let sums: Vec<(u64, Vec<ChunkEntry>)> = parts
        .par_iter()
        .map(|chunks| {
            let table = chunks
                .par_iter()
                .map(|p| ChunkEntry {
                    stored: p.len() as u64,
                    xxh3: hex64(xxh3_64(p)),
                })
                .collect();
            let mut whole = xxhash_rust::xxh3::Xxh3::new();
            for p in chunks {
                whole.update(p);
            }
            (whole.digest(), table)
        })
        .collect();
    let encoded: Vec<(Encoding, usize, u64, Vec<ChunkEntry>)> = sections
        .iter()
        .zip(sums)
        .enumerate()
        .map(|(k, (s, (xxh3, table)))| {
            let encoding = if keep[k] { s.encoding } else { Encoding::Raw };
            let stored = parts[k].iter().map(|p| p.len()).sum();
            (encoding, stored, xxh3, table)
        })
        .collect();

    // The header records offsets, which depend on the header's length: lay out with a guess,
    // then again until the length settles (twice at most in practice).
    let mut header_len_guess = 0usize;
    let (header_bytes, offsets) = loop {
        let mut offset = align_up(PREAMBLE_LEN + header_len_guess);
        let mut offsets = Vec::with_capacity(sections.len());
        header.sections = sections
            .iter()
            .zip(&encoded)
            .map(|(s, (encoding, stored, xxh3, chunks))| {
                offsets.push(offset);
                let entry = SectionEntry {
                    name: s.name.clone(),
                    element: s.element.name().to_string(),
                    count: (s.bytes.len() / s.element.size()) as u64,
                    offset: offset as u64,
                    stored: *stored as u64,
                    raw: s.bytes.len() as u64,
                    encoding: *encoding,
                    xxh3: hex64(*xxh3),
                    chunk_raw: s.chunk_raw(),
                    chunks: chunks.clone(),
                };
                offset = align_up(offset + stored);
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
        .map_or(PREAMBLE_LEN + header_bytes.len(), |(o, e)| o + e.1);
    // Zeroed by the allocator (fresh pages, not a pass over them): the padding stays zero.
    let mut out = vec![0u8; body_end + crate::format::FOOTER_LEN];
    let preamble = Preamble {
        major: MAJOR,
        minor: MINOR,
        flags: 0,
        header_len: header_bytes.len() as u64,
        header_xxh3: xxh3_64(&header_bytes),
    }
    .to_bytes();
    out[..PREAMBLE_LEN].copy_from_slice(&preamble);
    out[PREAMBLE_LEN..PREAMBLE_LEN + header_bytes.len()].copy_from_slice(&header_bytes);
    // The sections copied into their places in parallel: at 1M points, one thread took as
    // long as everything else here.
    let mut places: Vec<(&mut [u8], &[u8])> = Vec::with_capacity(jobs.len());
    let mut rest = &mut out[..];
    let mut base = 0;
    for (offset, chunks) in offsets.iter().zip(&parts) {
        let mut at = *offset;
        for &chunk in chunks {
            let (_, tail) = rest.split_at_mut(at - base);
            let (place, tail) = tail.split_at_mut(chunk.len());
            places.push((place, chunk));
            rest = tail;
            at += chunk.len();
            base = at;
        }
    }
    places
        .into_par_iter()
        .for_each(|(place, chunk)| place.copy_from_slice(chunk));
    out.truncate(body_end);
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
