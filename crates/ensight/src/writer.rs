//! Writing cases: EnSight 6 ASCII, EnSight 6 C Binary, Gold ASCII and Gold C Binary, with point
//! parts or measured particles and per-node variables. Every file is written atomically.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::binary::ByteOrder;
use crate::case::VarType;
use crate::error::{Error, Result};

/// The flavour of EnSight to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteFormat {
    E6Ascii,
    E6Binary,
    GoldAscii,
    GoldBinary,
}

impl WriteFormat {
    fn gold(self) -> bool {
        matches!(self, WriteFormat::GoldAscii | WriteFormat::GoldBinary)
    }
    fn binary(self) -> bool {
        matches!(self, WriteFormat::E6Binary | WriteFormat::GoldBinary)
    }
}

/// Where the particles go: a `point` part of the model geometry, or a measured-particle file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    PointPart,
    Measured,
}

/// One variable's values for a step, one per particle.
#[derive(Debug, Clone, Copy)]
pub enum VarData<'a> {
    Scalar(&'a str, &'a [f32]),
    Vector(&'a str, &'a [[f32; 3]]),
}

impl VarData<'_> {
    fn name(&self) -> &str {
        match self {
            VarData::Scalar(n, _) | VarData::Vector(n, _) => n,
        }
    }
    fn var_type(&self) -> VarType {
        match self {
            VarData::Scalar(..) => VarType::Scalar,
            VarData::Vector(..) => VarType::Vector,
        }
    }
    fn len(&self) -> usize {
        match self {
            VarData::Scalar(_, v) => v.len(),
            VarData::Vector(_, v) => v.len(),
        }
    }
}

/// Digits of the step number in file names.
const STEP_DIGITS: usize = 5;

/// Writes a transient case one step at a time; the case file is rewritten after each step so
/// that an interrupted run leaves a readable case of the steps finished so far.
#[derive(Debug)]
pub struct CaseWriter {
    dir: PathBuf,
    name: String,
    format: WriteFormat,
    placement: Placement,
    variables: Vec<(String, VarType)>,
    times: Vec<f64>,
    order: ByteOrder,
}

impl CaseWriter {
    /// Prepares `dir/name.case`; `variables` are the names and types every step will carry.
    pub fn create(
        dir: &Path,
        name: &str,
        format: WriteFormat,
        placement: Placement,
        variables: &[(&str, VarType)],
    ) -> Result<CaseWriter> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        for (v, ty) in variables {
            if v.is_empty() || v.chars().any(|c| c.is_whitespace() || c == '*' || c == '/') {
                return Err(Error::Request(format!(
                    "variable name {v:?} must be one word without '*' or '/'"
                )));
            }
            if ty.components().is_none() {
                return Err(Error::Request(format!(
                    "variable {v:?}: only scalar and vector variables can be written"
                )));
            }
        }
        Ok(CaseWriter {
            dir: dir.to_path_buf(),
            name: name.to_string(),
            format,
            placement,
            variables: variables
                .iter()
                .map(|(n, t)| ((*n).to_string(), *t))
                .collect(),
            times: Vec::new(),
            order: ByteOrder::Little,
        })
    }

    /// Byte order of binary files (little-endian unless asked; big-endian for old Unix solvers).
    pub fn with_byte_order(mut self, order: ByteOrder) -> Self {
        self.order = order;
        self
    }

    pub fn case_path(&self) -> PathBuf {
        self.dir.join(format!("{}.case", self.name))
    }

    fn step_name(&self, stem: &str, step: usize) -> String {
        format!("{}.{stem}{step:0STEP_DIGITS$}", self.name)
    }

    /// Writes one step's geometry and variables, then the case file.
    pub fn write_step(
        &mut self,
        time: f64,
        positions: &[[f32; 3]],
        variables: &[VarData<'_>],
    ) -> Result<()> {
        let step = self.times.len();
        if step >= 10usize.pow(STEP_DIGITS as u32) {
            return Err(Error::Request(format!(
                "at most {} steps per case",
                10usize.pow(STEP_DIGITS as u32)
            )));
        }
        if let Some(&last) = self.times.last()
            && time <= last
        {
            return Err(Error::Request(format!(
                "time values must increase: {time} after {last}"
            )));
        }
        if variables.len() != self.variables.len()
            || variables
                .iter()
                .zip(&self.variables)
                .any(|(v, (n, t))| v.name() != n || v.var_type() != *t)
        {
            return Err(Error::Request(
                "variables of a step must match those the writer was created with, in order".into(),
            ));
        }
        if let Some(v) = variables.iter().find(|v| v.len() != positions.len()) {
            return Err(Error::Request(format!(
                "variable {:?} has {} values for {} particles",
                v.name(),
                v.len(),
                positions.len()
            )));
        }
        if let Some(i) = positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Request(format!(
                "particle {i} has a non-finite coordinate {:?}",
                positions[i]
            )));
        }
        if step == 0 && self.placement == Placement::Measured {
            // The model geometry of a measured-only case: no nodes, no parts.
            let geo = empty_geometry(self.format, self.order);
            atomic_write(&self.dir.join(format!("{}.geo", self.name)), &geo)?;
        }
        let (geo_stem, geo) = match self.placement {
            Placement::PointPart => ("geo", point_geometry(self.format, self.order, positions)),
            Placement::Measured => (
                "mgeo",
                measured_geometry(self.format, self.order, positions),
            ),
        };
        atomic_write(&self.dir.join(self.step_name(geo_stem, step)), &geo)?;
        for v in variables {
            let bytes = variable_file(self.format, self.order, self.placement, v);
            atomic_write(&self.dir.join(self.step_name(v.name(), step)), &bytes)?;
        }
        self.times.push(time);
        atomic_write(&self.case_path(), self.case_text().as_bytes())
    }

    fn case_text(&self) -> String {
        let wild = "*".repeat(STEP_DIGITS);
        let name = &self.name;
        let mut s = String::from("# written by slosh\nFORMAT\n");
        s += if self.format.gold() {
            "type: ensight gold\n"
        } else {
            "type: ensight\n"
        };
        s += "\nGEOMETRY\n";
        let per = match self.placement {
            Placement::PointPart => {
                let _ = writeln!(s, "model: 1 {name}.geo{wild}");
                "node"
            }
            Placement::Measured => {
                let _ = writeln!(s, "model: {name}.geo");
                let _ = writeln!(s, "measured: 1 {name}.mgeo{wild}");
                "measured node"
            }
        };
        if !self.variables.is_empty() {
            s += "\nVARIABLE\n";
            for (v, ty) in &self.variables {
                let kind = if *ty == VarType::Vector {
                    "vector"
                } else {
                    "scalar"
                };
                let _ = writeln!(s, "{kind} per {per}: 1 {v} {name}.{v}{wild}");
            }
        }
        let _ = write!(
            s,
            "\nTIME\ntime set: 1\nnumber of steps: {}\nfilename start number: 0\nfilename increment: 1\ntime values:\n",
            self.times.len()
        );
        for chunk in self.times.chunks(6) {
            let line: Vec<String> = chunk.iter().map(|t| format!("{t:e}")).collect();
            let _ = writeln!(s, "{}", line.join(" "));
        }
        s
    }
}

/// Writes `bytes` to `path` atomically (temporary name, flush, rename).
pub fn atomic_write(path: &Path, bytes: &[u8]) -> Result<()> {
    slosh_fileio::atomic_write(path, bytes).map_err(|e| Error::io(&e.path, e.source))
}

/// Buffers one file in either encoding, so each layout below is written once.
struct Out {
    binary: bool,
    gold: bool,
    order: ByteOrder,
    bytes: Vec<u8>,
    text: String,
}

impl Out {
    fn new(format: WriteFormat, order: ByteOrder) -> Out {
        Out {
            binary: format.binary(),
            gold: format.gold(),
            order,
            bytes: Vec::new(),
            text: String::new(),
        }
    }

    fn word(&mut self, bits: u32) {
        let b = match self.order {
            ByteOrder::Little => bits.to_le_bytes(),
            ByteOrder::Big => bits.to_be_bytes(),
        };
        self.bytes.extend_from_slice(&b);
    }

    fn string(&mut self, s: &str) {
        if self.binary {
            let mut rec = [0u8; 80];
            let n = s.len().min(79);
            rec[..n].copy_from_slice(&s.as_bytes()[..n]);
            self.bytes.extend_from_slice(&rec);
        } else {
            self.text.push_str(s);
            self.text.push('\n');
        }
    }

    /// A count or part number alone on its line: `%8d` (EnSight 6) or `%10d` (Gold).
    fn int(&mut self, v: usize) {
        if self.binary {
            self.word(v as u32);
        } else if self.gold {
            let _ = writeln!(self.text, "{v:10}");
        } else {
            let _ = writeln!(self.text, "{v:8}");
        }
    }

    fn int_array(&mut self, values: impl Iterator<Item = usize>) {
        for v in values {
            self.int(v);
        }
    }

    /// Floats, `per_line` to a line in ASCII (`%12.5e` each).
    fn floats(&mut self, values: impl Iterator<Item = f32>, per_line: usize) {
        if self.binary {
            for v in values {
                self.word(v.to_bits());
            }
            return;
        }
        let mut k = 0;
        for v in values {
            push_e12(&mut self.text, v);
            k += 1;
            if k == per_line {
                self.text.push('\n');
                k = 0;
            }
        }
        if k != 0 {
            self.text.push('\n');
        }
    }

    fn finish(self) -> Vec<u8> {
        if self.binary {
            self.bytes
        } else {
            self.text.into_bytes()
        }
    }
}

/// C's `%12.5e`: `-1.23450e+00`, right-aligned in 12 columns.
fn push_e12(out: &mut String, v: f32) {
    if !v.is_finite() {
        let _ = write!(
            out,
            "{:>12}",
            if v.is_nan() {
                "nan".to_string()
            } else if v > 0.0 {
                "inf".to_string()
            } else {
                "-inf".to_string()
            }
        );
        return;
    }
    let s = format!("{v:.5e}");
    let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let sign = if exp < 0 { '-' } else { '+' };
    let _ = write!(out, "{:>12}", format!("{mantissa}e{sign}{:02}", exp.abs()));
}

fn header(out: &mut Out) {
    if out.binary {
        out.string("C Binary");
    }
    out.string("particles written by slosh");
    out.string("EnSight point data");
    out.string("node id assign");
    out.string("element id assign");
}

fn empty_geometry(format: WriteFormat, order: ByteOrder) -> Vec<u8> {
    let mut out = Out::new(format, order);
    header(&mut out);
    if out.gold {
        // One part without nodes: readers (VTK among them) take the byte order of every file
        // of the case from the first integer of the geometry, so there must be one.
        out.string("part");
        out.int(1);
        out.string("empty model; particles are in the measured file");
        out.string("coordinates");
        out.int(0);
    } else {
        out.string("coordinates");
        out.int(0);
    }
    out.finish()
}

fn point_geometry(format: WriteFormat, order: ByteOrder, positions: &[[f32; 3]]) -> Vec<u8> {
    let n = positions.len();
    let mut out = Out::new(format, order);
    header(&mut out);
    if out.gold {
        out.string("part");
        out.int(1);
        out.string("particles");
        out.string("coordinates");
        out.int(n);
        for axis in 0..3 {
            out.floats(positions.iter().map(|p| p[axis]), 1);
        }
    } else {
        out.string("coordinates");
        out.int(n);
        out.floats(positions.iter().flatten().copied(), 3);
        out.string(&format!("part {:7}", 1));
        out.string("particles");
    }
    out.string("point");
    out.int(n);
    out.int_array(1..=n);
    out.finish()
}

fn measured_geometry(format: WriteFormat, order: ByteOrder, positions: &[[f32; 3]]) -> Vec<u8> {
    let n = positions.len();
    let mut out = Out::new(format, order);
    if out.binary {
        out.string("C Binary");
    }
    out.string("particles written by slosh");
    out.string("particle coordinates");
    if out.binary {
        out.int(n);
        for id in 1..=n {
            out.word(id as u32);
        }
        out.floats(positions.iter().flatten().copied(), 3);
    } else {
        let _ = writeln!(out.text, "{n:8}");
        for (i, p) in positions.iter().enumerate() {
            let _ = write!(out.text, "{:8}", i + 1);
            for &c in p {
                push_e12(&mut out.text, c);
            }
            out.text.push('\n');
        }
    }
    out.finish()
}

fn variable_file(
    format: WriteFormat,
    order: ByteOrder,
    placement: Placement,
    var: &VarData<'_>,
) -> Vec<u8> {
    let mut out = Out::new(format, order);
    out.string(var.name());
    let per_part = out.gold && placement == Placement::PointPart;
    if per_part {
        out.string("part");
        out.int(1);
        out.string("coordinates");
    }
    match *var {
        VarData::Scalar(_, v) => out.floats(v.iter().copied(), if per_part { 1 } else { 6 }),
        VarData::Vector(_, v) if per_part => {
            for axis in 0..3 {
                out.floats(v.iter().map(|p| p[axis]), 1);
            }
        }
        VarData::Vector(_, v) => out.floats(v.iter().flatten().copied(), 6),
    }
    out.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn e12_matches_printf() {
        let mut s = String::new();
        for v in [1.0f32, -0.25, 123456.0, 1e-7, 0.0] {
            push_e12(&mut s, v);
        }
        assert_eq!(
            s,
            " 1.00000e+00-2.50000e-01 1.23456e+05 1.00000e-07 0.00000e+00"
        );
    }
}
