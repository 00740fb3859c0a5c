//! Geometry files (EnSight 6 and Gold): nodes, parts, and the `point` elements that are particles.

use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;

use serde::Serialize;

use crate::binary::{ByteOrder, Encoding};
use crate::case::Format;
use crate::decoder::Decoder;
use crate::elements::{is_element_keyword, nodes_per_element};
use crate::error::{Error, Location, Result, quote};

/// How a geometry file lists node or element ids.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum IdMode {
    Off,
    Given,
    Assign,
    Ignore,
}

impl IdMode {
    /// Whether ids are written in the file.
    pub fn listed(self) -> bool {
        matches!(self, IdMode::Given | IdMode::Ignore)
    }

    fn parse(line: &str) -> Option<IdMode> {
        Some(match line.split_whitespace().last()? {
            "off" => IdMode::Off,
            "given" => IdMode::Given,
            "assign" => IdMode::Assign,
            "ignore" => IdMode::Ignore,
            _ => return None,
        })
    }
}

/// A run of elements of one type in a part.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ElementBlock {
    pub kind: String,
    pub count: usize,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Part {
    pub number: i64,
    pub description: String,
    /// This part's nodes in [`Geometry::nodes`]: its own in Gold, all of them in EnSight 6
    /// (where parts share one coordinate list).
    pub nodes: Range<usize>,
    pub blocks: Vec<ElementBlock>,
    /// Indices into [`Geometry::nodes`] of the nodes that `point` elements reference.
    #[serde(skip)]
    pub point_nodes: Vec<u32>,
}

/// A geometry file as read: every node, and per part what it holds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Geometry {
    pub encoding: Encoding,
    pub byte_order: Option<ByteOrder>,
    pub node_ids: IdMode,
    pub element_ids: IdMode,
    #[serde(skip)]
    pub nodes: Vec<[f32; 3]>,
    pub parts: Vec<Part>,
}

fn id_mode(d: &mut dyn Decoder, what: &str) -> Result<IdMode> {
    let line = d.keyword(what)?;
    if !line.starts_with(what) {
        return Err(d.error(
            &format!("\"{what} <off|given|assign|ignore>\""),
            &quote(line.as_bytes()),
        ));
    }
    IdMode::parse(&line).ok_or_else(|| {
        d.error(
            &format!("\"{what} <off|given|assign|ignore>\""),
            &quote(line.as_bytes()),
        )
    })
}

fn expect_keyword(d: &mut dyn Decoder, keyword: &str) -> Result<String> {
    let line = d.keyword(keyword)?;
    if !line.starts_with(keyword) {
        return Err(d.error(&format!("{keyword:?}"), &quote(line.as_bytes())));
    }
    Ok(line)
}

/// Reads a geometry file's content from the current position (after `C Binary` and any
/// `BEGIN TIME STEP`) to its end or to `END TIME STEP`.
pub(crate) fn read_geometry(
    d: &mut dyn Decoder,
    format: Format,
    encoding: Encoding,
    finite: bool,
) -> Result<Geometry> {
    d.text("description line 1")?;
    d.text("description line 2")?;
    let node_ids = id_mode(d, "node id")?;
    let element_ids = id_mode(d, "element id")?;
    let mut geometry = Geometry {
        encoding,
        byte_order: None,
        node_ids,
        element_ids,
        nodes: Vec::new(),
        parts: Vec::new(),
    };
    match format {
        Format::Ensight6 => read_e6_body(d, &mut geometry, finite)?,
        Format::Gold => read_gold_body(d, &mut geometry, finite)?,
    }
    geometry.byte_order = d.byte_order();
    Ok(geometry)
}

fn read_e6_body(d: &mut dyn Decoder, g: &mut Geometry, finite: bool) -> Result<()> {
    expect_keyword(d, "coordinates")?;
    let ids = g.node_ids.listed();
    let nn = d.count("number of nodes", 12 + if ids { 4 } else { 0 })?;
    let mut node_ids: Vec<i64> = Vec::new();
    if d.is_ascii() {
        // One node per line: [id] x y z.
        g.nodes.reserve(nn);
        let mut xyz = Vec::with_capacity(3);
        for _ in 0..nn {
            if ids {
                node_ids.push(d.int("node id")?);
            }
            xyz.clear();
            d.floats(3, &mut xyz, "node coordinates", finite)?;
            g.nodes.push([xyz[0], xyz[1], xyz[2]]);
        }
    } else {
        if ids {
            d.ints(nn, &mut node_ids, "node ids")?;
        }
        d.vec3s(nn, &mut g.nodes, "node coordinates", finite)?;
    }
    // With given ids, connectivity names nodes by id; otherwise by 1-based position.
    let id_to_index: Option<HashMap<i64, u32>> = (g.node_ids == IdMode::Given
        && !node_ids
            .iter()
            .enumerate()
            .all(|(i, &id)| id == i as i64 + 1))
    .then(|| {
        node_ids
            .iter()
            .enumerate()
            .map(|(i, &id)| (id, i as u32))
            .collect()
    });

    while let Some(kw) = d.peek_keyword() {
        if kw.starts_with("end time step") {
            break;
        }
        let line = d.keyword("\"part <number>\"")?;
        let number = line
            .strip_prefix("part")
            .and_then(|n| n.trim().parse::<i64>().ok())
            .ok_or_else(|| d.error("\"part <number>\"", &quote(line.as_bytes())))?;
        let description = d.text("part description")?;
        let mut part = Part {
            number,
            description,
            nodes: 0..nn,
            blocks: Vec::new(),
            point_nodes: Vec::new(),
        };
        let nodes = match &id_to_index {
            Some(map) => NodeRefs::Ids(map),
            None => NodeRefs::Positions {
                count: nn,
                first: 0,
            },
        };
        read_element_blocks(d, g.element_ids, true, &mut part, &nodes)?;
        g.parts.push(part);
    }
    Ok(())
}

fn read_gold_body(d: &mut dyn Decoder, g: &mut Geometry, finite: bool) -> Result<()> {
    if d.peek_keyword().is_some_and(|k| k.starts_with("extents")) {
        d.keyword("extents")?;
        let mut extents = Vec::with_capacity(6);
        d.floats(6, &mut extents, "extents", false)?;
    }
    while let Some(kw) = d.peek_keyword() {
        if kw.starts_with("end time step") {
            break;
        }
        expect_keyword(d, "part")?;
        let number = d.int("part number")?;
        let description = d.text("part description")?;
        let start = g.nodes.len();
        let mut nn = 0;
        if let Some(kw) = d.peek_keyword() {
            if kw.starts_with("block") {
                return Err(Error::unsupported(
                    d.path(),
                    format!("structured part {number} ({kw:?})"),
                ));
            }
            if kw.starts_with("coordinates") {
                d.keyword("coordinates")?;
                let ids = g.node_ids.listed();
                nn = d.count("number of nodes", 12 + if ids { 4 } else { 0 })?;
                if ids {
                    d.skip_ints(nn, "node ids")?;
                }
                // x block, y block, z block.
                let mut block = Vec::with_capacity(nn);
                g.nodes.resize(start + nn, [0.0; 3]);
                for (axis, what) in ["x coordinates", "y coordinates", "z coordinates"]
                    .iter()
                    .enumerate()
                {
                    block.clear();
                    d.floats(nn, &mut block, what, finite)?;
                    for (node, v) in g.nodes[start..].iter_mut().zip(&block) {
                        node[axis] = *v;
                    }
                }
            }
        }
        let mut part = Part {
            number,
            description,
            nodes: start..start + nn,
            blocks: Vec::new(),
            point_nodes: Vec::new(),
        };
        read_element_blocks(
            d,
            g.element_ids,
            false,
            &mut part,
            &NodeRefs::Positions {
                count: nn,
                first: start,
            },
        )?;
        g.parts.push(part);
    }
    Ok(())
}

/// How connectivity names nodes: by 1-based position among `count` nodes that start at
/// `first` in the geometry's node array, or by the ids the file gave them.
#[derive(Debug)]
enum NodeRefs<'a> {
    Positions { count: usize, first: usize },
    Ids(&'a HashMap<i64, u32>),
}

impl NodeRefs<'_> {
    fn resolve(&self, raw: i64) -> Result<u32, String> {
        match *self {
            NodeRefs::Positions { count, first } => {
                if (1..=count as i64).contains(&raw) {
                    Ok((first + raw as usize - 1) as u32)
                } else {
                    Err(format!("node {raw}, which is not among the {count} nodes"))
                }
            }
            NodeRefs::Ids(map) => map
                .get(&raw)
                .copied()
                .ok_or_else(|| format!("node id {raw}, which no node has")),
        }
    }

    /// Resolves raw 1-based references in place; on failure, the index of the bad one.
    fn resolve_all(&self, refs: &mut [u32]) -> Result<(), (usize, String)> {
        if let NodeRefs::Positions { count, first } = *self {
            // Common case: one vectorisable range check, then one shift.
            let (lo, hi) = refs
                .iter()
                .fold((u32::MAX, 0), |(lo, hi), &v| (lo.min(v), hi.max(v)));
            if refs.is_empty()
                || (lo >= 1 && (hi as usize) <= count && first + count <= u32::MAX as usize)
            {
                let shift = first as u32;
                for v in refs.iter_mut() {
                    *v = *v - 1 + shift;
                }
                return Ok(());
            }
        }
        for (k, v) in refs.iter_mut().enumerate() {
            *v = self.resolve(i64::from(*v as i32)).map_err(|e| (k, e))?;
        }
        Ok(())
    }
}

/// Reads the element blocks of a part; `point` connectivity is resolved through `nodes`,
/// every other type is read past. EnSight 6 ASCII starts each element's line with its id
/// (`e6`); everything else lists the ids as a block before the connectivity.
fn read_element_blocks(
    d: &mut dyn Decoder,
    element_ids: IdMode,
    e6: bool,
    part: &mut Part,
    nodes: &NodeRefs<'_>,
) -> Result<()> {
    let ids = element_ids.listed();
    while let Some(kw) = d.peek_keyword() {
        if !is_element_keyword(&kw) {
            if kw.starts_with("block") {
                return Err(Error::unsupported(
                    d.path(),
                    format!("structured part {} ({kw:?})", part.number),
                ));
            }
            break;
        }
        let kind = d.keyword("element type")?;
        let base = kind.strip_prefix("g_").unwrap_or(&kind).to_string();
        let id_bytes = if ids { 4 } else { 0 };
        let ids_inline = ids && e6 && d.is_ascii();
        let count;
        match (base.as_str(), nodes_per_element(&base)) {
            ("nsided", _) => {
                count = d.count("number of nsided elements", 4 + id_bytes)?;
                if ids {
                    d.skip_ints(count, "element ids")?;
                }
                let mut per = Vec::new();
                d.ints(count, &mut per, "nodes per nsided element")?;
                let total = checked_total(d, &per, "nsided node count")?;
                d.skip_ints(total, "nsided connectivity")?;
            }
            ("nfaced", _) => {
                count = d.count("number of nfaced elements", 4 + id_bytes)?;
                if ids {
                    d.skip_ints(count, "element ids")?;
                }
                let mut faces = Vec::new();
                d.ints(count, &mut faces, "faces per nfaced element")?;
                let nf = checked_total(d, &faces, "nfaced face count")?;
                let mut per_face = Vec::new();
                d.ints(nf, &mut per_face, "nodes per nfaced face")?;
                let total = checked_total(d, &per_face, "nfaced node count")?;
                d.skip_ints(total, "nfaced connectivity")?;
            }
            (_, Some(npe)) => {
                count = d.count(&format!("number of {kind} elements"), 4 * npe + id_bytes)?;
                let is_point = base == "point";
                if ids && !ids_inline {
                    d.skip_ints(count, "element ids")?;
                }
                if d.is_ascii() {
                    // One element per line: [id] n1 … n_npe.
                    let mut conn = Vec::with_capacity(npe);
                    for _ in 0..count {
                        if ids_inline {
                            d.int("element id")?;
                        }
                        conn.clear();
                        d.ints(npe, &mut conn, &format!("{kind} connectivity"))?;
                        if is_point {
                            let i = nodes
                                .resolve(conn[0])
                                .map_err(|e| d.error("a node of this geometry", &e))?;
                            part.point_nodes.push(i);
                        }
                    }
                } else if is_point {
                    // Bulk decode, then resolve every reference in one pass.
                    let first = part.point_nodes.len();
                    let start = d.u32s(count, &mut part.point_nodes, "point connectivity")?;
                    nodes
                        .resolve_all(&mut part.point_nodes[first..])
                        .map_err(|(k, e)| {
                            Error::parse(
                                d.path(),
                                Location::Byte((start + 4 * k) as u64),
                                "a node of this geometry",
                                e,
                            )
                        })?;
                } else {
                    d.skip_ints(count * npe, &format!("{kind} connectivity"))?;
                }
            }
            (_, None) => return Err(d.error("a known element type", &quote(kind.as_bytes()))),
        }
        part.blocks.push(ElementBlock { kind, count });
    }
    Ok(())
}

fn checked_total(d: &dyn Decoder, counts: &[i64], what: &str) -> Result<usize> {
    let mut total: usize = 0;
    for &c in counts {
        let c = usize::try_from(c).map_err(|_| d.error(&format!("{what} ≥ 0"), &c.to_string()))?;
        total = total
            .checked_add(c)
            .ok_or_else(|| d.error(what, "a total that overflows"))?;
    }
    Ok(total)
}

/// Reads a whole geometry file given its bytes.
pub(crate) fn parse_geometry_bytes(
    path: &Path,
    data: &[u8],
    format: Format,
    block: Option<usize>,
    order: Option<ByteOrder>,
    finite: bool,
) -> Result<Geometry> {
    let encoding = crate::binary::sniff(path, data)?;
    crate::reader::with_decoder(path, data, format, encoding, true, block, order, |d| {
        read_geometry(d, format, encoding, finite)
    })
}
