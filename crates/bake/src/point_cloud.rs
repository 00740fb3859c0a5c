//! Point clouds from PLY (ASCII or binary) and OBJ files, with normals where the file has them.

use std::path::{Path, PathBuf};

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};

/// Why a point cloud file could not be read: the file and what was wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{}: {what}", path.display())]
pub struct PointCloudError {
    pub path: PathBuf,
    pub what: String,
}

type Result<T> = std::result::Result<T, PointCloudError>;

/// The error `what` about `path`.
fn bad(path: &Path, what: impl Into<String>) -> PointCloudError {
    PointCloudError {
        path: path.to_path_buf(),
        what: what.into(),
    }
}

/// Positions and (unit, or `None` where the file has none) normals.
#[derive(Debug, Default)]
pub struct PointCloud {
    pub positions: Vec<[f64; 3]>,
    pub normals: Option<Vec<[f64; 3]>>,
}

pub fn read_point_cloud(path: &Path) -> Result<PointCloud> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let cloud = match ext.as_deref() {
        Some("ply") => read_ply(path)?,
        Some("obj") => read_obj(path)?,
        _ => return Err(bad(path, "expected a .ply or .obj file")),
    };
    if cloud.positions.is_empty() {
        return Err(bad(path, "no vertices found"));
    }
    if let Some(i) = cloud
        .positions
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(bad(
            path,
            format!(
                "vertex {i} has a non-finite coordinate {:?}",
                cloud.positions[i]
            ),
        ));
    }
    Ok(cloud)
}

fn number(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Float(v) => f64::from(v),
        Property::Double(v) => v,
        Property::Char(v) => f64::from(v),
        Property::UChar(v) => f64::from(v),
        Property::Short(v) => f64::from(v),
        Property::UShort(v) => f64::from(v),
        Property::Int(v) => f64::from(v),
        Property::UInt(v) => f64::from(v),
        _ => return None,
    })
}

fn read_ply(path: &Path) -> Result<PointCloud> {
    let file = std::fs::File::open(path).map_err(|e| bad(path, format!("cannot open: {e}")))?;
    let mut reader = std::io::BufReader::new(file);
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| bad(path, format!("not a readable PLY file: {e}")))?;
    let vertices = ply
        .payload
        .get("vertex")
        .ok_or_else(|| bad(path, "PLY file without a `vertex` element"))?;
    let get = |v: &DefaultElement, k: &str| v.get(k).and_then(number);
    let mut cloud = PointCloud::default();
    let has_normals = vertices
        .first()
        .is_some_and(|v| v.contains_key("nx") && v.contains_key("ny") && v.contains_key("nz"));
    let mut normals = Vec::new();
    for (i, v) in vertices.iter().enumerate() {
        let (Some(x), Some(y), Some(z)) = (get(v, "x"), get(v, "y"), get(v, "z")) else {
            return Err(bad(path, format!("vertex {i} lacks numeric x, y, z")));
        };
        cloud.positions.push([x, y, z]);
        if has_normals {
            normals.push([
                get(v, "nx").unwrap_or(0.0),
                get(v, "ny").unwrap_or(0.0),
                get(v, "nz").unwrap_or(0.0),
            ]);
        }
    }
    if has_normals {
        cloud.normals = Some(normals.into_iter().map(normalise).collect());
    }
    Ok(cloud)
}

fn read_obj(path: &Path) -> Result<PointCloud> {
    let options = tobj::LoadOptions {
        single_index: false,
        triangulate: false,
        ignore_points: false,
        ignore_lines: false,
    };
    let (models, _) = match tobj::load_obj(path, &options) {
        Ok(loaded) => loaded,
        // tobj names no line; where a vertex line is what is wrong, ours does.
        Err(e) => {
            read_obj_vertices(path)?;
            return Err(bad(path, format!("not a readable OBJ file: {e}")));
        }
    };
    // tobj makes models of faces, lines and points only; a scanner's or solver's cloud of
    // bare `v` (and `vn`) lines has none.
    if models.iter().all(|m| m.mesh.positions.is_empty()) {
        return read_obj_vertices(path);
    }
    let mut cloud = PointCloud::default();
    let mut normals: Vec<[f64; 3]> = Vec::new();
    let mut any_normals = false;
    for m in &models {
        let mesh = &m.mesh;
        let base = cloud.positions.len();
        let count = mesh.positions.len() / 3;
        cloud.positions.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|c| [f64::from(c[0]), f64::from(c[1]), f64::from(c[2])]),
        );
        normals.resize(base + count, [0.0; 3]);
        // Face corners pair a vertex index with a normal index; accumulate per vertex.
        if !mesh.normals.is_empty() && mesh.normal_indices.len() == mesh.indices.len() {
            any_normals = true;
            for (&vi, &ni) in mesh.indices.iter().zip(&mesh.normal_indices) {
                let n = &mesh.normals[3 * ni as usize..3 * ni as usize + 3];
                let acc = &mut normals[base + vi as usize];
                for k in 0..3 {
                    acc[k] += f64::from(n[k]);
                }
            }
        } else if !mesh.normals.is_empty() && mesh.normals.len() == mesh.positions.len() {
            any_normals = true;
            for (acc, n) in normals[base..].iter_mut().zip(mesh.normals.chunks_exact(3)) {
                *acc = [f64::from(n[0]), f64::from(n[1]), f64::from(n[2])];
            }
        }
    }
    if any_normals {
        cloud.normals = Some(normals.into_iter().map(normalise).collect());
    }
    Ok(cloud)
}

/// The `v` lines of an OBJ file without elements, and its `vn` lines as their normals where
/// there is one per vertex, in order (how point-cloud exporters write them).
fn read_obj_vertices(path: &Path) -> Result<PointCloud> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| bad(path, format!("not a readable OBJ text file: {e}")))?;
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let list = match words.next() {
            Some("v") => &mut positions,
            Some("vn") => &mut normals,
            _ => continue,
        };
        let values: Vec<f64> = words
            .by_ref()
            .take(3)
            .map(str::parse)
            .collect::<std::result::Result<_, _>>()
            .ok()
            .filter(|v: &Vec<f64>| v.len() == 3)
            .ok_or_else(|| {
                bad(
                    path,
                    format!(
                        "line {}: expected three numbers after '{}', found '{line}'",
                        number + 1,
                        line.split_whitespace().next().unwrap_or_default()
                    ),
                )
            })?;
        list.push([values[0], values[1], values[2]]);
    }
    let normals = match normals.len() {
        0 => None,
        n if n == positions.len() => Some(normals.into_iter().map(normalise).collect()),
        n => {
            return Err(bad(
                path,
                format!(
                    "{} vertices but {n} normals (vn lines) and no faces to pair them: \
                     expected one normal per vertex, in order, or none",
                    positions.len()
                ),
            ));
        }
    };
    Ok(PointCloud { positions, normals })
}

/// Unit length; zero stays zero (the reader of the result decides what a zero normal means).
fn normalise(n: [f64; 3]) -> [f64; 3] {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        [n[0] / len, n[1] / len, n[2] / len]
    } else {
        [0.0; 3]
    }
}
