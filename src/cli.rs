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
    /// Bake an EnSight series (or a PLY/OBJ point cloud) into one .slc cache per step.
    Bake(BakeArgs),
    /// Summarise and verify .slc caches (a step file or a cache directory).
    Inspect(InspectArgs),
    /// Render a frame and its hit buffer from a cache.
    Render(RenderArgs),
    /// Open the player on a cache directory (one a bake may still be filling).
    Play(PlayArgs),
    /// Generate, bake and play a demo series (a sloshing tank with droplets); without a
    /// display, or with --headless, render a short sequence of frames instead.
    Demo(DemoArgs),
    /// Measure speed against error.
    #[command(subcommand)]
    Bench(BenchCommand),
}

/// Where `slosh bake` runs its data-parallel stages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BakeDevice {
    /// A GPU where one is found (a discrete or integrated adapter; not a software rasteriser
    /// such as lavapipe, on which the CPU is faster), else the CPU.
    Auto,
    Cpu,
    Gpu,
}

#[derive(Debug, Args)]
pub struct PlayArgs {
    /// A cache directory written by `slosh bake`, or an EnSight .case file: its steps are
    /// baked as the player needs them, into --cache.
    pub input: PathBuf,
    /// Where a .case file's steps are baked (kept: the next run starts with them). Default:
    /// NAME.slosh beside NAME.case.
    #[arg(long)]
    pub cache: Option<PathBuf>,
    #[command(flatten, next_help_heading = "Baking a .case file (as `slosh bake`)")]
    pub bake: BakeSettings,
    /// GPU adapter whose name contains this.
    #[arg(long)]
    pub adapter: Option<String>,
    /// GPU memory for resident steps, in GiB (default: half the adapter's memory).
    #[arg(long)]
    pub budget: Option<f64>,
    /// Field to colour by: a scalar field, or a vector field's magnitude (its name) or
    /// component (`velocity.x`, `.y`, `.z`).
    #[arg(long)]
    pub field: Option<String>,
    /// Colour range: `series` (the series' range where its manifest records one, else the
    /// widest seen over the steps shown), `step` (each step's own) or `LO,HI` (fixed).
    #[arg(long, default_value = "series", allow_hyphen_values = true)]
    pub field_range: String,
    /// The field's colour map (also in the Colour panel).
    #[arg(long, value_enum, default_value_t = ColormapArg::Viridis)]
    pub colormap: ColormapArg,
    /// Traced pixels per screen pixel, per axis (0.25-2; lower for large screens).
    #[arg(long, default_value_t = 1.0)]
    pub render_scale: f32,
    /// Up axis: x, y or z (default: from the data, else z).
    #[arg(long)]
    pub up: Option<String>,
    /// Iterations refined to when the view is still.
    #[arg(long, default_value_t = 3)]
    pub iterations: u32,
    /// How the surface is shown at the start (the View section switches it).
    #[arg(long, value_enum, default_value_t = ModeArg::Shade)]
    pub mode: ModeArg,
    /// Milliseconds a frame may take on the GPU: while the view moves it is drawn smaller,
    /// and a still view refines in bands of rows, so the window answers on a slow GPU
    /// (0: every frame whole at full size).
    #[arg(long, default_value_t = 33.0)]
    pub frame_budget_ms: f64,
    /// Window size in points, WxH.
    #[arg(long, default_value = "1280x800")]
    pub window: String,
    /// Folder for screenshots and exported frames.
    #[arg(long, default_value = ".")]
    pub output: PathBuf,
    /// Loader threads (default: three eighths of the cores, 2 to 6). A raw case's loaders each
    /// bake a step, on a share of the cores (default: what `slosh bake` would take at once, at
    /// most half the cores).
    #[arg(long)]
    pub loaders: Option<usize>,
    /// Pause every step load this long (tests a frame loop that must not wait on loads).
    #[arg(long, hide = true)]
    pub load_delay_ms: Option<u64>,
    /// Print a line per UI pass and per failed step (for tests driving the window).
    #[arg(long, hide = true)]
    pub log_frames: bool,
}

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Render frames instead of opening the player.
    #[arg(long)]
    pub headless: bool,
    /// Steps in the demo series.
    #[arg(long, default_value_t = 200)]
    pub steps: usize,
    /// Particles per step.
    #[arg(long, default_value_t = 20_000, value_parser = point_count)]
    pub points: usize,
    /// Where the demo lives (default: the user's cache directory, slosh/demo).
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// Frames rendered on the headless path.
    #[arg(long, default_value_t = 12)]
    pub frames: usize,
}

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// CPU MLS accuracy against analytic scenes: error vs cost tables and a plot.
    Accuracy(AccuracyArgs),
    /// Bake stage times against the thesis, bytes per point, section encodings, load times.
    Bake(BakeBenchArgs),
    /// Stored precision: each analytic scene baked in the compact layout and as computed, traced from the
    /// cache against the exact surface and the exact cache, with bytes per point.
    Precision(PrecisionBenchArgs),
    /// GPU frame times (timestamp queries) against the thesis's tables, with upload times and
    /// the error of each setting.
    Gpu(GpuBenchArgs),
    /// Streaming: sequential playback and random jumps through a series on the player's
    /// engine, beside the floors (file reads, raw buffer writes).
    Scrub(ScrubBenchArgs),
}

#[derive(Debug, Args)]
pub struct ScrubBenchArgs {
    /// Markdown report to write.
    #[arg(long, default_value = "docs/results-scrub.md")]
    pub out: PathBuf,
    /// Points per step of each series measured (default 100000,1000000; --quick 2000).
    #[arg(long, value_delimiter = ',', value_parser = point_count)]
    pub points: Vec<usize>,
    /// Steps per series.
    #[arg(long, default_value_t = 64)]
    pub steps: usize,
    /// Distinct baked shapes per series (the moving sphere at that many instants, cycled
    /// over the steps; default: every step up to 200k points, 8 above).
    #[arg(long)]
    pub distinct: Option<usize>,
    /// Frame size.
    #[arg(long, default_value = "1280x800")]
    pub size: String,
    /// Random jumps measured, in the pool and from the page cache each.
    #[arg(long, default_value_t = 100)]
    pub jumps: usize,
    /// Seed of the jumps.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Loader threads of the engine (default: three eighths of the cores, 2 to 6; for a raw
    /// case, as `slosh play CASE.case` has them).
    #[arg(long)]
    pub loaders: Option<usize>,
    /// Pool size in steps for sequential playback and page-cache jumps (so that steps stream
    /// rather than stay resident).
    #[arg(long, default_value_t = 16)]
    pub pool_steps: u64,
    /// Where the series are written (reused when already there with the same shape; one run
    /// at a time holds it).
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// A tiny series and frame (checks the harness; lavapipe-friendly).
    #[arg(long)]
    pub quick: bool,
    /// GPU adapter whose name contains this.
    #[arg(long)]
    pub adapter: Option<String>,
    /// Also jumps from storage: the page cache dropped before each (needs root).
    #[arg(long)]
    pub cold: bool,
    /// Series stored without compression (`bake --compress none`): a load is then a copy.
    #[arg(long)]
    pub raw: bool,
    /// Also each size as a raw EnSight case played with no bake first: every step baked
    /// as the player needs it (sequential playback and jumps to steps not baked yet).
    #[arg(long)]
    pub raw_case: bool,
    /// With --raw-case: find the steps' neighbours on the engine's GPU (`bake --device gpu`).
    #[arg(long)]
    pub raw_case_gpu: bool,
    /// Only the raw EnSight cases (--raw-case without the baked series and their tables),
    /// for a machine whose time is short.
    #[arg(long)]
    pub raw_case_only: bool,
}

#[derive(Debug, Args)]
pub struct GpuBenchArgs {
    /// Markdown report to write.
    #[arg(long, default_value = "docs/results-gpu.md")]
    pub out: PathBuf,
    /// Timed frames per row (median reported), after 10 warm-up frames.
    #[arg(long, default_value_t = 50)]
    pub frames: usize,
    /// Highest iteration count measured (refinement is slow; cap it to bound the run).
    #[arg(long, default_value_t = 5)]
    pub max_iterations: u32,
    /// Small scenes and images only (checks the harness; lavapipe-friendly).
    #[arg(long)]
    pub quick: bool,
    /// The 28k-vertex bunny.obj of the pymeshlab wheel (default: $SLOSH_DATA/bunny.obj).
    #[arg(long)]
    pub bunny: Option<PathBuf>,
    /// Folder for rendered frames of the tank and the bunny (PNG).
    #[arg(long, default_value = "docs/img")]
    pub images: PathBuf,
    /// GPU adapter whose name contains this.
    #[arg(long)]
    pub adapter: Option<String>,
    /// Tables to measure (all by default); the water row needs the tank.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub tables: Vec<BenchTable>,
    /// Point counts of table 4.6 (default 2500,10000,100000,1000000; --quick 2500,10000).
    #[arg(long, value_delimiter = ',', value_parser = point_count)]
    pub points: Vec<usize>,
}

/// A table of `slosh bench gpu`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BenchTable {
    /// Table 4.1: the bunny, iterations 1–5, quadratic and cubic.
    #[value(name = "4.1")]
    Bunny,
    /// Table 4.5: the tank at four image sizes.
    #[value(name = "4.5")]
    Tank,
    /// Figure 4.9: the water shader on the tank.
    #[value(name = "water")]
    Water,
    /// Table 4.6: point counts at 1280×800 (and 1920×1080 from 100k points).
    #[value(name = "4.6")]
    Points,
}

#[derive(Debug, Args)]
pub struct PrecisionBenchArgs {
    /// Markdown report to write.
    #[arg(long, default_value = "docs/results-precision.md")]
    pub out: PathBuf,
    /// Particles per scene.
    #[arg(long, default_value_t = 20_000, value_parser = point_count)]
    pub points: usize,
    /// Image size in pixels (square) of every render.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
}

#[derive(Debug, Args)]
pub struct BakeBenchArgs {
    /// Markdown report to write.
    #[arg(long, default_value = "docs/results-bake.md")]
    pub out: PathBuf,
    /// Runs per size (median reported; 1 at 1M points).
    #[arg(long, default_value_t = 5, value_parser = at_least_one)]
    pub runs: usize,
    /// Only 2.5k and 10k points.
    #[arg(long)]
    pub quick: bool,
    /// Point counts to bake (default 2500,10000,100000,1000000; --quick 2500,10000).
    #[arg(long, value_delimiter = ',', value_parser = point_count)]
    pub points: Vec<usize>,
    /// Thread counts of the scaling table: each size baked on a pool of each (default 1, 2
    /// and every core).
    #[arg(long, value_delimiter = ',', value_parser = at_least_one)]
    pub threads: Vec<usize>,
    /// Steps of the series baked through the batch driver per size, against one step alone
    /// (0 skips it).
    #[arg(long, default_value_t = 8)]
    pub series: usize,
    /// Leave out the bakes with the GPU's neighbour search (by default each size is also
    /// baked so, where an adapter opens).
    #[arg(long)]
    pub no_gpu: bool,
    /// The adapter for the GPU column: the first whose name contains this.
    #[arg(long)]
    pub adapter: Option<String>,
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
    /// Real SPH cases to compare with splashsurf: a directory of case directories, each from
    /// `scripts/sph_reference.py` (particles.ply, splashsurf.ply, meta.json).
    #[arg(long)]
    pub sph: Option<PathBuf>,
    /// Only the SPH comparison (needs --sph).
    #[arg(long, requires = "sph")]
    pub sph_only: bool,
    /// Also write the measurements as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write each SPH case as a small fixture under this directory (particles, meta and the
    /// reference's ray depths instead of its mesh), then stop.
    #[arg(long, requires = "sph")]
    pub sph_fixture: Option<PathBuf>,
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
    /// sphere, torus, ellipsoid, tank, droplets, wave, sheet, plane, or from-file.
    pub scene: String,
    /// The PLY or OBJ file, for `from-file`.
    pub input: Option<PathBuf>,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Particles of the main body (droplets and hard-case extras come on top).
    #[arg(long, default_value_t = 10_000, value_parser = point_count)]
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
    /// Translate everything (truth included) by this in x, y and z, e.g. 1e5 or -1.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
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

/// How a step is baked: `slosh bake`'s settings, and `slosh play`'s for a raw case.
#[derive(Debug, Clone, Args)]
pub struct BakeSettings {
    #[command(flatten)]
    pub fit: FitSettings,
    #[command(flatten)]
    pub select: SelectSettings,
}

/// How the MLS surface is fitted to the particles.
#[derive(Debug, Clone, Args)]
pub struct FitSettings {
    /// Polynomial degree of the fits.
    #[arg(long, default_value_t = 2)]
    pub degree: u8,
    /// Radius of trust = distance to the k-th nearest neighbour.
    #[arg(long, default_value_t = 6)]
    pub k: usize,
    /// h = h-scale × the dense fluid's radius of trust (its median).
    #[arg(long, default_value_t = 1.5)]
    pub h_scale: f64,
    /// At most this many neighbours per point.
    #[arg(long, default_value_t = 128)]
    pub neighbour_cap: usize,
    /// One h per point (h-scale × its radius) instead of a global h: for uneven sampling.
    #[arg(long)]
    pub per_point_h: bool,
    /// Clusters with fewer points (or no wider than h) are spray, drawn as spheres (default:
    /// the coefficient count of the degree, 6 or 10; 0 turns detection off).
    #[arg(long)]
    pub droplet_below: Option<usize>,
    /// Draw the surface this many particle radii (half the median particle spacing) outside
    /// the MLS surface through the particles: for particles that fill the fluid's volume
    /// (SPH), whose free surface lies outside the outer centres. Default: 0.75 with
    /// --surface estimate, else 0 (particles on the surface, as FPM's).
    #[arg(long)]
    pub surface_offset: Option<f64>,
}

/// Which particles and variables a bake reads, how it stores them, and where it finds their
/// neighbours.
#[derive(Debug, Clone, Args)]
pub struct SelectSettings {
    /// Where each step's data-parallel stages run: a GPU through Vulkan (the surface
    /// estimate's neighbours, kNN and radii, neighbour lists, initial fits and the BVH's
    /// tree; the same selection and lists where no distances tie, docs/bake.md; the other
    /// stages stay on the CPU for now), or the CPU. `auto` takes a GPU where one is found (a
    /// discrete or integrated adapter, not a software one such as lavapipe) and k allows, or
    /// the one --adapter names.
    #[arg(long, value_enum, default_value_t = BakeDevice::Auto)]
    pub device: BakeDevice,
    /// Surface particles: a flag variable's name, `estimate`, or `all` (default: the variable
    /// `surface` if the case has one, else all).
    #[arg(long)]
    pub surface: Option<String>,
    /// Normals: a vector variable's name, `pca` (none: support planes from the covariance) or
    /// `estimate` (outward, from the neighbourhoods of all particles; for SPH output). Default:
    /// `normal` or `normals` if present, else estimate with --surface estimate, else pca.
    #[arg(long)]
    pub normals: Option<String>,
    /// Variables to store per point, comma separated (scalars, and vectors, which the
    /// renderers colour by magnitude or component).
    #[arg(long, value_delimiter = ',')]
    pub fields: Vec<String>,
    /// zstd level (-7 to 22; negative levels are zstd's fast ones) or `none`. The default,
    /// -1, decodes 1.4–1.7× faster than level 1 for 5–8 % more bytes
    /// (`docs/cache-format.md`).
    #[arg(long, default_value = "-1", allow_hyphen_values = true)]
    pub compress: String,
    /// Force the byte order of binary EnSight files instead of detecting it.
    #[arg(long, value_enum)]
    pub byte_order: Option<ByteOrderArg>,
}

/// A count of particles a generated scene can have: 1 to [`slosh_scenes::MAX_POINTS`].
fn point_count(s: &str) -> Result<usize, String> {
    let n: usize = s
        .parse()
        .map_err(|_| format!("expected a count of points, found '{s}'"))?;
    if n == 0 || n > slosh_scenes::MAX_POINTS {
        return Err(format!(
            "expected 1 to {} points, found {n}",
            slosh_scenes::MAX_POINTS
        ));
    }
    Ok(n)
}

/// A count of at least one (runs, threads).
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse() {
        Ok(0) => Err("expected at least 1, found 0".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("expected a whole number, found '{s}'")),
    }
}

/// A flag group with every flag at its default, as a command line without them parses.
fn flag_defaults<T: Args + clap::FromArgMatches>() -> T {
    let command = T::augment_args(clap::Command::new("slosh"));
    T::from_arg_matches(&command.get_matches_from(["slosh"])).unwrap_or_else(|e| e.exit())
}

impl Default for BakeSettings {
    fn default() -> BakeSettings {
        flag_defaults()
    }
}

impl Default for FitSettings {
    fn default() -> FitSettings {
        flag_defaults()
    }
}

#[derive(Debug, Args)]
pub struct BakeArgs {
    /// The .case file, a .ply/.obj point cloud, or with --manifest-only the cache directory.
    pub input: PathBuf,
    /// Output directory for step-NNNNN.slc files and manifest.json.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Steps to bake: A..B (B excluded), A..=B (B included) or N, e.g. 0..50.
    #[arg(long)]
    pub steps: Option<String>,
    /// Steps baked at once (each is also parallel inside). Default: half the cores (three
    /// for every two cores where the stages run on a GPU, within half its memory), within
    /// three quarters of the memory available, for the first step's size.
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Bake only shard I of N (0-based), e.g. 2/8 for task 2 of a job array, or `slurm`: this
    /// task's shard of a SLURM job array (docs/slurm.md).
    #[arg(long)]
    pub shard: Option<String>,
    #[command(flatten)]
    pub settings: BakeSettings,
    /// The GPU adapter whose name contains this (with --device auto or gpu; default: the best
    /// one). Naming one asks for the GPU: with --device auto, no CPU fallback.
    #[arg(long)]
    pub adapter: Option<String>,
    /// Rebuild manifest.json from the step files in the directory, bake nothing.
    #[arg(long)]
    pub manifest_only: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct InspectArgs {
    /// A step file (.slc) or a cache directory.
    pub path: PathBuf,
    /// Machine-readable output (schema in docs/inspect-json.md).
    #[arg(long)]
    pub json: bool,
    /// Check every checksum and structural invariant; exit non-zero on any failure.
    #[arg(long)]
    pub verify: bool,
    /// Dump the record of point I (cache order) of a step file.
    #[arg(long)]
    pub point: Option<usize>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Blinn–Phong (coloured by --field if given).
    Shade,
    /// Normals as colours.
    Normals,
    /// Status and iteration heat map: green converged, yellow iteration limit, red no
    /// support or degenerate fit, blue droplet; brighter for more iterations.
    Status,
    /// Back-facing hits in magenta.
    Backfaces,
    /// Water over a checkerboard floor: reflection, refraction and shadows by secondary rays
    /// (GPU only).
    Water,
}

impl From<ModeArg> for slosh_render::ShadeMode {
    fn from(mode: ModeArg) -> Self {
        match mode {
            ModeArg::Shade => Self::Shade,
            ModeArg::Normals => Self::Normals,
            ModeArg::Status => Self::Status,
            ModeArg::Backfaces => Self::Backfaces,
            ModeArg::Water => Self::Water,
        }
    }
}

/// A field's colour map (`--colormap`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ColormapArg {
    /// Sequential, perceptually uniform.
    Viridis,
    /// Diverging blue–grey–red (Moreland), for signed fields such as pressure around zero.
    Coolwarm,
    Grey,
}

impl From<ColormapArg> for slosh_render::Colormap {
    fn from(map: ColormapArg) -> Self {
        match map {
            ColormapArg::Viridis => Self::Viridis,
            ColormapArg::Coolwarm => Self::CoolWarm,
            ColormapArg::Grey => Self::Grey,
        }
    }
}

/// `slosh render`'s vertical field of view unless `--fov` says otherwise, in degrees.
pub const DEFAULT_FOV: f64 = 40.0;

#[derive(Debug, Args)]
pub struct RenderArgs {
    /// A cache directory, one step file, or an EnSight .case file: the steps rendered are
    /// baked first, into --cache (kept for the next run), with the default fit.
    pub path: PathBuf,
    /// Where a .case file's steps are baked. Default: NAME.slosh beside NAME.case.
    #[arg(long)]
    pub cache: Option<PathBuf>,
    #[command(flatten, next_help_heading = "Baking a .case file (as `slosh bake`)")]
    pub bake: SelectSettings,
    /// Step index (cache directories).
    #[arg(long, default_value_t = 0)]
    pub step: usize,
    /// A range of steps, A..B (B excluded) or A..=B, for a video: --out and --aov then take
    /// a pattern with {} or {:05} for the step number. One camera frames every step of it.
    /// Not with --step.
    #[arg(long, conflicts_with = "step")]
    pub steps: Option<String>,
    /// Camera position X,Y,Z (default: framing the step's bounds).
    #[arg(long, allow_hyphen_values = true)]
    pub eye: Option<String>,
    #[arg(long, allow_hyphen_values = true)]
    pub target: Option<String>,
    #[arg(long, allow_hyphen_values = true)]
    pub up: Option<String>,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = DEFAULT_FOV)]
    pub fov: f64,
    /// Image size WxH.
    #[arg(long, default_value = "640x480")]
    pub size: String,
    /// MLS iterations, counting the precomputed polynomial.
    #[arg(long, default_value_t = 1)]
    pub iterations: u32,
    #[arg(long, value_enum, default_value_t = ModeArg::Shade)]
    pub mode: ModeArg,
    /// PNG to write, or a movie: NAME.mp4 (H.264), one frame per step of --steps.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// A movie's frame rate (default: the series' own times, in real time).
    #[arg(long, conflicts_with = "slowdown")]
    pub fps: Option<f64>,
    /// A movie timed by the series' times, this many times slower than simulated.
    #[arg(long)]
    pub slowdown: Option<f64>,
    /// Hit buffer to write: float32 H×W×8 .npy (position xyz, normal xyz, t, status; 0 = miss).
    #[arg(long)]
    pub aov: Option<PathBuf>,
    /// Trace on the CPU with the reference tracer.
    #[arg(long)]
    pub cpu: bool,
    /// Degree of the refinement fits (default: the degree the cache was baked with).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=3))]
    pub degree: Option<u8>,
    /// Smoothing length scale for refinement, as h = SCALE × mean radius (default: as baked).
    #[arg(long)]
    pub h_scale: Option<f64>,
    /// Support normals from the weighted covariance instead of the data normals.
    #[arg(long)]
    pub covariance: bool,
    /// Colour the surface by this baked field: a scalar field, or a vector
    /// field's magnitude (its name) or component (`velocity.x`, `.y`, `.z`). Values that are not finite are
    /// left out of the colour; a hit that finds none is drawn magenta (a refined frame
    /// weighs its ball's neighbours' values, a one-iteration frame reads the ball's own).
    #[arg(long)]
    pub field: Option<String>,
    /// The field's colour range: `series` (the widest over the steps drawn, so that a colour
    /// means one value through a movie), `step` (each step's own) or `LO,HI` (fixed).
    #[arg(long, default_value = "series", allow_hyphen_values = true)]
    pub field_range: String,
    /// The field's colour map.
    #[arg(long, value_enum, default_value_t = ColormapArg::Viridis)]
    pub colormap: ColormapArg,
    /// Draw the step's time and, with --field, the colour legend into the frames.
    #[arg(long)]
    pub labels: bool,
    /// GPU adapter whose name contains this (default: the best one wgpu finds).
    #[arg(long)]
    pub adapter: Option<String>,
}
