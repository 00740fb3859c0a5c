//! Opening a step file: the map (or read) and the structural checks that make every later
//! access safe: magic, version, footer, header checksum, section table bounds.

use std::collections::HashSet;
use std::path::Path;

use bytemuck::Pod;
use slosh_fileio::FileBytes;
use xxhash_rust::xxh3::xxh3_64;

use crate::bvh::Bvh;
use crate::bvh_grid::GpuBvhNode;
use crate::codec::decode_into;
use crate::error::{Error, Result};
use crate::format::{
    ALIGN, CHUNK_ALIGN, FOOTER_LEN, FOOTER_MAGIC, Footer, Header, MAGIC, MAJOR, MINOR,
    PREAMBLE_LEN, Preamble, SectionEntry, hex64,
};
use crate::layout::Element;

/// A step file, mapped and structurally checked. Section contents are checked when they are
/// decoded (checksum) or by [`CacheFile::verify`] (everything).
#[derive(Debug)]
pub struct CacheFile {
    bytes: FileBytes,
    preamble: Preamble,
    footer: Footer,
    header: Header,
    /// Only for fuzzing: see [`CacheFile::parse`].
    skip_checksums: bool,
}

/// The source case an older file names in its header, for the re-bake command ("CASE" where
/// its header cannot be read).
fn older_source(bytes: &[u8], preamble: &Preamble) -> String {
    let header = usize::try_from(preamble.header_len)
        .ok()
        .and_then(|len| bytes.get(PREAMBLE_LEN..PREAMBLE_LEN.checked_add(len)?));
    header
        .and_then(|h| serde_json::from_slice::<serde_json::Value>(h).ok())
        .and_then(|v| v["source"]["path"].as_str().map(str::to_string))
        .unwrap_or_else(|| "CASE".into())
}

/// The chunk table of a section: one chunk per `chunk_raw` raw bytes (a positive multiple
/// of 8 and of the encoding's shuffle width), their stored sizes adding up to the section's,
/// each raw chunk stored as it is.
fn check_chunks(s: &SectionEntry) -> std::result::Result<(), String> {
    let step = s.encoding.chunk_step();
    if s.chunk_raw == 0 || !s.chunk_raw.is_multiple_of(step) {
        let of = match s.encoding.shuffle_width() {
            Some(width) => format!(
                "a positive multiple of {step}: of {CHUNK_ALIGN}, and of {width}, the {} width",
                s.encoding.name()
            ),
            None => format!("a positive multiple of {CHUNK_ALIGN}"),
        };
        return Err(format!(
            "chunks of {} raw bytes ({of} expected)",
            s.chunk_raw
        ));
    }
    let expected = s.raw.div_ceil(s.chunk_raw);
    if s.chunks.len() as u64 != expected {
        return Err(format!(
            "{} chunks for {} raw bytes in chunks of {} ({expected} expected)",
            s.chunks.len(),
            s.raw,
            s.chunk_raw
        ));
    }
    let total = s
        .chunks
        .iter()
        .try_fold(0u64, |sum, c| sum.checked_add(c.stored));
    if total != Some(s.stored) {
        return Err(format!(
            "chunks store {} bytes, the section {}",
            total.map_or("more than 2^64".into(), |t| t.to_string()),
            s.stored
        ));
    }
    if s.encoding == crate::format::Encoding::Raw
        && let Some((k, _)) = s
            .chunk_spans()
            .iter()
            .enumerate()
            .find(|(_, (st, r))| st.len() != r.len())
    {
        return Err(format!("raw chunk {k} is not stored as it is"));
    }
    Ok(())
}

impl CacheFile {
    pub fn open(path: &Path) -> Result<CacheFile> {
        CacheFile::from_bytes(FileBytes::open(path)?)
    }

    pub fn from_bytes(bytes: FileBytes) -> Result<CacheFile> {
        CacheFile::parse(bytes, false)
    }

    /// Opens `bytes`; with `skip_checksums` (fuzzing only) no checksum is ever compared, so
    /// that mutated bytes reach the parser, the decoders and the invariant checks.
    pub(crate) fn parse(bytes: FileBytes, skip_checksums: bool) -> Result<CacheFile> {
        let path = bytes.path().to_path_buf();
        let len = bytes.len();
        let format = |offset: usize, expected: &str, found: String| Error::Format {
            path: path.clone(),
            offset: offset as u64,
            expected: expected.to_string(),
            found,
        };
        if len < PREAMBLE_LEN + FOOTER_LEN {
            return Err(format(
                len,
                "a 32-byte preamble and a 32-byte footer",
                format!("a file of {len} bytes (truncated?)"),
            ));
        }
        if bytes[..8] != MAGIC {
            return Err(format(
                0,
                "the .slc magic 89 53 4c 43 0d 0a 1a 0a",
                format!("{:02x?}", &bytes[..8]),
            ));
        }
        let mut pre = [0u8; PREAMBLE_LEN];
        pre.copy_from_slice(&bytes[..PREAMBLE_LEN]);
        let preamble = Preamble::parse(&pre);
        if preamble.major > MAJOR {
            return Err(Error::NewerVersion {
                path,
                found_major: preamble.major,
                found_minor: preamble.minor,
                supported: MAJOR,
            });
        }
        if preamble.major < MAJOR {
            return Err(Error::OlderVersion {
                case: older_source(&bytes, &preamble),
                path,
                found_major: preamble.major,
                found_minor: preamble.minor,
                supported_major: MAJOR,
                supported_minor: MINOR,
            });
        }
        let foot = len - FOOTER_LEN;
        if bytes[foot..foot + 8] != FOOTER_MAGIC {
            return Err(format(
                foot,
                "the footer magic \"SLC-END\\n\" in the last 32 bytes (the file may be truncated)",
                format!("{:02x?}", &bytes[foot..foot + 8]),
            ));
        }
        let word = |o: usize| {
            let mut w = [0u8; 8];
            w.copy_from_slice(&bytes[o..o + 8]);
            u64::from_le_bytes(w)
        };
        let footer = Footer {
            file_len: word(foot + 8),
            body_xxh3: word(foot + 16),
        };
        if footer.file_len != len as u64 {
            return Err(format(
                foot + 8,
                &format!("the file length {len}"),
                format!("{} (truncated or appended to)", footer.file_len),
            ));
        }
        if word(foot + 24) != 0 {
            return Err(format(foot + 24, "reserved zero", hex64(word(foot + 24))));
        }
        let header_end = usize::try_from(preamble.header_len)
            .ok()
            .and_then(|h| h.checked_add(PREAMBLE_LEN))
            .filter(|&e| e <= foot)
            .ok_or_else(|| {
                format(
                    16,
                    "a header length that fits in the file",
                    preamble.header_len.to_string(),
                )
            })?;
        let header_bytes = &bytes[PREAMBLE_LEN..header_end];
        let sum = xxh3_64(header_bytes);
        if sum != preamble.header_xxh3 && !skip_checksums {
            return Err(format(
                PREAMBLE_LEN,
                &format!("a header with xxh3 {}", hex64(preamble.header_xxh3)),
                format!("xxh3 {} (corrupt header)", hex64(sum)),
            ));
        }
        let header: Header = serde_json::from_slice(header_bytes).map_err(|e| {
            format(
                PREAMBLE_LEN + e.column().saturating_sub(1),
                "the JSON header",
                e.to_string(),
            )
        })?;
        let mut names = HashSet::new();
        let mut end = header_end;
        for s in &header.sections {
            let bad = |problem: String| Error::Section {
                path: path.clone(),
                section: s.name.clone(),
                offset: s.offset,
                problem,
            };
            let element = Element::from_name(&s.element)
                .ok_or_else(|| bad(format!("unknown element type '{}'", s.element)))?;
            if !names.insert(s.name.as_str()) {
                return Err(bad("the name appears twice in the section table".into()));
            }
            if s.count.checked_mul(element.size() as u64) != Some(s.raw) {
                return Err(bad(format!(
                    "{} elements of {} bytes cannot be {} raw bytes",
                    s.count,
                    element.size(),
                    s.raw
                )));
            }
            let start = usize::try_from(s.offset).unwrap_or(usize::MAX);
            let stop = usize::try_from(s.stored)
                .ok()
                .and_then(|n| start.checked_add(n));
            if start % ALIGN != 0 || start < end || stop.is_none_or(|e| e > foot) {
                return Err(bad(format!(
                    "stored bytes {}..+{} are not page-aligned, in order and inside the body \
                     (which ends at byte {foot})",
                    s.offset, s.stored
                )));
            }
            if s.encoding == crate::format::Encoding::Raw && s.stored != s.raw {
                return Err(bad(format!(
                    "raw section stores {} bytes for {} raw",
                    s.stored, s.raw
                )));
            }
            check_chunks(s).map_err(bad)?;
            end = stop.unwrap_or(foot);
        }
        Ok(CacheFile {
            bytes,
            preamble,
            footer,
            header,
            skip_checksums,
        })
    }

    pub fn path(&self) -> &Path {
        self.bytes.path()
    }

    /// Every byte of the file.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    pub fn version(&self) -> (u16, u16) {
        (self.preamble.major, self.preamble.minor)
    }

    pub fn file_len(&self) -> u64 {
        self.bytes.len() as u64
    }

    pub fn is_mapped(&self) -> bool {
        self.bytes.is_mapped()
    }

    /// An error where the file shrank under its map since it was opened (another program
    /// truncated or rewrote it in place): whatever was read from it since may be zeros.
    pub fn unchanged(&self) -> Result<()> {
        if self.bytes.changed() {
            return Err(Error::Invalid {
                path: self.path().to_path_buf(),
                problem: "the file changed while it was read (truncated or rewritten in place by \
                          another program); nothing read from it is used"
                    .into(),
            });
        }
        Ok(())
    }

    /// The footer's xxh3 over the body, as recorded.
    pub fn footer_checksum(&self) -> u64 {
        self.footer.body_xxh3
    }

    /// Whether the xxh3 of every byte before the footer matches the footer.
    pub fn body_intact(&self) -> bool {
        if self.skip_checksums {
            return true;
        }
        let foot = self.bytes.len() - FOOTER_LEN;
        xxh3_64(&self.bytes[..foot]) == self.footer.body_xxh3 && !self.bytes.changed()
    }

    pub fn section(&self, name: &str) -> Option<&SectionEntry> {
        self.header.sections.iter().find(|s| s.name == name)
    }

    fn required(&self, name: &str) -> Result<&SectionEntry> {
        self.section(name).ok_or_else(|| Error::Invalid {
            path: self.path().to_path_buf(),
            problem: format!("no section '{name}'"),
        })
    }

    /// The stored bytes of a section (bounds were checked at open).
    pub fn stored(&self, entry: &SectionEntry) -> &[u8] {
        let start = entry.offset as usize;
        &self.bytes[start..start + entry.stored as usize]
    }

    /// A raw section's bytes in place (zero-copy from the map); `None` if it is compressed.
    pub fn raw_bytes(&self, name: &str) -> Option<&[u8]> {
        self.section(name)
            .filter(|s| s.encoding == crate::format::Encoding::Raw)
            .map(|s| self.stored(s))
    }

    fn section_error(&self, entry: &SectionEntry, problem: String) -> Error {
        Error::Section {
            path: self.path().to_path_buf(),
            section: entry.name.clone(),
            offset: entry.offset,
            problem,
        }
    }

    /// Checks a stored run's checksum against `expected` (16 hex digits).
    pub(crate) fn check_sum(
        &self,
        entry: &SectionEntry,
        what: &str,
        at: usize,
        bytes: &[u8],
        expected: &str,
    ) -> Result<()> {
        let sum = hex64(xxh3_64(bytes));
        self.unchanged()?;
        if sum != expected && !self.skip_checksums {
            return Err(self.section_error(
                entry,
                format!(
                    "{what} (stored bytes {at}..{}): checksum xxh3 {sum}, the table says {expected} (corrupt)",
                    at + bytes.len()
                ),
            ));
        }
        Ok(())
    }

    /// The stored bytes of a section after checking its checksums (chunk by chunk, in
    /// parallel, where it has chunks): for a raw section, its decoded bytes in place
    /// (zero-copy from the map).
    pub fn checked_stored(&self, entry: &SectionEntry) -> Result<&[u8]> {
        use rayon::prelude::*;
        let stored = self.stored(entry);
        if entry.chunks.is_empty() {
            self.check_sum(entry, "section", 0, stored, &entry.xxh3)?;
        } else {
            entry
                .chunk_spans()
                .par_iter()
                .zip(&entry.chunks)
                .enumerate()
                .try_for_each(|(k, ((st, _), chunk))| {
                    let what = format!("chunk {k}");
                    self.check_sum(entry, &what, st.start, &stored[st.clone()], &chunk.xxh3)
                })?;
        }
        Ok(stored)
    }

    /// Checks the section's checksums, then decodes it into `out` (exactly `entry.raw` bytes),
    /// its runs in parallel. `scratch` is reused for a section of one run.
    pub fn decode_into(
        &self,
        entry: &SectionEntry,
        out: &mut [u8],
        scratch: &mut Vec<u8>,
    ) -> Result<()> {
        use rayon::prelude::*;
        if out.len() as u64 != entry.raw {
            return Err(self.section_error(
                entry,
                format!(
                    "a {}-byte buffer was given for {} bytes",
                    out.len(),
                    entry.raw
                ),
            ));
        }
        let spans = entry.chunk_spans();
        if spans.len() == 1 {
            return self.decode_run_into(entry, &spans, 0, out, scratch);
        }
        let mut outs: Vec<&mut [u8]> = Vec::with_capacity(spans.len());
        let mut rest = out;
        for (_, raw) in &spans {
            let (head, tail) = rest.split_at_mut(raw.len());
            outs.push(head);
            rest = tail;
        }
        outs.into_par_iter()
            .enumerate()
            .try_for_each_init(Vec::new, |scratch, (k, out)| {
                self.decode_run_into(entry, &spans, k, out, scratch)
            })
    }

    /// Checks every run of `entry` against its checksum and, where compressed, that it
    /// decodes to its raw size, keeping nothing: runs in parallel, each decoded into a
    /// buffer its thread reuses, so that a verifier allocates no section's worth of memory. A
    /// raw run, checksummed, is what a reader gets (opening the file checked that raw runs
    /// are stored as they are).
    pub fn check_decodes(&self, entry: &SectionEntry) -> Result<()> {
        use rayon::prelude::*;
        let spans = entry.chunk_spans();
        (0..spans.len()).into_par_iter().try_for_each_init(
            || (Vec::new(), Vec::new()),
            |(out, scratch), k| {
                if entry.encoding == crate::format::Encoding::Raw {
                    return self.checked_run(entry, &spans, k).map(|_| ());
                }
                out.resize(spans[k].1.len(), 0);
                self.decode_run_into(entry, &spans, k, out, scratch)
            },
        )
    }

    /// Run `k` of a section as stored (its chunk, or the whole section where the table has no
    /// chunks; `spans` from [`SectionEntry::chunk_spans`]), its checksum checked: a raw run is
    /// then ready to copy where it belongs. Whoever copies it asks [`CacheFile::unchanged`]
    /// afterwards (the map may go to zeros under the copy).
    pub fn checked_run(
        &self,
        entry: &SectionEntry,
        spans: &[(std::ops::Range<usize>, std::ops::Range<usize>)],
        k: usize,
    ) -> Result<&[u8]> {
        let Some((st, _)) = spans.get(k) else {
            return Err(self.section_error(entry, format!("no run {k}")));
        };
        let bytes = &self.stored(entry)[st.clone()];
        let sum = entry.chunks.get(k).map_or(&entry.xxh3, |chunk| &chunk.xxh3);
        self.check_sum(entry, &run_label(entry, k), st.start, bytes, sum)?;
        Ok(bytes)
    }

    /// Checks run `k` of a section (its chunk, or the whole section where the table has no
    /// chunks; `spans` from [`SectionEntry::chunk_spans`]) and decodes it into `out`, exactly
    /// the run's raw bytes. Runs decode independently, so a caller can put each straight
    /// where it belongs (a GPU staging buffer), on any thread.
    pub fn decode_run_into(
        &self,
        entry: &SectionEntry,
        spans: &[(std::ops::Range<usize>, std::ops::Range<usize>)],
        k: usize,
        out: &mut [u8],
        scratch: &mut Vec<u8>,
    ) -> Result<()> {
        let bytes = self.checked_run(entry, spans, k)?;
        let st = &spans[k].0;
        let decoded = decode_into(bytes, entry.encoding, out, scratch);
        // The bytes may have gone to zeros after their checksum was taken: that, not the
        // decoder's complaint about them, is what happened.
        self.unchanged()?;
        decoded.map_err(|e| {
            let problem = if entry.chunks.is_empty() {
                e.to_string()
            } else {
                let what = run_label(entry, k);
                format!("{what} (stored bytes {}..{}): {e}", st.start, st.end)
            };
            self.section_error(entry, problem)
        })
    }

    /// One zeroed buffer per section, each the size of its decoded bytes.
    pub fn section_buffers(&self) -> Vec<Vec<u8>> {
        self.header
            .sections
            .iter()
            .map(|s| vec![0u8; s.raw as usize])
            .collect()
    }

    /// Decodes every section into `buffers` (from [`CacheFile::section_buffers`] of a file with
    /// the same table, reused across steps), sections in parallel.
    pub fn decode_all_into(&self, buffers: &mut [Vec<u8>]) -> Result<()> {
        use rayon::prelude::*;
        self.header
            .sections
            .par_iter()
            .zip(buffers.par_iter_mut())
            .try_for_each_init(Vec::new, |scratch, (entry, buf)| {
                buf.resize(entry.raw as usize, 0);
                self.decode_into(entry, buf, scratch)
            })
    }

    /// The BVH, its boxes decoded from the header's grid.
    pub fn bvh(&self) -> Result<Bvh> {
        let nodes: Vec<GpuBvhNode> = self.decode(crate::names::BVH_NODES)?;
        Ok(Bvh::from_stored(&self.header().bvh_grid, &nodes))
    }

    /// Decodes a whole section into a new vector of `T`.
    pub fn decode<T: Pod>(&self, name: &str) -> Result<Vec<T>> {
        let entry = self.required(name)?;
        let element = Element::from_name(&entry.element).map(Element::size);
        if element != Some(size_of::<T>()) {
            return Err(self.section_error(
                entry,
                format!(
                    "holds '{}' elements, read as {} bytes each",
                    entry.element,
                    size_of::<T>()
                ),
            ));
        }
        let mut out: Vec<T> = bytemuck::zeroed_vec(entry.count as usize);
        self.decode_into(entry, bytemuck::cast_slice_mut(&mut out), &mut Vec::new())?;
        Ok(out)
    }
}

/// How errors name run `k` of a section: its chunk, or the whole section where the table
/// has no chunks.
fn run_label(entry: &SectionEntry, k: usize) -> String {
    if entry.chunks.get(k).is_some() {
        format!("chunk {k}")
    } else {
        "section".to_string()
    }
}
