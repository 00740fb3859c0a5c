//! Command-line flags as parsed; `config` turns them into validated settings.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

#[derive(Debug, Parser)]
#[command(
    name = "slosh",
    version,
    about = "Ray traced MLS surfaces for particle simulation time series"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Write a synthetic EnSight scene with exact ground truth (truth.json), or convert a PLY/OBJ
    /// point cloud (`slosh gen from-file bunny.obj --out DIR`).
    Gen(GenArgs),
    /// Print what an EnSight case holds.
    Info(InfoArgs),
    /// Measure speed against error.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// CPU MLS accuracy against analytic scenes: error vs cost tables and a plot.
    Accuracy(AccuracyArgs),
}

#[derive(Debug, Args)]
pub struct AccuracyArgs {
    /// Markdown report to write.
    #[arg(long, default_value = "docs/accuracy.md")]
    pub out: PathBuf,
    /// PNG plot of error against cost.
    #[arg(long, default_value = "docs/img/accuracy.png")]
    pub plot: PathBuf,
    /// Image size in pixels (square) of every render.
    #[arg(long, default_value_t = 96)]
    pub size: u32,
    /// A small, fast run (fewer scenes and configurations) to check the harness itself.
    #[arg(long)]
    pub quick: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    E6Ascii,
    E6Binary,
    GoldAscii,
    GoldBinary,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ByteOrderArg {
    Little,
    Big,
}

#[derive(Debug, Args)]
pub struct GenArgs {
    /// sphere, torus, ellipsoid, tank, droplets, sheet, plane, or from-file.
    pub scene: String,
    /// The PLY or OBJ file, for `from-file`.
    pub input: Option<PathBuf>,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Particles of the main body (droplets and hard-case extras come on top).
    #[arg(long, default_value_t = 10_000)]
    pub points: usize,
    #[arg(long, default_value_t = 10)]
    pub steps: usize,
    /// Seconds between steps.
    #[arg(long, default_value_t = 0.05)]
    pub dt: f64,
    #[arg(long, value_enum, default_value_t = FormatArg::E6Binary)]
    pub format: FormatArg,
    /// Byte order of binary output.
    #[arg(long, value_enum, default_value_t = ByteOrderArg::Little)]
    pub byte_order: ByteOrderArg,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write particles as measured particles instead of a `point` part.
    #[arg(long)]
    pub measured: bool,
    /// Ballistic droplets (the droplets scene defaults to 40).
    #[arg(long)]
    pub droplets: Option<usize>,
    /// Position noise, σ as a fraction of the mean spacing.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Fraction of normals reversed.
    #[arg(long, default_value_t = 0.0)]
    pub flip_normals: f64,
    /// Translate everything (truth included) by this in x, y and z, e.g. 1e5.
    #[arg(long, default_value_t = 0.0)]
    pub offset: f64,
    /// Fraction of points duplicated exactly.
    #[arg(long, default_value_t = 0.0)]
    pub duplicates: f64,
    /// Fraction of normals made NaN or zero.
    #[arg(long, default_value_t = 0.0)]
    pub bad_normals: f64,
    /// Points on an isolated straight segment.
    #[arg(long, default_value_t = 0)]
    pub collinear: usize,
    /// Points on an isolated flat patch.
    #[arg(long, default_value_t = 0)]
    pub coplanar: usize,
    /// Density ratio between the scene's two halves (e.g. 100).
    #[arg(long, default_value_t = 0.0)]
    pub density_jump: f64,
    /// Add one point far from everything.
    #[arg(long)]
    pub isolated: bool,
}

#[derive(Debug, Args)]
pub struct InfoArgs {
    /// The .case file.
    pub case: PathBuf,
    /// Machine-readable output (schema in docs/info-json.md).
    #[arg(long)]
    pub json: bool,
    /// Force the byte order of binary files instead of detecting it.
    #[arg(long, value_enum)]
    pub byte_order: Option<ByteOrderArg>,
}
