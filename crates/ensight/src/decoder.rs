//! One interface over ASCII and C Binary files, so each format's grammar is written once.

use std::path::Path;

use crate::ascii::AsciiCursor;
use crate::binary::{BinCursor, ByteOrder, Words, first_non_finite};
use crate::error::{Error, Location, Result};

/// Reads the pieces EnSight files are made of, whatever their encoding.
pub(crate) trait Decoder {
    fn is_ascii(&self) -> bool;
    fn path(&self) -> &Path;
    /// A string record: an 80-byte string, or an ASCII line (which may be blank).
    fn text(&mut self, what: &str) -> Result<String>;
    /// The next keyword record (blank ASCII lines skipped), lowercased and trimmed.
    fn keyword(&mut self, what: &str) -> Result<String>;
    /// The next keyword record without consuming it; `None` at the end of the data.
    fn peek_keyword(&self) -> Option<String>;
    fn int(&mut self, what: &str) -> Result<i64>;
    /// A count whose items take `bytes_per_item` bytes each in a binary file (checked against
    /// what is left of it).
    fn count(&mut self, what: &str, bytes_per_item: usize) -> Result<usize>;
    fn ints(&mut self, n: usize, out: &mut Vec<i64>, what: &str) -> Result<()>;
    fn skip_ints(&mut self, n: usize, what: &str) -> Result<()>;
    /// Binary only: `n` integers as raw u32 bits in bulk; returns the array's byte offset.
    fn u32s(&mut self, n: usize, out: &mut Vec<u32>, what: &str) -> Result<usize>;
    /// Floats appended to `out`; `finite` refuses NaN and Inf with the value's location.
    fn floats(&mut self, n: usize, out: &mut Vec<f32>, what: &str, finite: bool) -> Result<()>;
    /// `n` interleaved (x, y, z) triples appended to `out`.
    fn vec3s(&mut self, n: usize, out: &mut Vec<[f32; 3]>, what: &str, finite: bool) -> Result<()>;
    fn error(&self, expected: &str, found: &str) -> Error;
    fn byte_order(&self) -> Option<ByteOrder>;
}

/// ASCII flavour: the integer field width differs between EnSight 6 (8) and Gold (10).
#[derive(Debug)]
pub(crate) struct Ascii<'a> {
    pub cursor: AsciiCursor<'a>,
    pub int_width: usize,
}

impl Decoder for Ascii<'_> {
    fn is_ascii(&self) -> bool {
        true
    }
    fn path(&self) -> &Path {
        self.cursor.path()
    }
    fn text(&mut self, what: &str) -> Result<String> {
        Ok(self.cursor.line(what)?.trim().to_string())
    }
    fn keyword(&mut self, what: &str) -> Result<String> {
        Ok(self.cursor.nonblank_line(what)?.trim().to_ascii_lowercase())
    }
    fn peek_keyword(&self) -> Option<String> {
        self.cursor
            .peek_nonblank()
            .map(|l| l.trim().to_ascii_lowercase())
    }
    fn int(&mut self, what: &str) -> Result<i64> {
        self.cursor.int(self.int_width, what)
    }
    fn count(&mut self, what: &str, bytes_per_item: usize) -> Result<usize> {
        // Binary sizes are 4 bytes per value; ASCII holds the same number of values.
        self.cursor.count(self.int_width, bytes_per_item / 4, what)
    }
    fn ints(&mut self, n: usize, out: &mut Vec<i64>, what: &str) -> Result<()> {
        self.cursor.ints(n, self.int_width, out, what)
    }
    fn skip_ints(&mut self, n: usize, what: &str) -> Result<()> {
        for _ in 0..n {
            self.cursor.int(self.int_width, what)?;
        }
        Ok(())
    }
    fn u32s(&mut self, n: usize, out: &mut Vec<u32>, what: &str) -> Result<usize> {
        for _ in 0..n {
            let v = self.cursor.int(self.int_width, what)?;
            out.push(u32::try_from(v).unwrap_or(u32::MAX));
        }
        Ok(0)
    }
    fn floats(&mut self, n: usize, out: &mut Vec<f32>, what: &str, finite: bool) -> Result<()> {
        self.cursor.floats(n, out, what, finite)
    }
    fn vec3s(&mut self, n: usize, out: &mut Vec<[f32; 3]>, what: &str, finite: bool) -> Result<()> {
        for _ in 0..n {
            let x = self.cursor.float(what, finite)?;
            let y = self.cursor.float(what, finite)?;
            let z = self.cursor.float(what, finite)?;
            out.push([x, y, z]);
        }
        Ok(())
    }
    fn error(&self, expected: &str, found: &str) -> Error {
        self.cursor.error(expected, found)
    }
    fn byte_order(&self) -> Option<ByteOrder> {
        None
    }
}

impl Decoder for BinCursor<'_> {
    fn is_ascii(&self) -> bool {
        false
    }
    fn path(&self) -> &Path {
        BinCursor::path(self)
    }
    fn text(&mut self, what: &str) -> Result<String> {
        Ok(self.string(what)?.trim().to_string())
    }
    fn keyword(&mut self, what: &str) -> Result<String> {
        Ok(self.string(what)?.trim().to_ascii_lowercase())
    }
    fn peek_keyword(&self) -> Option<String> {
        self.peek_string().map(|s| s.trim().to_ascii_lowercase())
    }
    fn int(&mut self, what: &str) -> Result<i64> {
        BinCursor::int(self, what).map(i64::from)
    }
    fn count(&mut self, what: &str, bytes_per_item: usize) -> Result<usize> {
        BinCursor::count(self, what, bytes_per_item)
    }
    fn ints(&mut self, n: usize, out: &mut Vec<i64>, what: &str) -> Result<()> {
        let words = self.words(n, what)?;
        out.reserve(n);
        out.extend((0..n).map(|i| i64::from(words.i32(i))));
        Ok(())
    }
    fn skip_ints(&mut self, n: usize, what: &str) -> Result<()> {
        self.words(n, what).map(|_| ())
    }
    fn u32s(&mut self, n: usize, out: &mut Vec<u32>, what: &str) -> Result<usize> {
        let words = self.words(n, what)?;
        words.extend_u32(out);
        Ok(words.start)
    }
    fn floats(&mut self, n: usize, out: &mut Vec<f32>, what: &str, finite: bool) -> Result<()> {
        let words = self.words(n, what)?;
        let start = out.len();
        words.extend_f32(out);
        if finite {
            require_finite(BinCursor::path(self), &words, &out[start..], what)?;
        }
        Ok(())
    }
    fn vec3s(&mut self, n: usize, out: &mut Vec<[f32; 3]>, what: &str, finite: bool) -> Result<()> {
        let len = n
            .checked_mul(3)
            .ok_or_else(|| BinCursor::error(self, what, "a count that overflows"))?;
        let words = self.words(len, what)?;
        let start = out.len();
        words.extend_vec3(out);
        if finite {
            require_finite(
                BinCursor::path(self),
                &words,
                bytemuck::cast_slice(&out[start..]),
                what,
            )?;
        }
        Ok(())
    }
    fn error(&self, expected: &str, found: &str) -> Error {
        BinCursor::error(self, expected, found)
    }
    fn byte_order(&self) -> Option<ByteOrder> {
        self.order()
    }
}

/// Fails at the byte offset of the first NaN or Inf among `values`, decoded from `words`.
fn require_finite(path: &Path, words: &Words<'_>, values: &[f32], what: &str) -> Result<()> {
    match first_non_finite(values) {
        Some(k) => Err(Error::parse(
            path,
            Location::Byte(words.offset_of(k)),
            format!("a finite number ({what})"),
            values[k].to_string(),
        )),
        None => Ok(()),
    }
}
