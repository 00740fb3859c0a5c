//! ASCII decoding: lines with numbers, fixed width (`%8d%12.5e…`) or whitespace separated.

use std::path::Path;

use crate::error::{Error, Location, Result, quote};

/// A read position in an ASCII file, by line, that can also stream numbers across lines.
///
/// Numbers in EnSight ASCII files are written with fixed widths, so neighbours can touch:
/// `-1.00000e+00-2.00000e+00`. Floats are split where a sign follows a digit; integers in a
/// line with a token wider than the field width are cut at the column boundaries.
#[derive(Debug)]
pub(crate) struct AsciiCursor<'a> {
    path: &'a Path,
    data: &'a [u8],
    /// Start of the next unread line.
    next: usize,
    /// Number (1-based) of the line `rest` belongs to.
    line_no: usize,
    /// Unconsumed part of the current line when numbers are being streamed.
    rest: &'a [u8],
    /// Set when the current line holds integers packed at fixed column width.
    columns: Option<usize>,
    /// True until the first value of the current line is taken (column mode is decided there).
    fresh: bool,
}

impl<'a> AsciiCursor<'a> {
    /// Starts at byte `pos`, which is the beginning of line `line_no + 1`.
    pub fn at(path: &'a Path, data: &'a [u8], pos: usize, line_no: usize) -> Self {
        AsciiCursor {
            path,
            data,
            next: pos,
            line_no,
            rest: &[],
            columns: None,
            fresh: false,
        }
    }

    pub fn path(&self) -> &'a Path {
        self.path
    }

    pub fn error(&self, expected: impl Into<String>, found: impl Into<String>) -> Error {
        Error::parse(
            self.path,
            Location::Line(self.line_no.max(1)),
            expected,
            found,
        )
    }

    fn raw_line(&mut self) -> Option<&'a [u8]> {
        if self.next >= self.data.len() {
            return None;
        }
        let tail = &self.data[self.next..];
        let len = memchr::memchr(b'\n', tail).unwrap_or(tail.len());
        let mut line = &tail[..len];
        self.next += (len + 1).min(tail.len());
        self.line_no += 1;
        if let [head @ .., b'\r'] = line {
            line = head;
        }
        Some(line)
    }

    fn ensure_line_finished(&mut self) -> Result<()> {
        if !is_blank(self.rest) {
            return Err(self.error("end of line", format!("extra text {}", quote(self.rest))));
        }
        self.rest = &[];
        self.columns = None;
        Ok(())
    }

    /// The next whole line, as text (descriptions, keywords).
    pub fn line(&mut self, what: &str) -> Result<&'a str> {
        self.ensure_line_finished()?;
        let line = self
            .raw_line()
            .ok_or_else(|| self.error(what, "end of file"))?;
        std::str::from_utf8(line).map_err(|_| self.error(what, "bytes that are not text"))
    }

    /// The next non-blank line, without consuming it.
    pub fn peek_nonblank(&self) -> Option<&'a str> {
        let mut probe = AsciiCursor::at(self.path, self.data, self.next, self.line_no);
        loop {
            let line = probe.raw_line()?;
            if !is_blank(line) {
                return std::str::from_utf8(line).ok();
            }
        }
    }

    pub fn nonblank_line(&mut self, what: &str) -> Result<&'a str> {
        loop {
            let line = self.line(what)?;
            if !line.trim().is_empty() {
                return Ok(line);
            }
        }
    }

    fn refill(&mut self, what: &str) -> Result<()> {
        while is_blank(self.rest) {
            self.columns = None;
            self.fresh = true;
            self.rest = self
                .raw_line()
                .ok_or_else(|| self.error(what.to_string(), "end of file"))?;
        }
        Ok(())
    }

    fn float_token(&mut self, what: &str) -> Result<&'a [u8]> {
        self.refill(what)?;
        self.fresh = false;
        let rest = trim_start(self.rest);
        let mut end = 1;
        while end < rest.len() {
            let b = rest[end];
            if b.is_ascii_whitespace() {
                break;
            }
            if (b == b'-' || b == b'+') && (rest[end - 1].is_ascii_digit() || rest[end - 1] == b'.')
            {
                break;
            }
            end += 1;
        }
        self.rest = &rest[end..];
        Ok(&rest[..end])
    }

    /// One float, possibly run together with its neighbours; `finite` refuses NaN and Inf.
    pub fn float(&mut self, what: &str, finite: bool) -> Result<f32> {
        let token = self.float_token(what)?;
        match parse_f32(token) {
            Some(v) if v.is_finite() || !finite => Ok(v),
            Some(_) => Err(self.error(format!("a finite number ({what})"), quote(token))),
            None => Err(self.error(format!("a number ({what})"), quote(token))),
        }
    }

    /// `n` floats streamed across lines, appended to `out`.
    pub fn floats(&mut self, n: usize, out: &mut Vec<f32>, what: &str, finite: bool) -> Result<()> {
        out.reserve(n.min(self.bytes_left() / 2));
        for _ in 0..n {
            let v = self.float(what, finite)?;
            out.push(v);
        }
        Ok(())
    }

    /// One integer written with field width `width` (8 in EnSight 6, 10 in Gold).
    pub fn int(&mut self, width: usize, what: &str) -> Result<i64> {
        self.refill(what)?;
        if self.fresh && needs_columns(self.rest, width) {
            self.columns = Some(width);
        }
        self.fresh = false;
        let token = match self.columns {
            Some(w) => {
                let take = w.min(self.rest.len());
                let (head, tail) = self.rest.split_at(take);
                self.rest = tail;
                trim(head)
            }
            None => {
                let rest = trim_start(self.rest);
                let mut end = 1.min(rest.len());
                while end < rest.len()
                    && !rest[end].is_ascii_whitespace()
                    && !(matches!(rest[end], b'-' | b'+') && rest[end - 1].is_ascii_digit())
                {
                    end += 1;
                }
                self.rest = &rest[end..];
                &rest[..end]
            }
        };
        parse_i64(token).ok_or_else(|| self.error(format!("an integer ({what})"), quote(token)))
    }

    /// `n` integers streamed across lines.
    pub fn ints(&mut self, n: usize, width: usize, out: &mut Vec<i64>, what: &str) -> Result<()> {
        out.reserve(n.min(self.bytes_left() / 2));
        for _ in 0..n {
            let v = self.int(width, what)?;
            out.push(v);
        }
        Ok(())
    }

    /// A count (≥ 0) written as an integer line.
    /// Unread bytes: an upper bound on what any request can still consume.
    fn bytes_left(&self) -> usize {
        self.rest.len() + self.data.len().saturating_sub(self.next)
    }

    /// A count (≥ 0) of items that each hold `values_per_item` numbers further on. Every
    /// number takes at least two bytes (a digit and a separator), so a count the rest of the
    /// file cannot hold is refused before anything is allocated for it.
    /// A count stands alone on its line, so a token wider than the field is read whole: cutting
    /// it at the column would report a value the file does not hold.
    pub fn count(&mut self, width: usize, values_per_item: usize, what: &str) -> Result<usize> {
        self.refill(what)?;
        let alone = self.fresh && trim(self.rest).split(u8::is_ascii_whitespace).count() == 1;
        let v = if alone {
            let token = trim(self.rest);
            self.rest = &[];
            self.fresh = false;
            parse_i64(token)
                .ok_or_else(|| self.error(format!("{what} (a count ≥ 0)"), quote(token)))?
        } else {
            self.int(width, what)?
        };
        let n = usize::try_from(v)
            .map_err(|_| self.error(format!("{what} (a count ≥ 0)"), v.to_string()))?;
        let left = self.bytes_left();
        if n.saturating_mul(values_per_item).saturating_mul(2) > left {
            return Err(self.error(
                format!("{what}: {n} items need more than the {left} bytes left in the file"),
                v.to_string(),
            ));
        }
        Ok(n)
    }
}

/// Whether a line of integers must be cut into columns because neighbours touch.
fn needs_columns(line: &[u8], width: usize) -> bool {
    line.split(u8::is_ascii_whitespace).any(|t| {
        t.len() > width
            && t.iter()
                .all(|&b| b.is_ascii_digit() || b == b'-' || b == b'+')
    })
}

fn is_blank(s: &[u8]) -> bool {
    s.iter().all(u8::is_ascii_whitespace)
}

fn trim_start(s: &[u8]) -> &[u8] {
    let start = s
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(s.len());
    &s[start..]
}

fn trim(s: &[u8]) -> &[u8] {
    let s = trim_start(s);
    let end = s
        .iter()
        .rposition(|b| !b.is_ascii_whitespace())
        .map_or(0, |e| e + 1);
    &s[..end]
}

/// What C's printf writes: decimal and exponent forms, `nan`, `inf`. Fortran `D` exponents fail.
fn parse_f32(token: &[u8]) -> Option<f32> {
    std::str::from_utf8(token).ok()?.parse::<f32>().ok()
}

fn parse_i64(token: &[u8]) -> Option<i64> {
    let (neg, digits) = match token {
        [b'-', rest @ ..] => (true, rest),
        [b'+', rest @ ..] => (false, rest),
        _ => (false, token),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut v: i64 = 0;
    for &b in digits {
        if !b.is_ascii_digit() {
            return None;
        }
        v = v * 10 + i64::from(b - b'0');
    }
    Some(if neg { -v } else { v })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_that_touch_are_split_at_signs() {
        let data = b"-1.00000e+00-2.50000e-01 3.00000e+02\n";
        let mut c = AsciiCursor::at(Path::new("t"), data, 0, 0);
        let mut out = Vec::new();
        c.floats(3, &mut out, "x", true).unwrap();
        assert_eq!(out, vec![-1.0, -0.25, 300.0]);
    }

    #[test]
    fn packed_integers_are_cut_at_columns() {
        let data = b"       1123456781234567\n";
        let mut c = AsciiCursor::at(Path::new("t"), data, 0, 0);
        let mut out = Vec::new();
        c.ints(3, 8, &mut out, "n").unwrap();
        assert_eq!(out, vec![1, 12345678, 1234567]);
    }

    #[test]
    fn an_over_long_count_is_reported_whole() {
        let data = b"123456789012345678901\n";
        let mut c = AsciiCursor::at(Path::new("g.geo"), data, 0, 0);
        let e = c.count(10, 12, "number of nodes").unwrap_err().to_string();
        assert!(e.contains("123456789012345678901"), "{e}");
        let data = b"  123456789012\n";
        let mut c = AsciiCursor::at(Path::new("g.geo"), data, 0, 0);
        let e = c.count(8, 12, "number of nodes").unwrap_err().to_string();
        assert!(e.contains("123456789012 items"), "{e}");
        let data = b"      42\n";
        let mut c = AsciiCursor::at(Path::new("g.geo"), data, 0, 0);
        assert_eq!(c.count(8, 0, "n").unwrap(), 42);
    }

    #[test]
    fn fortran_exponent_is_an_error_with_a_line() {
        let data = b"1.0\n1.0D+00\n";
        let mut c = AsciiCursor::at(Path::new("f.geo"), data, 0, 0);
        let mut out = Vec::new();
        let e = c.floats(2, &mut out, "x", true).unwrap_err().to_string();
        assert!(e.contains("f.geo: line 2"), "{e}");
    }
}
