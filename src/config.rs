//! Validated settings built from parsed flags: every check on user input happens here, once.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use slosh_ensight::{ByteOrder, Placement, WriteFormat};
use slosh_scenes::{HardCases, SceneKind, SceneSpec};

use crate::cli::{ByteOrderArg, FormatArg, GenArgs};

impl From<ByteOrderArg> for ByteOrder {
    fn from(b: ByteOrderArg) -> Self {
        match b {
            ByteOrderArg::Little => ByteOrder::Little,
            ByteOrderArg::Big => ByteOrder::Big,
        }
    }
}

impl From<FormatArg> for WriteFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::E6Ascii => WriteFormat::E6Ascii,
            FormatArg::E6Binary => WriteFormat::E6Binary,
            FormatArg::GoldAscii => WriteFormat::GoldAscii,
            FormatArg::GoldBinary => WriteFormat::GoldBinary,
        }
    }
}

/// What `slosh gen` writes.
#[derive(Debug)]
pub enum GenSource {
    Scene { spec: SceneSpec, steps: usize },
    File(PathBuf),
}

#[derive(Debug)]
pub struct GenConfig {
    pub source: GenSource,
    pub out: PathBuf,
    pub format: WriteFormat,
    pub byte_order: ByteOrder,
    pub placement: Placement,
}

impl GenConfig {
    pub fn from_args(a: &GenArgs) -> Result<GenConfig> {
        let source = if a.scene == "from-file" {
            let input = a
                .input
                .clone()
                .context("`slosh gen from-file` needs the PLY or OBJ file to convert")?;
            GenSource::File(input)
        } else {
            if a.input.is_some() {
                bail!("a file argument only goes with `from-file`");
            }
            let kind: SceneKind = a.scene.parse().map_err(anyhow::Error::msg)?;
            if a.steps == 0 {
                bail!("--steps must be at least 1");
            }
            let mut spec = SceneSpec::new(kind, a.points, a.seed);
            spec.dt = a.dt;
            if let Some(d) = a.droplets {
                if !matches!(kind, SceneKind::Tank | SceneKind::Droplets) {
                    bail!("--droplets applies to the tank and droplets scenes");
                }
                spec.droplets = d;
            }
            spec.hard = HardCases {
                noise: a.noise,
                flip_normals: a.flip_normals,
                offset: a.offset,
                duplicates: a.duplicates,
                bad_normals: a.bad_normals,
                collinear: a.collinear,
                coplanar: a.coplanar,
                density_jump: a.density_jump,
                isolated: a.isolated,
            };
            GenSource::Scene {
                spec,
                steps: a.steps,
            }
        };
        Ok(GenConfig {
            source,
            out: a.out.clone(),
            format: a.format.into(),
            byte_order: a.byte_order.into(),
            placement: if a.measured {
                Placement::Measured
            } else {
                Placement::PointPart
            },
        })
    }
}
