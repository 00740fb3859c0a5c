//! Section encodings: byte shuffling, word deltas and zstd, and their inverses straight into a
//! caller's buffer.

use crate::format::Encoding;

/// Encodes `raw` (a multiple of 4 bytes for the shuffled encodings).
pub fn encode(raw: &[u8], encoding: Encoding, level: i32) -> std::io::Result<Vec<u8>> {
    match encoding {
        Encoding::Raw => Ok(raw.to_vec()),
        Encoding::Zstd => zstd::bulk::compress(raw, level),
        Encoding::Shuffle4Zstd => zstd::bulk::compress(&shuffle4(raw), level),
        Encoding::Delta4Shuffle4Zstd => zstd::bulk::compress(&shuffle4(&delta4(raw)), level),
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
        Encoding::Shuffle4Zstd | Encoding::Delta4Shuffle4Zstd => {
            if !expected.is_multiple_of(4) {
                return Err(size(expected));
            }
            scratch.clear();
            scratch.resize(expected, 0);
            let n = unzstd(stored, scratch)?;
            if n != expected {
                return Err(size(n));
            }
            unshuffle4_into(scratch, out);
            if encoding == Encoding::Delta4Shuffle4Zstd {
                undelta4_in_place(out);
            }
        }
    }
    Ok(())
}

fn unzstd(stored: &[u8], out: &mut [u8]) -> Result<usize, DecodeError> {
    // A frame that claims more than `out` holds is an error, never an allocation.
    let mut dec = zstd::bulk::Decompressor::new().map_err(|e| DecodeError::Zstd(e.to_string()))?;
    dec.decompress_to_buffer(stored, out)
        .map_err(|e| DecodeError::Zstd(e.to_string()))
}

/// Regroups bytes by their position within each 4-byte word.
pub fn shuffle4(raw: &[u8]) -> Vec<u8> {
    let words = raw.len() / 4;
    let mut out = vec![0u8; raw.len()];
    for (w, chunk) in raw.chunks_exact(4).enumerate() {
        for (b, &byte) in chunk.iter().enumerate() {
            out[b * words + w] = byte;
        }
    }
    out
}

fn unshuffle4_into(shuffled: &[u8], out: &mut [u8]) {
    let words = out.len() / 4;
    let planes: [&[u8]; 4] = std::array::from_fn(|b| &shuffled[b * words..(b + 1) * words]);
    for (w, chunk) in out.chunks_exact_mut(4).enumerate() {
        chunk.copy_from_slice(&[planes[0][w], planes[1][w], planes[2][w], planes[3][w]]);
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
