//! One staging buffer per step, filled in parallel: raw sections checksummed and copied from
//! the map run by run, compressed ones decoded run by run straight into it, the copies
//! recorded.

use rayon::prelude::*;
use slosh_cache::{CacheFile, Encoding, SectionEntry};

use super::EMPTY_BINDING;
use super::host::Source;
use crate::buffer_shelf::{BufferShelf, new_section};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::staging::StagingPool;

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

/// Where [`storage_buffers`] takes its memory from, and when it gives up.
#[derive(Clone, Copy, Default)]
pub(super) struct Memory<'a> {
    pub(super) staging: Option<&'a StagingPool>,
    pub(super) shelf: Option<&'a BufferShelf>,
    pub(super) cancelled: Option<&'a (dyn Fn() -> bool + Sync)>,
}

/// Device-local storage buffers for `arrays` (label, bytes), all filled
/// through one staging buffer (one allocation per step, not one per section), whose pieces
/// are copied or decoded in parallel; the copies are recorded into `encoder`.
pub(super) fn storage_buffers(
    gpu: &Gpu,
    file: &CacheFile,
    arrays: &[(&str, Source<'_>)],
    encoder: &mut wgpu::CommandEncoder,
    memory: Memory<'_>,
) -> Result<(Vec<wgpu::Buffer>, Option<wgpu::Buffer>)> {
    let Memory {
        staging: pool,
        shelf,
        cancelled,
    } = memory;
    // Each array's place in the staging buffer, 256-byte aligned.
    let mut offsets = Vec::with_capacity(arrays.len());
    let mut total = 0u64;
    for (_, source) in arrays {
        offsets.push(total);
        total += source.len().next_multiple_of(256);
    }
    let targets: Vec<wgpu::Buffer> = arrays
        .iter()
        .map(|(label, source)| {
            let size = source.len().max(EMPTY_BINDING).next_multiple_of(4);
            // An empty section binds zeros: only a new buffer is known to hold them.
            match shelf {
                Some(shelf) if source.len() > 0 => shelf.take(gpu, label, size),
                _ => new_section(gpu, label, size),
            }
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
        .map(|(_, source)| match source {
            Source::Runs { entry, .. } => entry.chunk_spans(),
            Source::Bytes(_) => Vec::new(),
        })
        .collect();
    let view = |start: u64, len: usize| {
        let end = start + (len as u64).next_multiple_of(4);
        staging
            .slice(start..end)
            .get_mapped_range_mut()
            .map_err(|e| Error::Readback(e.to_string()))
    };
    let pieces = || -> Result<Vec<_>> {
        let mut pieces = Vec::new();
        for (((_, source), &offset), spans) in arrays.iter().zip(&offsets).zip(&spans) {
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
        Ok(pieces)
    };
    // A view that cannot be made (a run placed off the mapping's alignment) is given up as a
    // failed fill is: nothing is left mapped or taken.
    let filled = pieces().and_then(|pieces| {
        pieces.into_par_iter().try_for_each_init(
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
                    } if entry.encoding == Encoding::Raw => {
                        // A raw run is checksummed and copied straight in: one pass over the map.
                        // Opening the file checked that raw chunks are stored as they are, so the
                        // run fills its view.
                        let bytes = file.checked_run(entry, spans, k)?;
                        view.slice(..bytes.len()).copy_from_slice(bytes);
                    }
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
        )
    });
    // Raw pieces were copied straight from the map, which may have gone to zeros under them.
    let filled = filled.and_then(|()| file.unchanged().map_err(Error::from));
    if let Err(e) = filled {
        // Still mapped and never submitted: ready for the next upload as it is. The section
        // buffers go back too: a prefetch that a jump cancels would otherwise drop a step's
        // worth, and the next uploads would allocate device memory on the jump's path.
        if let Some(pool) = pool {
            pool.restore(staging);
        }
        if let Some(shelf) = shelf {
            for target in targets {
                shelf.put(target);
            }
        }
        return Err(e);
    }
    staging.unmap();
    for (((_, source), offset), target) in arrays.iter().zip(&offsets).zip(&targets) {
        if source.len() > 0 {
            let size = source.len().next_multiple_of(4);
            encoder.copy_buffer_to_buffer(&staging, *offset, target, 0, size);
        }
    }
    Ok((targets, pool.map(|_| staging)))
}

/// Bytes copied per task into a staging buffer.
const COPY_PIECE: usize = 1 << 20;
