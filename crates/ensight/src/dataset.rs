//! A case opened once: its steps, and reading one step into particle arrays.

use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::binary::{ByteOrder, Encoding, sniff};
use crate::case::{
    CaseFile, FileRef, Format, StepFile, VarLocation, VarType, Variable, expand_wildcards,
    has_wildcards,
};
use crate::error::{Error, Location, Result};
use crate::geometry::{Geometry, read_geometry};
use crate::reader::with_decoder;
use crate::source;
use crate::variables::{Measured, VarLayout, read_measured, read_node_variable};

/// Which points of a step are the particles.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PointSource {
    /// `point` elements of the model if it has any, else the measured particles.
    #[default]
    Auto,
    /// Nodes referenced by `point` elements of the model geometry.
    PointElements,
    /// Every node of the model geometry (mesh nodes too).
    AllNodes,
    /// The measured-particle file.
    Measured,
}

/// What to read from a step; everything not asked for is not decoded.
#[derive(Debug, Clone, Default)]
pub struct StepRequest {
    pub points: PointSource,
    /// Part numbers to take points from (model geometry); `None` for all parts.
    pub parts: Option<Vec<i64>>,
    /// A vector variable holding the particle normals.
    pub normals: Option<String>,
    /// Scalar or vector variables to read.
    pub fields: Vec<String>,
    /// A scalar variable whose nonzero values flag surface particles.
    pub surface: Option<String>,
    /// Accept NaN/Inf coordinates instead of failing with their location.
    pub allow_non_finite: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub enum FieldValues {
    Scalar(Vec<f32>),
    Vector(Vec<[f32; 3]>),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    pub name: String,
    pub values: FieldValues,
}

/// One time step's particles.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    pub index: usize,
    pub time: f64,
    /// The source the request resolved to.
    pub source: PointSource,
    pub positions: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub fields: Vec<Field>,
    pub surface: Option<Vec<bool>>,
}

/// The particles of a step before variables are read, and how to find their values.
#[derive(Debug)]
struct SelectedPoints {
    positions: Vec<[f32; 3]>,
    /// Indices into the geometry's nodes; `None` for measured particles (all, in order).
    selection: Option<Vec<u32>>,
    encoding: Encoding,
    order: Option<ByteOrder>,
    /// Nodes a variable file covers.
    count: usize,
    /// Gold parts `(number, node range)`, for per-part variable files.
    parts_layout: Vec<(i64, Range<usize>)>,
}

/// An EnSight case, opened once.
#[derive(Debug, Clone)]
pub struct Case {
    path: PathBuf,
    file: CaseFile,
    byte_order: Option<ByteOrder>,
    main_set: Option<u32>,
    times: Vec<f64>,
}

impl Case {
    pub fn open(path: impl AsRef<Path>) -> Result<Case> {
        let path = path.as_ref();
        // Through FileBytes: a FIFO or device in place of the case is refused, not waited on.
        let text = source::open(path)?.to_vec();
        let text = String::from_utf8(text).map_err(|e| {
            Error::parse(
                path,
                Location::Byte(e.utf8_error().valid_up_to() as u64),
                "a text case file",
                "bytes that are not UTF-8",
            )
        })?;
        Case::from_text(path, &text)
    }

    /// Parses case text as if it had been read from `path` (data files are found beside it).
    pub fn from_text(path: &Path, text: &str) -> Result<Case> {
        let file = CaseFile::parse(path, text)?;
        // Without geometry there are no particles to read, in any step: say so once, here.
        if file.model.is_none() && file.measured.is_none() {
            return Err(Error::parse(
                path,
                Location::File,
                "a \"model:\" or \"measured:\" line in the GEOMETRY section",
                "neither",
            ));
        }
        let main_set = file
            .model
            .as_ref()
            .and_then(|m| m.time_set)
            .or_else(|| file.measured.as_ref().and_then(|m| m.time_set))
            .or_else(|| {
                file.variables
                    .iter()
                    .find_map(|v| v.file.as_ref().and_then(|f| f.time_set))
            })
            .or_else(|| (file.time_sets.len() == 1).then(|| file.time_sets[0].id));
        let times = match main_set {
            Some(id) => file
                .time_set(id)
                .ok_or_else(|| {
                    Error::parse(
                        path,
                        Location::File,
                        format!("time set {id} in the TIME section"),
                        "none",
                    )
                })?
                .times
                .clone(),
            None => vec![0.0],
        };
        Ok(Case {
            path: path.to_path_buf(),
            file,
            byte_order: None,
            main_set,
            times,
        })
    }

    /// Forces the byte order of binary files instead of detecting it.
    pub fn set_byte_order(&mut self, order: Option<ByteOrder>) {
        self.byte_order = order;
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn case_file(&self) -> &CaseFile {
        &self.file
    }

    pub fn format(&self) -> Format {
        self.file.format
    }

    pub fn step_count(&self) -> usize {
        self.times.len()
    }

    pub fn times(&self) -> &[f64] {
        &self.times
    }

    pub fn variables(&self) -> &[Variable] {
        &self.file.variables
    }

    pub fn variable(&self, name: &str) -> Result<&Variable> {
        self.file
            .variables
            .iter()
            .find(|v| v.name == name)
            .ok_or_else(|| {
                let names: Vec<&str> = self
                    .file
                    .variables
                    .iter()
                    .map(|v| v.name.as_str())
                    .collect();
                Error::Request(format!(
                    "{}: no variable {name:?} (it has: {})",
                    self.path.display(),
                    names.join(", ")
                ))
            })
    }

    fn check_step(&self, step: usize) -> Result<()> {
        if step >= self.times.len() {
            return Err(Error::Request(format!(
                "{}: step {step} requested, the case has {} (0..{})",
                self.path.display(),
                self.times.len(),
                self.times.len()
            )));
        }
        Ok(())
    }

    /// The file (and block) holding `fref`'s data for main step `step`.
    pub fn resolve(&self, fref: &FileRef, step: usize) -> Result<StepFile> {
        self.check_step(step)?;
        let dir = self.path.parent().unwrap_or(Path::new("."));
        let set_id = fref
            .time_set
            .or(if has_wildcards(&fref.pattern) || fref.file_set.is_some() {
                self.main_set
            } else {
                None
            });
        let Some(set_id) = set_id else {
            return Ok(StepFile {
                path: dir.join(&fref.pattern),
                block: None,
            });
        };
        let set = self.file.time_set(set_id).ok_or_else(|| {
            Error::Request(format!(
                "{}: {:?} uses time set {set_id}, which the case does not define",
                self.path.display(),
                fref.pattern
            ))
        })?;
        // Map the main step onto this file's time set by time.
        let j = if Some(set_id) == self.main_set {
            step
        } else {
            let t = self.times[step];
            set.times
                .iter()
                .rposition(|&s| s <= t + 1e-12 * t.abs().max(1.0))
                .unwrap_or(0)
        };
        if let Some(fs) = fref.file_set {
            let set = self.file.file_set(fs).ok_or_else(|| {
                Error::Request(format!(
                    "{}: {:?} uses file set {fs}, which the case does not define",
                    self.path.display(),
                    fref.pattern
                ))
            })?;
            let mut first = 0;
            for chunk in &set.chunks {
                if j < first + chunk.steps {
                    let name = match chunk.index {
                        Some(i) => expand_wildcards(&fref.pattern, i),
                        None => fref.pattern.clone(),
                    };
                    return Ok(StepFile {
                        path: dir.join(name),
                        block: Some(j - first),
                    });
                }
                first += chunk.steps;
            }
            return Err(Error::Request(format!(
                "{}: file set {fs} holds {first} steps, step {j} requested",
                self.path.display()
            )));
        }
        if !has_wildcards(&fref.pattern) {
            return Ok(StepFile {
                path: dir.join(&fref.pattern),
                block: None,
            });
        }
        let number = *set.file_numbers.get(j).ok_or_else(|| {
            Error::Request(format!("{}: time set {set_id} gives no filename numbers (filename start number / filename numbers) for {:?}", self.path.display(), fref.pattern))
        })?;
        Ok(StepFile {
            path: dir.join(expand_wildcards(&fref.pattern, number)),
            block: None,
        })
    }

    pub fn model_file(&self, step: usize) -> Result<Option<StepFile>> {
        self.file
            .model
            .as_ref()
            .map(|m| self.resolve(m, step))
            .transpose()
    }

    pub fn measured_file(&self, step: usize) -> Result<Option<StepFile>> {
        self.file
            .measured
            .as_ref()
            .map(|m| self.resolve(m, step))
            .transpose()
    }

    /// Reads the model geometry of a step.
    pub fn read_geometry(&self, step: usize, allow_non_finite: bool) -> Result<Geometry> {
        let file = self
            .model_file(step)?
            .ok_or_else(|| Error::Request(format!("{}: no model geometry", self.path.display())))?;
        // After the first step such files hold coordinates only, laid out by the first
        // step's connectivity: read as geometry they would fail somewhere in their bytes.
        if step > 0
            && self
                .file
                .model
                .as_ref()
                .is_some_and(|m| m.change_coords_only)
        {
            return Err(Error::Request(format!(
                "{}: the model line says `change_coords_only` (the geometry files after the \
                 first step hold coordinates only), which slosh does not read: write each \
                 step's geometry in full, or the particles as measured files",
                self.path.display()
            )));
        }
        let bytes = source::open(&file.path)?;
        let encoding = sniff(&file.path, &bytes)?;
        let format = self.file.format;
        with_decoder(
            &file.path,
            &bytes,
            format,
            encoding,
            true,
            file.block,
            self.byte_order,
            |d| read_geometry(d, format, encoding, !allow_non_finite),
        )
    }

    /// Reads the measured particles of a step.
    pub fn read_measured(&self, step: usize, allow_non_finite: bool) -> Result<Measured> {
        let file = self.measured_file(step)?.ok_or_else(|| {
            Error::Request(format!(
                "{}: no measured particle file",
                self.path.display()
            ))
        })?;
        let bytes = source::open(&file.path)?;
        let encoding = sniff(&file.path, &bytes)?;
        with_decoder(
            &file.path,
            &bytes,
            self.file.format,
            encoding,
            true,
            file.block,
            self.byte_order,
            |d| read_measured(d, encoding, !allow_non_finite),
        )
    }

    /// Reads one variable for a step, `components` floats per node interleaved, over every
    /// node of `layout`.
    fn read_variable(
        &self,
        var: &Variable,
        step: usize,
        encoding: Encoding,
        order: Option<ByteOrder>,
        layout: VarLayout<'_>,
        out: &mut Vec<f32>,
    ) -> Result<()> {
        let fref = var.file.as_ref().ok_or_else(|| {
            Error::Request(format!(
                "{}: variable {:?} has no file",
                self.path.display(),
                var.name
            ))
        })?;
        let file = self.resolve(fref, step)?;
        let components = var.var_type.components().ok_or_else(|| {
            Error::unsupported(
                &self.path,
                format!("variable {:?} of type {:?}", var.name, var.var_type),
            )
        })?;
        let bytes = source::open(&file.path)?;
        let order = self.byte_order.or(order);
        with_decoder(
            &file.path,
            &bytes,
            self.file.format,
            encoding,
            false,
            file.block,
            order,
            |d| read_node_variable(d, components, layout, out),
        )
    }

    /// The model nodes that are particles for `source`, and their positions.
    fn select_nodes(
        &self,
        g: Geometry,
        source: PointSource,
        parts: Option<&[i64]>,
        step: usize,
    ) -> Result<SelectedPoints> {
        let mut idx: Vec<u32> = Vec::new();
        for part in selected_parts(&g, parts) {
            if source == PointSource::AllNodes {
                idx.extend(part.nodes.start as u32..part.nodes.end as u32);
            } else {
                idx.extend_from_slice(&part.point_nodes);
            }
        }
        if source == PointSource::AllNodes && self.file.format == Format::Ensight6 {
            // EnSight 6 parts share the one node list: take each node once.
            idx.sort_unstable();
            idx.dedup();
        }
        // A `point` block of no elements is a step without particles yet (Lagrangian and DEM
        // runs inject them later): an empty step, not an error. Only a geometry without any
        // `point` block has nothing slosh can read as particles.
        if idx.is_empty()
            && source == PointSource::PointElements
            && parts.is_none()
            && !g.parts.iter().any(|p| {
                p.blocks
                    .iter()
                    .any(|b| b.kind.trim_start_matches("g_") == "point")
            })
        {
            let mut kinds: Vec<&str> = g
                .parts
                .iter()
                .flat_map(|p| p.blocks.iter().map(|b| b.kind.as_str()))
                .collect();
            kinds.sort_unstable();
            kinds.dedup();
            return Err(Error::Request(format!(
                "{}: slosh reads particles from `point` elements or a measured file; this \
                 case has no measured file and step {step}'s geometry holds {}",
                self.path.display(),
                if kinds.is_empty() {
                    "no elements".to_string()
                } else {
                    format!("only {} elements", kinds.join(", "))
                }
            )));
        }
        let parts_layout = g
            .parts
            .iter()
            .map(|p| (p.number, p.nodes.clone()))
            .collect();
        Ok(SelectedPoints {
            count: g.nodes.len(),
            encoding: g.encoding,
            order: g.byte_order,
            positions: gather(g.nodes, &idx),
            selection: Some(idx),
            parts_layout,
        })
    }

    /// Reads one step: the particles `request` selects, with the variables it names.
    pub fn read_step(&self, step: usize, request: &StepRequest) -> Result<Step> {
        self.check_step(step)?;
        let finite = !request.allow_non_finite;
        let mut source = request.points;
        let mut geometry = None;
        if matches!(
            source,
            PointSource::Auto | PointSource::PointElements | PointSource::AllNodes
        ) && self.file.model.is_some()
        {
            let g = self.read_geometry(step, !finite)?;
            if source == PointSource::Auto {
                let has_points =
                    selected_parts(&g, request.parts.as_deref()).any(|p| !p.point_nodes.is_empty());
                source = if has_points || self.file.measured.is_none() {
                    PointSource::PointElements
                } else {
                    PointSource::Measured
                };
            }
            geometry = Some(g);
        } else if source == PointSource::Auto {
            source = PointSource::Measured;
        }

        let points = if source == PointSource::Measured {
            let m = self.read_measured(step, !finite)?;
            SelectedPoints {
                count: m.positions.len(),
                encoding: m.encoding,
                order: m.byte_order,
                positions: m.positions,
                selection: None,
                parts_layout: Vec::new(),
            }
        } else {
            let g = match geometry {
                Some(g) => g,
                None => {
                    return Err(Error::Request(format!(
                        "{}: points from the model geometry requested, the case has none",
                        self.path.display()
                    )));
                }
            };
            self.select_nodes(g, source, request.parts.as_deref(), step)?
        };
        let SelectedPoints {
            positions,
            selection,
            encoding,
            order,
            count,
            parts_layout,
        } = points;

        let location = if source == PointSource::Measured {
            VarLocation::MeasuredNode
        } else {
            VarLocation::Node
        };
        let layout = if location == VarLocation::Node && self.file.format == Format::Gold {
            VarLayout::Parts(&parts_layout)
        } else {
            VarLayout::Global(count)
        };
        let read = |name: &str, want: Option<VarType>| -> Result<(VarType, Vec<f32>)> {
            let var = self.variable(name)?;
            if var.location != location {
                return Err(Error::Request(format!(
                    "{}: variable {name:?} is per {:?}, the particles come from {:?}",
                    self.path.display(),
                    var.location,
                    source
                )));
            }
            if let Some(want) = want
                && var.var_type != want
            {
                return Err(Error::Request(format!(
                    "{}: variable {name:?} is a {:?}, a {want:?} is needed",
                    self.path.display(),
                    var.var_type
                )));
            }
            let mut values = Vec::new();
            self.read_variable(var, step, encoding, order, layout, &mut values)?;
            let comps = var.var_type.components().unwrap_or(1);
            Ok((
                var.var_type,
                gather_components(values, comps, selection.as_deref()),
            ))
        };

        let normals = match &request.normals {
            Some(name) => Some(to_vec3(read(name, Some(VarType::Vector))?.1)),
            None => None,
        };
        let surface = match &request.surface {
            Some(name) => Some(
                read(name, Some(VarType::Scalar))?
                    .1
                    .iter()
                    .map(|&v| v != 0.0 && !v.is_nan())
                    .collect(),
            ),
            None => None,
        };
        let mut fields = Vec::with_capacity(request.fields.len());
        for name in &request.fields {
            let (ty, values) = read(name, None)?;
            let values = if ty == VarType::Vector {
                FieldValues::Vector(to_vec3(values))
            } else {
                FieldValues::Scalar(values)
            };
            fields.push(Field {
                name: name.clone(),
                values,
            });
        }
        Ok(Step {
            index: step,
            time: self.times[step],
            source,
            positions,
            normals,
            fields,
            surface,
        })
    }
}

fn selected_parts<'a>(
    g: &'a Geometry,
    parts: Option<&'a [i64]>,
) -> impl Iterator<Item = &'a crate::geometry::Part> + 'a {
    g.parts
        .iter()
        .filter(move |p| parts.is_none_or(|sel| sel.contains(&p.number)))
}

fn is_identity(idx: &[u32], n: usize) -> bool {
    // Branch-free so that it vectorises: the whole step is scanned either way.
    idx.len() == n && idx.iter().zip(0u32..).fold(0, |acc, (&v, i)| acc | (v ^ i)) == 0
}

/// Picks `idx` out of `all`; moves the vector when the selection is everything in order.
fn gather<T: Copy>(all: Vec<T>, idx: &[u32]) -> Vec<T> {
    if is_identity(idx, all.len()) {
        return all;
    }
    idx.iter().map(|&i| all[i as usize]).collect()
}

fn gather_components(values: Vec<f32>, comps: usize, idx: Option<&[u32]>) -> Vec<f32> {
    match idx {
        Some(idx) if !is_identity(idx, values.len() / comps) => {
            let mut out = Vec::with_capacity(idx.len() * comps);
            for &i in idx {
                let i = i as usize * comps;
                out.extend_from_slice(&values[i..i + comps]);
            }
            out
        }
        _ => values,
    }
}

fn to_vec3(values: Vec<f32>) -> Vec<[f32; 3]> {
    match bytemuck::allocation::try_cast_vec::<f32, [f32; 3]>(values) {
        Ok(v) => v,
        Err((_, values)) => values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
    }
}
