//! EnSight 6 and EnSight Gold: case files, geometry, measured particles and per-node
//! variables, in ASCII and C Binary of either byte order; reading and writing.
//!
//! Open a case once with [`Case::open`], then read any step with [`Case::read_step`]:
//! binary files are memory-mapped and decoded straight into the output arrays.

mod ascii;
mod binary;
mod case;
mod dataset;
mod decoder;
pub mod elements;
mod error;
mod geometry;
pub mod info;
mod reader;
mod source;
mod variables;
mod writer;

pub use binary::{ByteOrder, Encoding};
pub use case::{
    CaseFile, FileRef, FileSet, FileSetChunk, Format, StepFile, TimeSet, VarLocation, VarType,
    Variable, expand_wildcards,
};
pub use dataset::{Case, Field, FieldValues, PointSource, Step, StepRequest};
pub use error::{Error, Location, Result};
pub use geometry::{ElementBlock, Geometry, IdMode, Part};
pub use source::FileBytes;
pub use variables::Measured;
pub use writer::{CaseWriter, Placement, VarData, WriteFormat, atomic_write};

/// Entry points for fuzzing: parse bytes as each kind of file, never panicking.
pub mod fuzzing {
    use std::path::Path;

    use crate::case::{CaseFile, Format};

    pub fn case(data: &[u8]) {
        if let Ok(text) = std::str::from_utf8(data) {
            let _ = CaseFile::parse(Path::new("fuzz.case"), text);
        }
    }

    pub fn geometry(data: &[u8]) {
        for format in [Format::Ensight6, Format::Gold] {
            for block in [None, Some(0)] {
                let _ = crate::geometry::parse_geometry_bytes(
                    Path::new("fuzz.geo"),
                    data,
                    format,
                    block,
                    None,
                    true,
                );
            }
        }
    }

    pub fn measured(data: &[u8]) {
        let path = Path::new("fuzz.mgeo");
        if let Ok(encoding) = crate::binary::sniff(path, data) {
            let _ = crate::reader::with_decoder(
                path,
                data,
                Format::Ensight6,
                encoding,
                true,
                None,
                None,
                |d| crate::variables::read_measured(d, encoding, true),
            );
        }
    }
}
