//! Section encodings: byte shuffling, word deltas and zstd, and their inverses straight into a
//! caller's buffer.

use crate::format::Encoding;

/// Encodes `raw` (a multiple of the shuffle width for the shuffled encodings).
pub fn encode(raw: &[u8], encoding: Encoding, level: i32) -> std::io::Result<Vec<u8>> {
    if let Some(width) = encoding.shuffle_width()
        && !raw.len().is_multiple_of(width)
    {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "{} bytes are not whole {width}-byte elements for {}",
                raw.len(),
                encoding.name()
            ),
        ));
    }
    match encoding {
        Encoding::Raw => Ok(raw.to_vec()),
        Encoding::Zstd => zstd::bulk::compress(raw, level),
        Encoding::Delta4Shuffle4Zstd => zstd::bulk::compress(&shuffle4(&delta4(raw)), level),
        Encoding::Shuffle4Zstd
        | Encoding::Shuffle16Zstd
        | Encoding::Shuffle20Zstd
        | Encoding::Shuffle24Zstd
        | Encoding::Shuffle32Zstd
        | Encoding::Shuffle64Zstd => {
            let width = encoding.shuffle_width().unwrap_or(4);
            zstd::bulk::compress(&shuffle(raw, width), level)
        }
    }
}

/// Why stored bytes could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("zstd: {0}")]
    Zstd(String),
    #[error("decodes to {found} bytes, expected {expected}")]
    Size { expected: usize, found: usize },
}

/// Decodes `stored` into `out`, whose length is the expected raw size. `scratch` is reused
/// between calls so that decoding allocates nothing in steady state.
pub fn decode_into(
    stored: &[u8],
    encoding: Encoding,
    out: &mut [u8],
    scratch: &mut Vec<u8>,
) -> Result<(), DecodeError> {
    let expected = out.len();
    let size = |found| DecodeError::Size { expected, found };
    match encoding {
        Encoding::Raw => {
            if stored.len() != expected {
                return Err(size(stored.len()));
            }
            out.copy_from_slice(stored);
        }
        Encoding::Zstd => {
            let n = unzstd(stored, out)?;
            if n != expected {
                return Err(size(n));
            }
        }
        Encoding::Shuffle4Zstd
        | Encoding::Delta4Shuffle4Zstd
        | Encoding::Shuffle16Zstd
        | Encoding::Shuffle20Zstd
        | Encoding::Shuffle24Zstd
        | Encoding::Shuffle32Zstd
        | Encoding::Shuffle64Zstd => {
            let width = encoding.shuffle_width().unwrap_or(4);
            if !expected.is_multiple_of(width) {
                return Err(size(expected));
            }
            // Decompressed straight into the scratch's capacity: no zero-fill first.
            scratch.clear();
            scratch.reserve(expected);
            let n = unzstd(stored, scratch)?;
            if n != expected {
                return Err(size(n));
            }
            unshuffle_into(scratch, out, width);
            if encoding == Encoding::Delta4Shuffle4Zstd {
                undelta4_in_place(out);
            }
        }
    }
    Ok(())
}

fn unzstd<C: zstd::zstd_safe::WriteBuf + ?Sized>(
    stored: &[u8],
    out: &mut C,
) -> Result<usize, DecodeError> {
    thread_local! {
        /// One decompression context per thread: a step decodes up to hundreds of chunks.
        static DECOMPRESSOR: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
            const { std::cell::RefCell::new(None) };
    }
    DECOMPRESSOR.with_borrow_mut(|slot| {
        let dec = match slot {
            Some(dec) => dec,
            None => slot.insert(
                zstd::bulk::Decompressor::new().map_err(|e| DecodeError::Zstd(e.to_string()))?,
            ),
        };
        // A frame that claims more than `out` holds is an error, never an allocation.
        dec.decompress_to_buffer(stored, out)
            .map_err(|e| DecodeError::Zstd(e.to_string()))
    })
}

/// Regroups bytes by their position within each 4-byte word.
pub fn shuffle4(raw: &[u8]) -> Vec<u8> {
    shuffle(raw, 4)
}

/// Regroups bytes by their position within each `width`-byte element: byte 0 of every
/// element, then byte 1, … (`raw` holds whole elements).
pub fn shuffle(raw: &[u8], width: usize) -> Vec<u8> {
    let mut out = vec![0u8; raw.len()];
    transpose_width(raw, &mut out, width, Direction::Shuffle);
    out
}

/// The inverse of [`shuffle`], into `out` (as long as `shuffled`).
fn unshuffle_into(shuffled: &[u8], out: &mut [u8], width: usize) {
    transpose_width(shuffled, out, width, Direction::Unshuffle);
}

/// [`transpose`] with the encodings' widths as constants, so that each gets its own unrolled
/// loop.
fn transpose_width(from: &[u8], to: &mut [u8], width: usize, direction: Direction) {
    match width {
        4 => transpose(from, to, 4, direction),
        16 => transpose(from, to, 16, direction),
        20 => transpose(from, to, 20, direction),
        24 => transpose(from, to, 24, direction),
        32 => transpose(from, to, 32, direction),
        64 => transpose(from, to, 64, direction),
        _ => transpose(from, to, width, direction),
    }
}

/// Elements per block of the transposes: a block's elements (at most 4 KiB) stay in L1 while
/// every byte plane is read or written along them.
const BLOCK: usize = 64;

#[derive(Clone, Copy, PartialEq)]
enum Direction {
    /// Elements in `from`, byte planes out.
    Shuffle,
    /// Byte planes in `from`, elements out.
    Unshuffle,
}

/// Between whole `width`-byte elements and their byte planes, a block of elements at a time.
#[inline(always)]
fn transpose(from: &[u8], to: &mut [u8], width: usize, direction: Direction) {
    let count = from.len() / width;
    for first in (0..count).step_by(BLOCK) {
        let block = BLOCK.min(count - first);
        let elements = first * width..(first + block) * width;
        for b in 0..width {
            let plane = b * count + first..b * count + first + block;
            match direction {
                Direction::Shuffle => {
                    for (slot, element) in to[plane]
                        .iter_mut()
                        .zip(from[elements.clone()].chunks_exact(width))
                    {
                        *slot = element[b];
                    }
                }
                Direction::Unshuffle => {
                    for (element, &byte) in to[elements.clone()]
                        .chunks_exact_mut(width)
                        .zip(&from[plane])
                    {
                        element[b] = byte;
                    }
                }
            }
        }
    }
}

/// Little-endian u32 words replaced by their wrapping difference from the previous word.
fn delta4(raw: &[u8]) -> Vec<u8> {
    let mut prev = 0u32;
    let mut out = Vec::with_capacity(raw.len());
    for chunk in raw.chunks_exact(4) {
        let v = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
        out.extend_from_slice(&v.wrapping_sub(prev).to_le_bytes());
        prev = v;
    }
    out
}

fn undelta4_in_place(words: &mut [u8]) {
    let mut prev = 0u32;
    for chunk in words.chunks_exact_mut(4) {
        let v = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]).wrapping_add(prev);
        chunk.copy_from_slice(&v.to_le_bytes());
        prev = v;
    }
}
