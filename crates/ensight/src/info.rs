//! What a case holds, for people (a table) and programs (`slosh info --json`): its parts,
//! variables and time sets, and per step its files, particles, bounds or why it cannot be
//! read.

use serde::Serialize;

use crate::{
    ByteOrder, Case, CaseFile, ElementBlock, Encoding, Format, StepRequest, TimeSet, VarLocation,
    VarType,
};

/// The `--json` document. Field names and meanings are stable (docs/info-json.md).
#[derive(Debug, Serialize)]
pub struct Info {
    pub info_version: u32,
    pub case: String,
    pub format: Format,
    pub encoding: Option<Encoding>,
    pub byte_order: Option<ByteOrder>,
    pub model: Option<String>,
    pub measured: Option<String>,
    pub time_sets: Vec<TimeSet>,
    pub parts: Vec<PartInfo>,
    pub variables: Vec<VariableInfo>,
    pub steps: Vec<StepInfo>,
}

#[derive(Debug, Serialize)]
pub struct PartInfo {
    pub number: i64,
    pub description: String,
    pub nodes: usize,
    pub elements: Vec<ElementBlock>,
}

#[derive(Debug, Serialize)]
pub struct VariableInfo {
    pub name: String,
    #[serde(rename = "type")]
    pub var_type: VarType,
    pub location: VarLocation,
    pub file: Option<String>,
}

#[derive(Debug, Serialize)]
pub struct StepInfo {
    pub index: usize,
    pub time: f64,
    pub files: Vec<String>,
    /// Particles (point elements or measured), `None` if the step could not be read.
    pub points: Option<usize>,
    pub source: Option<crate::PointSource>,
    pub bounds: Option<[[f32; 3]; 2]>,
    pub error: Option<String>,
}

pub fn gather(case: &Case) -> Info {
    let file: &CaseFile = case.case_file();
    let mut encoding = None;
    let mut byte_order = None;
    let mut parts = Vec::new();
    // The format is read off the first step whose geometry reads: one missing file does not
    // make the whole case "unreadable".
    let first_geometry =
        (0..case.step_count().max(1)).find_map(|i| case.read_geometry(i, true).ok());
    if file.model.is_some()
        && let Some(g) = first_geometry
    {
        encoding = Some(g.encoding);
        byte_order = g.byte_order;
        let e6 = file.format == Format::Ensight6;
        parts = g
            .parts
            .iter()
            .map(|p| PartInfo {
                number: p.number,
                description: p.description.clone(),
                nodes: if e6 { g.nodes.len() } else { p.nodes.len() },
                elements: p.blocks.clone(),
            })
            .collect();
    }
    if file.measured.is_some()
        && let Some(m) =
            (0..case.step_count().max(1)).find_map(|i| case.read_measured(i, true).ok())
    {
        encoding = encoding.or(Some(m.encoding));
        byte_order = byte_order.or(m.byte_order);
    }
    let steps = (0..case.step_count())
        .map(|i| {
            let mut files = Vec::new();
            if let Ok(Some(f)) = case.model_file(i) {
                files.push(f.path.display().to_string());
            }
            if let Ok(Some(f)) = case.measured_file(i) {
                files.push(f.path.display().to_string());
            }
            match case.read_step(i, &StepRequest::default()) {
                Ok(s) => {
                    let bounds = s
                        .positions
                        .iter()
                        .fold(None, |acc: Option<[[f32; 3]; 2]>, p| {
                            let [lo, hi] = acc.unwrap_or([*p, *p]);
                            Some([
                                [lo[0].min(p[0]), lo[1].min(p[1]), lo[2].min(p[2])],
                                [hi[0].max(p[0]), hi[1].max(p[1]), hi[2].max(p[2])],
                            ])
                        });
                    StepInfo {
                        index: i,
                        time: s.time,
                        files,
                        points: Some(s.positions.len()),
                        source: Some(s.source),
                        bounds,
                        error: None,
                    }
                }
                Err(e) => StepInfo {
                    index: i,
                    time: case.times()[i],
                    files,
                    points: None,
                    source: None,
                    bounds: None,
                    error: Some(e.to_string()),
                },
            }
        })
        .collect();
    Info {
        info_version: 1,
        case: case.path().display().to_string(),
        format: file.format,
        encoding,
        byte_order,
        model: file.model.as_ref().map(|m| m.pattern.clone()),
        measured: file.measured.as_ref().map(|m| m.pattern.clone()),
        time_sets: file.time_sets.clone(),
        parts,
        variables: file
            .variables
            .iter()
            .map(|v| VariableInfo {
                name: v.name.clone(),
                var_type: v.var_type,
                location: v.location,
                file: v.file.as_ref().map(|f| f.pattern.clone()),
            })
            .collect(),
        steps,
    }
}

pub fn render_human(info: &Info) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let fmt = match info.format {
        Format::Ensight6 => "EnSight 6",
        Format::Gold => "EnSight Gold",
    };
    let enc = match info.encoding {
        Some(Encoding::CBinary) => format!(
            "C Binary, {}-endian",
            match info.byte_order {
                Some(ByteOrder::Big) => "big",
                _ => "little",
            }
        ),
        Some(Encoding::Ascii) => "ASCII".to_string(),
        None => "encoding unknown: no step's files could be read".to_string(),
    };
    let _ = writeln!(out, "case      {}", info.case);
    let _ = writeln!(out, "format    {fmt}, {enc}");
    if let Some(m) = &info.model {
        let _ = writeln!(out, "model     {m}");
    }
    if let Some(m) = &info.measured {
        let _ = writeln!(out, "measured  {m}");
    }
    for p in &info.parts {
        let elements: Vec<String> = p
            .elements
            .iter()
            .map(|b| format!("{} {}", b.count, b.kind))
            .collect();
        let _ = writeln!(
            out,
            "part {:<4} {:<24} {} nodes, {}",
            p.number,
            p.description,
            p.nodes,
            if elements.is_empty() {
                "no elements".to_string()
            } else {
                elements.join(", ")
            }
        );
    }
    for v in &info.variables {
        let _ = writeln!(
            out,
            "variable  {:<16} {:?} per {:?}",
            v.name, v.var_type, v.location
        );
    }
    let _ = writeln!(out, "steps     {}", info.steps.len());
    let _ = writeln!(out, "{:>6} {:>12} {:>10}  bounds", "step", "time", "points");
    for s in &info.steps {
        let _ = match (&s.error, s.bounds) {
            (Some(e), _) => writeln!(
                out,
                "{:>6} {:>12.6} {:>10}  error: {e}",
                s.index, s.time, "-"
            ),
            (None, Some([lo, hi])) => writeln!(
                out,
                "{:>6} {:>12.6} {:>10}  [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]",
                s.index,
                s.time,
                s.points.unwrap_or(0),
                lo[0],
                lo[1],
                lo[2],
                hi[0],
                hi[1],
                hi[2]
            ),
            (None, None) => writeln!(out, "{:>6} {:>12.6} {:>10}  (empty)", s.index, s.time, 0),
        };
    }
    out
}
