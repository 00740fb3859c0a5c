//! C Binary decoding: 80-byte strings, 4-byte integers and floats, either byte order.

use std::path::Path;

use crate::error::{Error, Location, Result, quote};

pub(crate) const STRING_LEN: usize = 80;

/// Byte order of a C Binary file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ByteOrder {
    Little,
    Big,
}

impl ByteOrder {
    pub fn native() -> Self {
        if cfg!(target_endian = "little") {
            ByteOrder::Little
        } else {
            ByteOrder::Big
        }
    }

    fn i32(self, b: [u8; 4]) -> i32 {
        match self {
            ByteOrder::Little => i32::from_le_bytes(b),
            ByteOrder::Big => i32::from_be_bytes(b),
        }
    }
}

/// A read position in a binary file that knows how to say where it is when something is wrong.
///
/// The byte order may start unknown: the first count read decides it by plausibility (a count
/// must fit in what is left of the file; a byte-swapped small count is enormous).
#[derive(Debug)]
pub(crate) struct BinCursor<'a> {
    path: &'a Path,
    data: &'a [u8],
    pos: usize,
    order: Option<ByteOrder>,
    /// Whether the byte order was guessed from a value that both orders read as plausible.
    ambiguous: bool,
}

impl<'a> BinCursor<'a> {
    pub fn new(path: &'a Path, data: &'a [u8], order: Option<ByteOrder>) -> Self {
        BinCursor {
            path,
            data,
            pos: 0,
            order,
            ambiguous: false,
        }
    }

    pub fn at(path: &'a Path, data: &'a [u8], pos: usize, order: Option<ByteOrder>) -> Self {
        BinCursor {
            path,
            data,
            pos,
            order,
            ambiguous: false,
        }
    }

    pub fn pos(&self) -> usize {
        self.pos
    }

    pub fn order(&self) -> Option<ByteOrder> {
        self.order
    }

    /// Whether the byte order was a guess between two plausible readings (the other order
    /// may be the file's: `reader::with_decoder` then tries it).
    pub fn order_was_ambiguous(&self) -> bool {
        self.ambiguous
    }

    fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    pub fn error(&self, expected: impl Into<String>, found: impl Into<String>) -> Error {
        Error::parse(self.path, Location::Byte(self.pos as u64), expected, found)
    }

    fn error_at(&self, pos: usize, expected: impl Into<String>, found: impl Into<String>) -> Error {
        Error::parse(self.path, Location::Byte(pos as u64), expected, found)
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if self.remaining() < n {
            return Err(self.error(
                format!("{what} ({n} bytes)"),
                format!("end of file after {} bytes", self.remaining()),
            ));
        }
        let slice = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(slice)
    }

    /// An 80-byte, NUL- or space-padded string.
    pub fn string(&mut self, what: &str) -> Result<String> {
        let raw = self.take(STRING_LEN, what)?;
        Ok(decode_string(raw))
    }

    /// The next 80-byte string without consuming it; `None` at end of file.
    pub fn peek_string(&self) -> Option<String> {
        self.data
            .get(self.pos..self.pos + STRING_LEN)
            .map(decode_string)
    }

    /// An 80-byte string that must start with `keyword`.
    pub fn keyword(&mut self, keyword: &str) -> Result<String> {
        let start = self.pos;
        let s = self.string(&format!("{keyword:?}"))?;
        if !s.trim_start().starts_with(keyword) {
            return Err(self.error_at(start, format!("{keyword:?}"), quote(s.as_bytes())));
        }
        Ok(s)
    }

    fn resolve_order(&mut self, raw: [u8; 4], per_unit: usize) -> ByteOrder {
        if let Some(order) = self.order {
            return order;
        }
        if raw == [0; 4] {
            // Zero reads the same either way: decide on a later value.
            return ByteOrder::Little;
        }
        let left = self.remaining() as i64;
        let plausible = |v: i32| v >= 0 && (v as i64) * (per_unit as i64) <= left;
        let le = i32::from_le_bytes(raw);
        let be = i32::from_be_bytes(raw);
        let order = match (plausible(le), plausible(be)) {
            (true, false) => ByteOrder::Little,
            (false, true) => ByteOrder::Big,
            // Both fit: usually the smaller is the true one (a swapped small number is huge),
            // but not always (4 000 000 swapped is 605 440), so the guess is marked.
            (true, true) => {
                self.ambiguous = true;
                if be < le {
                    ByteOrder::Big
                } else {
                    ByteOrder::Little
                }
            }
            _ => ByteOrder::Little,
        };
        self.order = Some(order);
        order
    }

    /// A signed 4-byte integer (part numbers, ids).
    pub fn int(&mut self, what: &str) -> Result<i32> {
        let raw: [u8; 4] = self
            .take(4, what)?
            .try_into()
            .map_err(|_| self.error(what, "short read"))?;
        let order = self.resolve_order(raw, 0);
        Ok(order.i32(raw))
    }

    /// A count of items that each take `bytes_per_item` bytes further on; must fit in the file.
    pub fn count(&mut self, what: &str, bytes_per_item: usize) -> Result<usize> {
        let start = self.pos;
        let raw: [u8; 4] = self
            .take(4, what)?
            .try_into()
            .map_err(|_| self.error(what, "short read"))?;
        let order = self.resolve_order(raw, bytes_per_item);
        let v = order.i32(raw);
        if v < 0 {
            return Err(self.error_at(start, format!("{what} (a count ≥ 0)"), v.to_string()));
        }
        let need = (v as u64) * (bytes_per_item as u64);
        if need > self.remaining() as u64 {
            return Err(self.error_at(
                start,
                format!("{what}: {v} items need {need} more bytes"),
                format!("{} bytes left in the file", self.remaining()),
            ));
        }
        Ok(v as usize)
    }

    /// Raw bytes of `n` 4-byte values, decoded later with [`decode_i32`]/[`decode_f32_into`].
    pub fn words(&mut self, n: usize, what: &str) -> Result<Words<'a>> {
        let start = self.pos;
        let bytes = n
            .checked_mul(4)
            .ok_or_else(|| self.error(what, "a count that overflows"))?;
        let raw = self.take(bytes, what)?;
        Ok(Words {
            raw,
            start,
            order: self.order.unwrap_or(ByteOrder::Little),
        })
    }

    pub fn path(&self) -> &'a Path {
        self.path
    }
}

/// `n` consecutive 4-byte values at a known file offset.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Words<'a> {
    pub raw: &'a [u8],
    pub start: usize,
    pub order: ByteOrder,
}

impl Words<'_> {
    pub fn offset_of(&self, i: usize) -> u64 {
        (self.start + 4 * i) as u64
    }

    pub fn i32(&self, i: usize) -> i32 {
        let b = [
            self.raw[4 * i],
            self.raw[4 * i + 1],
            self.raw[4 * i + 2],
            self.raw[4 * i + 3],
        ];
        self.order.i32(b)
    }

    /// Appends every value as f32: one bulk copy, plus a byte swap for foreign byte order.
    pub fn extend_f32(&self, out: &mut Vec<f32>) {
        copy_words(self.raw, self.order, out);
    }

    /// Appends consecutive triples (x, y, z interleaved) as vectors.
    pub fn extend_vec3(&self, out: &mut Vec<[f32; 3]>) {
        copy_words(self.raw, self.order, out);
    }

    /// Appends every value as an unsigned 32-bit integer (raw bits of the file's i32).
    pub fn extend_u32(&self, out: &mut Vec<u32>) {
        copy_words(self.raw, self.order, out);
    }
}

/// Copies whole 4-byte words into `out` (a Pod type made of them) and fixes their byte order:
/// memcpy speed, no per-value work in the native order.
fn copy_words<T: bytemuck::Pod + bytemuck::Zeroable>(
    raw: &[u8],
    order: ByteOrder,
    out: &mut Vec<T>,
) {
    let item = size_of::<T>();
    debug_assert!(item.is_multiple_of(4));
    let n = raw.len() / item;
    let start = out.len();
    out.reserve(n);
    // SAFETY: `reserve` made room for n more items; exactly n * size_of::<T>() bytes are
    // copied into that room, and any bit pattern is a valid `T` (Pod), so the first n spare
    // items are initialised before `set_len` exposes them. Skipping the zero fill that a safe
    // `resize` would do saves a full pass over the step's largest arrays.
    unsafe {
        std::ptr::copy_nonoverlapping(
            raw.as_ptr(),
            out.as_mut_ptr().add(start).cast::<u8>(),
            n * item,
        );
        out.set_len(start + n);
    }
    let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out[start..]);
    if order != ByteOrder::native() {
        let words: &mut [u32] = match bytemuck::try_cast_slice_mut(dst) {
            Ok(w) => w,
            Err(_) => return swap_unaligned(dst),
        };
        for w in words {
            *w = w.swap_bytes();
        }
    }
}

/// Index of the first NaN or Inf; a branch-free scan by blocks, exact search only on a hit.
pub(crate) fn first_non_finite(values: &[f32]) -> Option<usize> {
    const EXP: u32 = 0x7f80_0000;
    const BLOCK: usize = 1024;
    for (b, block) in values.chunks(BLOCK).enumerate() {
        // Masked exponents are ≤ EXP; their maximum reaches EXP only for NaN or Inf.
        let worst = block.iter().map(|v| v.to_bits() & EXP).fold(0, u32::max);
        if worst == EXP {
            return block
                .iter()
                .position(|v| !v.is_finite())
                .map(|i| b * BLOCK + i);
        }
    }
    None
}

fn swap_unaligned(bytes: &mut [u8]) {
    for w in bytes.chunks_exact_mut(4) {
        w.reverse();
    }
}

fn decode_string(raw: &[u8]) -> String {
    let end = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
    String::from_utf8_lossy(&raw[..end]).trim_end().to_string()
}

/// How a file stores its values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    Ascii,
    CBinary,
}

/// Looks at the first bytes: "C Binary" is binary, "Fortran Binary" (bare or inside a record
/// marker) is refused, anything else is ASCII.
pub(crate) fn sniff(path: &Path, data: &[u8]) -> Result<Encoding> {
    let head = &data[..data.len().min(STRING_LEN)];
    let text = String::from_utf8_lossy(head);
    let trimmed = text.trim_start();
    if trimmed.starts_with("C Binary") {
        return Ok(Encoding::CBinary);
    }
    let fortran_marker = data.get(4..18) == Some(b"Fortran Binary".as_slice());
    if trimmed.starts_with("Fortran Binary") || fortran_marker {
        return Err(Error::unsupported(
            path,
            "Fortran Binary EnSight (record-marked); re-export it as C Binary",
        ));
    }
    Ok(Encoding::Ascii)
}
