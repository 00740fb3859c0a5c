//! Positions a decoder at the start of a file's content: past `C Binary`, and in single-file
//! transient data, past the chosen step's `BEGIN TIME STEP`.

use std::path::Path;

use crate::ascii::AsciiCursor;
use crate::binary::{BinCursor, ByteOrder, Encoding, STRING_LEN};
use crate::case::Format;
use crate::decoder::{Ascii, Decoder};
use crate::error::{Error, Location, Result, quote};

const BEGIN: &[u8] = b"BEGIN TIME STEP";

/// Runs `f` on a decoder over `data`. `header` says the file starts with a `C Binary` record
/// when binary (geometry and measured files do, variable files do not). Where the byte order
/// is not given and the first count read plausibly either way, a failure is retried in the
/// other order; the first error is reported where both fail.
#[allow(clippy::too_many_arguments)]
pub(crate) fn with_decoder<T>(
    path: &Path,
    data: &[u8],
    format: Format,
    encoding: Encoding,
    header: bool,
    block: Option<usize>,
    order: Option<ByteOrder>,
    mut f: impl FnMut(&mut dyn Decoder) -> Result<T>,
) -> Result<T> {
    match encoding {
        Encoding::Ascii => {
            let (pos, line) = match block {
                Some(b) => ascii_block_start(path, data, b)?,
                None => (0, 0),
            };
            let cursor = AsciiCursor::at(path, data, pos, line);
            let int_width = if format == Format::Gold { 10 } else { 8 };
            let mut d = Ascii { cursor, int_width };
            f(&mut d)
        }
        Encoding::CBinary => {
            let mut start = 0;
            if header {
                let mut c = BinCursor::new(path, data, order);
                c.keyword("C Binary")?;
                start = c.pos();
            }
            if let Some(b) = block {
                start = binary_block_start(path, data, start, b)?;
            }
            let mut d = BinCursor::at(path, data, start, order);
            let first = f(&mut d);
            match (first, d.order()) {
                (Err(e), Some(guessed)) if d.order_was_ambiguous() => {
                    let other = match guessed {
                        ByteOrder::Little => ByteOrder::Big,
                        ByteOrder::Big => ByteOrder::Little,
                    };
                    f(&mut BinCursor::at(path, data, start, Some(other))).map_err(|_| e)
                }
                (result, _) => result,
            }
        }
    }
}

fn ascii_block_start(path: &Path, data: &[u8], block: usize) -> Result<(usize, usize)> {
    let mut found = 0;
    let mut pos = 0;
    let mut line = 0;
    while pos < data.len() {
        let end = memchr::memchr(b'\n', &data[pos..]).map_or(data.len(), |e| pos + e);
        line += 1;
        let text = data[pos..end].trim_ascii();
        pos = (end + 1).min(data.len());
        if text.eq_ignore_ascii_case(BEGIN) {
            if found == block {
                return Ok((pos, line));
            }
            found += 1;
        }
    }
    Err(Error::parse(
        path,
        Location::File,
        format!("BEGIN TIME STEP number {}", block + 1),
        format!("{found} of them"),
    ))
}

fn binary_block_start(path: &Path, data: &[u8], from: usize, block: usize) -> Result<usize> {
    let mut found = 0;
    for at in memchr::memmem::find_iter(&data[from..], BEGIN) {
        let at = from + at;
        if found == block {
            if at + STRING_LEN > data.len() {
                return Err(Error::parse(
                    path,
                    Location::Byte(at as u64),
                    "an 80-byte BEGIN TIME STEP record",
                    quote(&data[at..]),
                ));
            }
            return Ok(at + STRING_LEN);
        }
        found += 1;
    }
    Err(Error::parse(
        path,
        Location::File,
        format!("BEGIN TIME STEP number {}", block + 1),
        format!("{found} of them"),
    ))
}
