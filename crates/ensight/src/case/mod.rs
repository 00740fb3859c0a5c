//! The `.case` file: format, geometry and variable files, time sets and file sets.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{Error, Location, Result, quote};

mod sets;

use sets::{build_file_sets, build_time_sets};

/// EnSight 6 or EnSight Gold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    #[serde(rename = "ensight6")]
    Ensight6,
    Gold,
}

/// A file named in the case, possibly with `*` wildcards for the step number.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FileRef {
    pub pattern: String,
    pub time_set: Option<u32>,
    pub file_set: Option<u32>,
    pub change_coords_only: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VarType {
    Constant,
    Scalar,
    Vector,
    TensorSymm,
    TensorAsym,
    ComplexScalar,
    ComplexVector,
}

impl VarType {
    /// Floats per value in a per-node file; `None` for types slosh does not read.
    pub fn components(self) -> Option<usize> {
        match self {
            VarType::Scalar => Some(1),
            VarType::Vector => Some(3),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VarLocation {
    Case,
    Node,
    MeasuredNode,
    Element,
}

/// One line of the VARIABLE section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Variable {
    pub name: String,
    pub var_type: VarType,
    pub location: VarLocation,
    /// The data file; `None` for `constant per case`.
    pub file: Option<FileRef>,
    /// Values of `constant per case`, one per step of its time set (or one).
    pub constants: Vec<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimeSet {
    pub id: u32,
    pub description: Option<String>,
    pub times: Vec<f64>,
    /// The number replacing the wildcards for each step; empty if the case gives none.
    pub file_numbers: Vec<i64>,
}

/// A run of consecutive steps stored in one file of a file set.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FileSetChunk {
    /// Replaces the wildcards in the file name; `None` when the name has none.
    pub index: Option<i64>,
    pub steps: usize,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FileSet {
    pub id: u32,
    pub chunks: Vec<FileSetChunk>,
}

/// The parsed content of a `.case` file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CaseFile {
    pub format: Format,
    pub model: Option<FileRef>,
    pub measured: Option<FileRef>,
    pub variables: Vec<Variable>,
    pub time_sets: Vec<TimeSet>,
    pub file_sets: Vec<FileSet>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Section {
    None,
    Format,
    Geometry,
    Variable,
    Time,
    File,
}

/// A TIME or FILE entry whose values may continue on the following lines.
#[derive(Debug)]
struct Entry {
    key: String,
    values: Vec<String>,
    line: usize,
}

impl CaseFile {
    /// Parses case text; `path` is used in messages and to find `… file:` side files.
    pub fn parse(path: &Path, text: &str) -> Result<CaseFile> {
        let err = |line: usize, expected: &str, found: &str| {
            Error::parse(
                path,
                Location::Line(line),
                expected,
                quote(found.as_bytes()),
            )
        };
        let mut section = Section::None;
        let mut format = None;
        let mut model = None;
        let mut measured = None;
        let mut variables = Vec::new();
        let mut time_entries: Vec<Entry> = Vec::new();
        let mut file_entries: Vec<Entry> = Vec::new();

        for (index, raw) in text.lines().enumerate() {
            let line_no = index + 1;
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let upper = line.to_ascii_uppercase();
            let header = match upper.as_str() {
                "FORMAT" => Some(Section::Format),
                "GEOMETRY" => Some(Section::Geometry),
                "VARIABLE" => Some(Section::Variable),
                "TIME" => Some(Section::Time),
                "FILE" => Some(Section::File),
                _ => None,
            };
            if let Some(h) = header {
                section = h;
                continue;
            }
            let (key, value) = match line.split_once(':') {
                Some((k, v)) => (k.trim().to_ascii_lowercase(), v.trim()),
                None => (String::new(), line),
            };
            match section {
                Section::None => {
                    return Err(err(
                        line_no,
                        "a section (FORMAT, GEOMETRY, VARIABLE, TIME, FILE)",
                        line,
                    ));
                }
                Section::Format => {
                    if key != "type" {
                        return Err(err(
                            line_no,
                            "\"type: ensight\" or \"type: ensight gold\"",
                            line,
                        ));
                    }
                    let v = value.to_ascii_lowercase();
                    let words: Vec<&str> = v.split_whitespace().collect();
                    format = Some(match words.as_slice() {
                        ["ensight"] => Format::Ensight6,
                        ["ensight", "gold"] => Format::Gold,
                        _ => return Err(err(line_no, "\"ensight\" or \"ensight gold\"", value)),
                    });
                }
                Section::Geometry => match key.as_str() {
                    "model" => {
                        model = Some(
                            parse_geometry_ref(value)
                                .ok_or_else(|| err(line_no, "model: [ts] [fs] filename", line))?,
                        )
                    }
                    "measured" => {
                        measured =
                            Some(parse_geometry_ref(value).ok_or_else(|| {
                                err(line_no, "measured: [ts] [fs] filename", line)
                            })?)
                    }
                    // Known, valid, and of no use to slosh.
                    "match" | "boundary" | "rigid_body" | "vector_glyphs" => {}
                    _ => {
                        return Err(err(
                            line_no,
                            "model:, measured:, match:, boundary: or rigid_body:",
                            line,
                        ));
                    }
                },
                Section::Variable => {
                    let var = parse_variable(&key, value).ok_or_else(|| {
                        err(
                            line_no,
                            "a variable line such as \"scalar per node: [ts] [fs] name file\"",
                            line,
                        )
                    })?;
                    variables.push(var);
                }
                Section::Time | Section::File => {
                    let entries = if section == Section::Time {
                        &mut time_entries
                    } else {
                        &mut file_entries
                    };
                    let tokens = value.split_whitespace().map(str::to_string);
                    if key.is_empty() {
                        // A continuation line of the previous entry's numbers.
                        match entries.last_mut() {
                            Some(e) if is_wrapping_key(&e.key) => e.values.extend(tokens),
                            _ => return Err(err(line_no, "a TIME/FILE keyword", line)),
                        }
                    } else {
                        entries.push(Entry {
                            key,
                            values: tokens.collect(),
                            line: line_no,
                        });
                    }
                }
            }
        }
        let format = format.ok_or_else(|| {
            Error::parse(
                path,
                Location::File,
                "a FORMAT section with \"type:\"",
                "none",
            )
        })?;
        let time_sets = build_time_sets(path, &time_entries)?;
        let file_sets = build_file_sets(path, &file_entries)?;
        Ok(CaseFile {
            format,
            model,
            measured,
            variables,
            time_sets,
            file_sets,
        })
    }

    pub fn time_set(&self, id: u32) -> Option<&TimeSet> {
        self.time_sets.iter().find(|t| t.id == id)
    }

    pub fn file_set(&self, id: u32) -> Option<&FileSet> {
        self.file_sets.iter().find(|f| f.id == id)
    }
}

fn is_wrapping_key(key: &str) -> bool {
    matches!(key, "time values" | "filename numbers")
}

fn parse_u32(s: &str) -> Option<u32> {
    s.parse().ok()
}

fn parse_geometry_ref(value: &str) -> Option<FileRef> {
    let mut tokens: Vec<&str> = value.split_whitespace().collect();
    let mut change_coords_only = false;
    if let Some(pos) = tokens
        .iter()
        .position(|t| t.eq_ignore_ascii_case("change_coords_only"))
    {
        change_coords_only = true;
        tokens.truncate(pos);
    }
    let pattern = tokens.pop()?.to_string();
    let (time_set, file_set) = match tokens.as_slice() {
        [] => (None, None),
        [ts] => (Some(parse_u32(ts)?), None),
        [ts, fs] => (Some(parse_u32(ts)?), Some(parse_u32(fs)?)),
        _ => return None,
    };
    Some(FileRef {
        pattern,
        time_set,
        file_set,
        change_coords_only,
    })
}

fn parse_variable(key: &str, value: &str) -> Option<Variable> {
    let key: String = key.split_whitespace().collect::<Vec<_>>().join(" ");
    let (var_type, location) = match key.as_str() {
        "constant per case" | "constant per case file" => (VarType::Constant, VarLocation::Case),
        _ => {
            let (ty, loc) = key.split_once(" per ")?;
            let var_type = match ty {
                "scalar" => VarType::Scalar,
                "vector" => VarType::Vector,
                "tensor symm" | "tensor" => VarType::TensorSymm,
                "tensor asym" => VarType::TensorAsym,
                "complex scalar" => VarType::ComplexScalar,
                "complex vector" => VarType::ComplexVector,
                _ => return None,
            };
            let location = match loc {
                "node" => VarLocation::Node,
                "measured node" => VarLocation::MeasuredNode,
                "element" => VarLocation::Element,
                _ => return None,
            };
            (var_type, location)
        }
    };
    let tokens: Vec<&str> = value.split_whitespace().collect();
    if var_type == VarType::Constant {
        // constant per case: [ts] description value(s)   |   constant per case file: [ts] description file
        let (time_set, rest) = match tokens.as_slice() {
            [ts, desc, ..] if parse_u32(ts).is_some() && desc.parse::<f64>().is_err() => {
                (parse_u32(ts), &tokens[1..])
            }
            _ => (None, &tokens[..]),
        };
        let (name, values) = rest.split_first()?;
        if key.ends_with("file") {
            let file = FileRef {
                pattern: (*values.first()?).to_string(),
                time_set,
                file_set: None,
                change_coords_only: false,
            };
            return Some(Variable {
                name: (*name).to_string(),
                var_type,
                location,
                file: Some(file),
                constants: Vec::new(),
            });
        }
        let constants = values
            .iter()
            .map(|v| v.parse::<f64>().ok())
            .collect::<Option<Vec<_>>>()?;
        if constants.is_empty() {
            return None;
        }
        return Some(Variable {
            name: (*name).to_string(),
            var_type,
            location,
            file: None,
            constants,
        });
    }
    // Complex variables end in: description real_file imag_file frequency.
    let tail = if matches!(var_type, VarType::ComplexScalar | VarType::ComplexVector) {
        4
    } else {
        2
    };
    if tokens.len() < tail {
        return None;
    }
    let (sets, rest) = tokens.split_at(tokens.len() - tail);
    let (time_set, file_set) = match sets {
        [] => (None, None),
        [ts] => (Some(parse_u32(ts)?), None),
        [ts, fs] => (Some(parse_u32(ts)?), Some(parse_u32(fs)?)),
        _ => return None,
    };
    let file = FileRef {
        pattern: rest[1].to_string(),
        time_set,
        file_set,
        change_coords_only: false,
    };
    Some(Variable {
        name: rest[0].to_string(),
        var_type,
        location,
        file: Some(file),
        constants: Vec::new(),
    })
}

/// Replaces each run of k `*` with `number` zero-padded to k digits.
pub fn expand_wildcards(pattern: &str, number: i64) -> String {
    let mut out = String::with_capacity(pattern.len() + 4);
    let mut chars = pattern.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '*' {
            let mut width = 1;
            while chars.peek() == Some(&'*') {
                chars.next();
                width += 1;
            }
            out.push_str(&format!("{number:0width$}"));
        } else {
            out.push(c);
        }
    }
    out
}

pub fn has_wildcards(pattern: &str) -> bool {
    pattern.contains('*')
}

/// Where the data of one step lives: a file, and which `BEGIN TIME STEP` block in it (if any).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepFile {
    pub path: PathBuf,
    /// Index of the step's block in a single-file transient file; `None` for one file per step.
    pub block: Option<usize>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wildcards_pad_to_their_width() {
        assert_eq!(expand_wildcards("a.geo****", 7), "a.geo0007");
        assert_eq!(expand_wildcards("p*.scl", 12), "p12.scl");
        assert_eq!(expand_wildcards("static.geo", 3), "static.geo");
    }

    #[test]
    fn wrapped_numbers_and_comments() {
        let text = "# comment\nFORMAT\ntype: ensight gold\n\nGEOMETRY\nmodel: 1 g.geo****\n\
            VARIABLE\nscalar per node: 1 p p.****\nconstant per case: Re 100.0\n\
            TIME\ntime set: 1 main\nnumber of steps: 4\nfilename numbers: 0 2\n 4 6\ntime values: 0.0 0.5\n1.0\n 1.5\n";
        let c = CaseFile::parse(Path::new("x.case"), text).unwrap();
        assert_eq!(c.format, Format::Gold);
        let ts = c.time_set(1).unwrap();
        assert_eq!(ts.file_numbers, vec![0, 2, 4, 6]);
        assert_eq!(ts.times, vec![0.0, 0.5, 1.0, 1.5]);
        assert_eq!(c.variables[1].constants, vec![100.0]);
        assert_eq!(c.variables[0].file.as_ref().unwrap().time_set, Some(1));
    }

    /// Time values that are not finite, repeat or go back are an error naming the case file
    /// and the line (issue 14, item 2): a step without a usable time cannot be baked.
    #[test]
    fn non_finite_duplicate_and_decreasing_times_are_refused() {
        let case = |times: &str| {
            format!(
                "FORMAT\ntype: ensight gold\nGEOMETRY\nmodel: 1 g.geo*\nTIME\ntime set: 1\nnumber of steps: 3\nfilename start number: 0\nfilename increment: 1\ntime values: {times}\n"
            )
        };
        for (times, found) in [
            ("0 nan inf", "time value 1 is NaN"),
            ("0 1 inf", "time value 2 is inf"),
            ("0 0.5 0.5", "time value 2 (0.5) after 0.5 (a duplicate)"),
            ("0 1 0.5", "time value 2 (0.5) after 1 (decreasing)"),
        ] {
            let err = CaseFile::parse(Path::new("runs/x.case"), &case(times))
                .unwrap_err()
                .to_string();
            assert!(err.contains("runs/x.case"), "{err}");
            assert!(err.contains("line 10"), "{err}");
            assert!(err.contains(found), "{times}: {err}");
        }
        assert!(CaseFile::parse(Path::new("x.case"), &case("0 0.5 1")).is_ok());
    }

    /// File numbers that would pass 2^63 are an error, not a wrap-around (issue 14, item 12).
    #[test]
    fn file_numbers_do_not_wrap() {
        let text = "FORMAT\ntype: ensight gold\nGEOMETRY\nmodel: 1 g.geo*\nTIME\ntime set: 1\nnumber of steps: 3\nfilename start number: 9223372036854775806\nfilename increment: 1\ntime values: 0 1 2\n";
        let err = CaseFile::parse(Path::new("big.case"), text)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("big.case") && err.contains("fit in 64 bits"),
            "{err}"
        );
    }
}
