//! A baked field as one value per point, which a colour map and a probe take: a scalar
//! field's own values; a vector field's magnitude (by its own name, `velocity`) or one of its
//! components (`velocity.x`, `.y`, `.z`), as ParaView offers them.

use rayon::prelude::*;

use crate::format::{Header, SectionEntry};
use crate::layout::{Element, FIELD_MISSING, field_missing};
use crate::names::FIELD_PREFIX;

/// Which value of a point's vector a view takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VectorPart {
    Magnitude,
    Component(usize),
}

/// Elements a task of [`field_view_ranges`] reads.
const RANGE_BLOCK: usize = 1 << 16;

/// Suffixes of the component views, in order.
const COMPONENTS: [&str; 3] = ["x", "y", "z"];

/// A field view: the section it reads, and for a vector field, which part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldView<'h> {
    pub section: &'h SectionEntry,
    /// `None` for a scalar field.
    pub part: Option<VectorPart>,
}

fn element(section: &SectionEntry) -> Option<Element> {
    Element::from_name(&section.element)
}

/// The views a step's baked fields offer, by name: each scalar field, and each vector field's
/// magnitude and components.
pub fn field_views(header: &Header) -> Vec<String> {
    header
        .sections
        .iter()
        .filter_map(|s| Some(views_of(s.name.strip_prefix(FIELD_PREFIX)?, element(s)?)))
        .flatten()
        .collect()
}

/// The views of field `name` stored as `element`s: its own name, and a vector's components.
pub fn views_of(name: &str, element: Element) -> Vec<String> {
    let mut views = vec![name.to_string()];
    if element == Element::Vec4 {
        views.extend(COMPONENTS.iter().map(|c| format!("{name}.{c}")));
    }
    views
}

/// The view named `name`: a field of that name (a scalar's values, a vector's magnitude),
/// else a component of the vector field `name` ends it with (`velocity.x`).
pub fn find_field_view<'h>(header: &'h Header, name: &str) -> Option<FieldView<'h>> {
    let field = |name: &str| {
        let section_name = format!("{FIELD_PREFIX}{name}");
        header.sections.iter().find(|s| s.name == section_name)
    };
    if let Some(section) = field(name) {
        let part = (element(section) == Some(Element::Vec4)).then_some(VectorPart::Magnitude);
        return Some(FieldView { section, part });
    }
    let (base, axis) = component_view(name)?;
    let section = field(base).filter(|s| element(s) == Some(Element::Vec4))?;
    Some(FieldView {
        section,
        part: Some(VectorPart::Component(axis)),
    })
}

/// The vector field and axis a component view names (`velocity.x`: `velocity`, 0), where
/// its name ends so.
pub fn component_view(view: &str) -> Option<(&str, usize)> {
    let (base, suffix) = view.rsplit_once('.')?;
    Some((base, COMPONENTS.iter().position(|c| *c == suffix)?))
}

/// One value per point from a vector field's decoded bytes (little-endian `vec4<f32>`s):
/// its magnitude or a component, little-endian f32s appended to `out`. A magnitude is
/// measured in f64, and one beyond f32's range is the largest value below
/// [`FIELD_MISSING`]; a vector with a part that is not finite has no magnitude (NaN, which
/// the caller marks missing).
pub fn vector_values(vectors: &[u8], part: VectorPart, out: &mut Vec<u8>) {
    out.reserve(vectors.len() / 4);
    for v in vectors.chunks_exact(16) {
        out.extend_from_slice(&vector_part(v, part).to_le_bytes());
    }
}

/// Part `part` of one little-endian `vec4<f32>` ([`vector_values`]).
fn vector_part(v: &[u8], part: VectorPart) -> f32 {
    let c = |k: usize| f32::from_le_bytes([v[4 * k], v[4 * k + 1], v[4 * k + 2], v[4 * k + 3]]);
    match part {
        VectorPart::Component(k) => c(k),
        VectorPart::Magnitude => {
            let m = (0..3).map(|k| f64::from(c(k)).powi(2)).sum::<f64>().sqrt();
            if m.is_finite() {
                (m as f32).min(FIELD_MISSING.next_down())
            } else {
                f32::NAN
            }
        }
    }
}

/// The least and greatest of a view's values that are not missing ([`field_missing`]).
pub type FieldRange = [f32; 2];

/// The range of each view field `name` offers ([`field_views`]' names), from its raw bytes
/// (`f32`s, or `vec4<f32>`s as [`vector_values`] reads them), missing values left out; a
/// view with no value that is not missing has none. What a step's header records
/// (`Header::field_ranges`), and what a renderer's colours span over a series.
pub fn field_view_ranges(name: &str, element: Element, bytes: &[u8]) -> Vec<(String, FieldRange)> {
    // Each part of a vector (its magnitude first, in the order of `views_of`), or the scalar,
    // over blocks of elements in parallel: a 4M-point vector field is 64 MB.
    let (width, parts) = if element == Element::Vec4 {
        (16, 4)
    } else {
        (4, 1)
    };
    let value = |e: &[u8], k: usize| match (width, k) {
        (4, _) => f32::from_le_bytes([e[0], e[1], e[2], e[3]]),
        (_, 0) => vector_part(e, VectorPart::Magnitude),
        _ => vector_part(e, VectorPart::Component(k - 1)),
    };
    let join = |a: Option<FieldRange>, b: Option<FieldRange>| match (a, b) {
        (Some([a0, a1]), Some([b0, b1])) => Some([a0.min(b0), a1.max(b1)]),
        (a, b) => a.or(b),
    };
    let ranges: Vec<Option<FieldRange>> = bytes
        .par_chunks(width * RANGE_BLOCK)
        .map(|block| {
            let mut ranges = vec![None; parts];
            for e in block.chunks_exact(width) {
                for (k, range) in ranges.iter_mut().enumerate() {
                    let v = value(e, k);
                    if !field_missing(v) {
                        *range = join(*range, Some([v, v]));
                    }
                }
            }
            ranges
        })
        .reduce(
            || vec![None; parts],
            |a, b| a.into_iter().zip(b).map(|(a, b)| join(a, b)).collect(),
        );
    views_of(name, element)
        .into_iter()
        .zip(ranges)
        .filter_map(|(view, range)| range.map(|r| (view, r)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vec4s(vs: &[[f32; 4]]) -> Vec<u8> {
        vs.iter().flatten().flat_map(|c| c.to_le_bytes()).collect()
    }

    fn floats(bytes: &[u8]) -> Vec<f32> {
        bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    }

    #[test]
    fn vectors_give_their_magnitude_and_components() {
        let bytes = vec4s(&[
            [3.0, 4.0, 12.0, 0.0],
            [-1.0, 0.0, 0.0, 7.0],
            [3e38, 3e38, 0.0, 0.0],
            [1.0, f32::NAN, 0.0, 0.0],
            [f32::INFINITY, 0.0, 0.0, 0.0],
        ]);
        let values = |part| {
            let mut out = Vec::new();
            vector_values(&bytes, part, &mut out);
            floats(&out)
        };
        let m = values(VectorPart::Magnitude);
        assert_eq!(&m[..2], &[13.0, 1.0]);
        // Beyond f32: the largest value that is not the missing mark.
        assert_eq!(m[2], FIELD_MISSING.next_down());
        assert!(m[3].is_nan() && m[4].is_nan());
        assert_eq!(values(VectorPart::Component(0))[..3], [3.0, -1.0, 3e38]);
        let y = values(VectorPart::Component(1));
        assert_eq!((y[0], y[1]), (4.0, 0.0));
        assert!(y[3].is_nan());
        assert_eq!(values(VectorPart::Component(2))[0], 12.0);
        // Ranges: the magnitude's and each component's, missing values left out.
        let ranges = field_view_ranges("v", Element::Vec4, &bytes);
        assert_eq!(
            ranges,
            [
                ("v".to_string(), [1.0, FIELD_MISSING.next_down()]),
                ("v.x".to_string(), [-1.0, 3e38]),
                ("v.y".to_string(), [0.0, 3e38]),
                ("v.z".to_string(), [0.0, 12.0])
            ]
        );
        let scalars: Vec<u8> = [f32::NAN, 2.0, -1.0, f32::MAX, f32::INFINITY]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert_eq!(
            field_view_ranges("p", Element::F32, &scalars),
            [("p".to_string(), [-1.0, 2.0])]
        );
        let none: Vec<u8> = f32::NAN.to_le_bytes().to_vec();
        assert!(field_view_ranges("p", Element::F32, &none).is_empty());
        // Over blocks read in parallel: a block of nothing but missing values, the least and
        // the greatest in others.
        let n = 3 * RANGE_BLOCK + 7;
        let many: Vec<u8> = (0..n)
            .map(|i| match i {
                _ if i < RANGE_BLOCK => f32::NAN,
                i if i == RANGE_BLOCK + 5 => -7.0,
                i if i == n - 1 => 9.0,
                i => (i % 5) as f32,
            })
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert_eq!(
            field_view_ranges("p", Element::F32, &many),
            [("p".to_string(), [-7.0, 9.0])]
        );
    }
}
