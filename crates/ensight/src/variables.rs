//! Measured (particle) geometry and per-node / per-measured-node variable files.

use std::ops::Range;

use serde::Serialize;

use crate::binary::{ByteOrder, Encoding};
use crate::decoder::Decoder;
use crate::error::{Error, Result, quote};

/// A measured-particle file: positions in file order.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Measured {
    pub encoding: Encoding,
    pub byte_order: Option<ByteOrder>,
    #[serde(skip)]
    pub positions: Vec<[f32; 3]>,
}

pub(crate) fn read_measured(
    d: &mut dyn Decoder,
    encoding: Encoding,
    finite: bool,
) -> Result<Measured> {
    d.text("description line")?;
    let kw = d.keyword("\"particle coordinates\"")?;
    if !kw.starts_with("particle coordinates") {
        return Err(d.error("\"particle coordinates\"", &quote(kw.as_bytes())));
    }
    let np = d.count("number of particles", 16)?;
    let mut positions = Vec::with_capacity(np);
    if d.is_ascii() {
        // One particle per line: id x y z.
        let mut xyz = Vec::with_capacity(3);
        for _ in 0..np {
            d.int("particle id")?;
            xyz.clear();
            d.floats(3, &mut xyz, "particle coordinates", finite)?;
            positions.push([xyz[0], xyz[1], xyz[2]]);
        }
    } else {
        // Ids as one array, then coordinates interleaved per particle (what EnSight writes,
        // whatever older manuals say).
        d.skip_ints(np, "particle ids")?;
        d.vec3s(np, &mut positions, "particle coordinates", finite)?;
    }
    Ok(Measured {
        encoding,
        byte_order: d.byte_order(),
        positions,
    })
}

/// How a variable file's values map onto the nodes they belong to.
#[derive(Debug, Clone, Copy)]
pub(crate) enum VarLayout<'a> {
    /// One list for all nodes, components interleaved (EnSight 6 per node, any measured).
    Global(usize),
    /// Gold per node: per part, one block per component. `(part number, node range)`.
    Parts(&'a [(i64, Range<usize>)]),
}

/// Reads a per-node or per-measured-node variable into `out`: `components` floats per node,
/// interleaved, over all nodes of the layout. Nodes a Gold file leaves out (or marks
/// undefined) are NaN.
pub(crate) fn read_node_variable(
    d: &mut dyn Decoder,
    components: usize,
    layout: VarLayout<'_>,
    out: &mut Vec<f32>,
) -> Result<()> {
    d.text("description line")?;
    match layout {
        VarLayout::Global(n) => {
            let len = n
                .checked_mul(components)
                .ok_or_else(|| d.error("a node count", "one that overflows"))?;
            out.clear();
            d.floats(len, out, "variable values", false)
        }
        VarLayout::Parts(parts) => {
            let total = parts.iter().map(|(_, r)| r.end).max().unwrap_or(0);
            out.clear();
            out.resize(total * components, f32::NAN);
            let mut block = Vec::new();
            while let Some(kw) = d.peek_keyword() {
                if kw.starts_with("end time step") {
                    break;
                }
                let line = d.keyword("\"part\"")?;
                if !line.starts_with("part") {
                    return Err(d.error("\"part\"", &quote(line.as_bytes())));
                }
                let number = d.int("part number")?;
                let range = parts
                    .iter()
                    .find(|(n, _)| *n == number)
                    .map(|(_, r)| r.clone())
                    .ok_or_else(|| d.error("a part number of the geometry", &number.to_string()))?;
                let nodes = range.len();
                if nodes == 0
                    && !d
                        .peek_keyword()
                        .is_some_and(|k| k.starts_with("coordinates"))
                {
                    continue;
                }
                let kw = d.keyword("\"coordinates\"")?;
                let undef = match kw.as_str() {
                    "coordinates" => None,
                    "coordinates undef" => {
                        let mut v = Vec::with_capacity(1);
                        d.floats(1, &mut v, "undefined value marker", false)?;
                        Some(v[0])
                    }
                    k if k.starts_with("coordinates partial") => {
                        return Err(Error::unsupported(
                            d.path(),
                            "partial per-node values (\"coordinates partial\")",
                        ));
                    }
                    k if k.starts_with("block") => {
                        return Err(Error::unsupported(
                            d.path(),
                            format!("structured part values ({k:?})"),
                        ));
                    }
                    _ => return Err(d.error("\"coordinates\"", &quote(kw.as_bytes()))),
                };
                for c in 0..components {
                    block.clear();
                    d.floats(nodes, &mut block, "variable values", false)?;
                    for (i, &v) in block.iter().enumerate() {
                        let v = if Some(v) == undef { f32::NAN } else { v };
                        out[(range.start + i) * components + c] = v;
                    }
                }
            }
            Ok(())
        }
    }
}
