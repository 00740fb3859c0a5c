//! What `slosh bench bake` measured, row by row, and its markdown.

use std::fmt::Write as _;

use super::{STAGE_COLUMNS, Settings};
use crate::report::Report;

/// One size's bake by stage, beside the bare core and the thesis (seconds).
#[derive(Debug, Clone, PartialEq)]
pub struct StageRow {
    pub points: usize,
    /// kNN + radii, neighbour lists, initial fits, droplets, BVH, order + sections, encode.
    pub stages: [f64; 7],
    pub total: f64,
    pub bare: f64,
    /// The thesis's kNN, MLS and total seconds for this size, where it has them.
    pub thesis: Option<(f64, f64, f64)>,
}

/// One size beside splashsurf: slosh's seconds, and the peer's seconds and triangles where
/// it ran.
#[derive(Debug, Clone, PartialEq)]
pub struct PeerRow {
    pub points: usize,
    pub total: f64,
    pub peer: Option<(f64, u64)>,
    /// The same step baked with the GPU's neighbour search, where an adapter opened.
    pub gpu: Option<GpuBakeRow>,
}

/// A bake with the GPU's neighbour search beside the CPU's (seconds, medians of the same
/// alternating runs).
#[derive(Debug, Clone, PartialEq)]
pub struct GpuBakeRow {
    pub total: f64,
    /// The size's first GPU step (seconds), before the runs: the pools' buffers made.
    pub first: f64,
    /// Its neighbour lists by part.
    pub first_list_parts: Vec<(String, f64)>,
    /// The GPU's own time in the bake (timestamp queries of its passes), where the device
    /// has timestamps.
    pub gpu_time: Option<f64>,
    /// kNN and radii, neighbour lists, initial fits, the BVH: with the GPU's stages, then in
    /// the CPU bake of the same runs.
    pub nearest: f64,
    pub lists: f64,
    pub fits: f64,
    /// The BVH (leaves on the CPU, tree on the GPU), beside the fits.
    pub bvh: f64,
    pub cpu_nearest: f64,
    pub cpu_lists: f64,
    pub cpu_fits: f64,
    pub cpu_bvh: f64,
    /// The GPU bake's stages that ran on the CPU, by name, in its order.
    pub on_cpu: Vec<(String, f64)>,
    /// The kNN and radii by part ("kd-tree and radii (kNN): …"), in their order.
    pub knn_parts: Vec<(String, f64)>,
    /// The GPU's neighbour lists by part ("neighbour lists: …"), in its order.
    pub list_parts: Vec<(String, f64)>,
    /// The initial fits by part ("initial fits: …"), in their order.
    pub fit_parts: Vec<(String, f64)>,
    /// The sections by part ("sections: …"), in their order.
    pub section_parts: Vec<(String, f64)>,
    /// The GPU time by pass (timestamp queries), in the order the passes first ran; empty
    /// where the device has no timestamps.
    pub gpu_passes: Vec<(String, f64)>,
}

/// One size's stored bytes: the file, and each section's stored and raw bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct SizeRow {
    pub points: usize,
    pub file_bytes: u64,
    pub sections: Vec<(String, u64, u64)>,
}

/// One size's load times from the page cache (seconds).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadRow {
    pub points: usize,
    pub open: f64,
    pub load: f64,
    /// Raw bytes of every section.
    pub raw_bytes: u64,
    pub load_uncompressed: f64,
    pub verify: f64,
    pub cpu_ready: f64,
}

/// One section under one encoding: sizes and single-thread seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodingRow {
    pub section: String,
    pub raw_bytes: usize,
    pub encoding: String,
    pub chosen: bool,
    pub stored_bytes: usize,
    pub compress: f64,
    pub decompress: f64,
}

/// One size on one thread count: each `STAGE_COLUMNS` stage and the total (seconds), and
/// the total on the fewest threads.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalingRow {
    pub points: usize,
    pub threads: usize,
    pub stages: Vec<f64>,
    pub total: f64,
    pub fewest_threads_total: f64,
}

/// One size's series through the batch driver, beside one step alone (seconds).
#[derive(Debug, Clone, PartialEq)]
pub struct SeriesRow {
    /// Where the neighbours and fits were found: "cpu", or "gpu" (`--device gpu`).
    pub device: &'static str,
    pub points: usize,
    pub jobs: usize,
    pub wall: f64,
    pub per_step: f64,
    pub one_step: f64,
}

/// What `slosh bench bake` measured.
#[derive(Debug, Clone)]
pub struct BakeReport {
    pub settings: Settings,
    /// rayon's threads, and the machine's cores.
    pub threads: usize,
    pub cores: usize,
    pub stages: Vec<StageRow>,
    pub peers: Vec<PeerRow>,
    pub sizes: Vec<SizeRow>,
    pub loads: Vec<LoadRow>,
    /// The size whose sections the encodings table measures.
    pub encodings_points: usize,
    pub encodings: Vec<EncodingRow>,
    pub scaling: Vec<ScalingRow>,
    pub series: Vec<SeriesRow>,
    pub volume: Vec<VolumeRow>,
}

/// A block of fluid particles baked with `--surface estimate` (seconds, medians of the same
/// alternating runs).
#[derive(Debug, Clone, PartialEq)]
pub struct VolumeRow {
    pub particles: usize,
    /// Particles the estimate kept on the surface.
    pub surface: usize,
    /// The whole bake and its selection (the estimate), on the CPU and with the GPU's stages.
    pub cpu: (f64, f64),
    pub gpu: Option<(f64, f64)>,
}

impl BakeReport {
    /// The volume rows: particles filling a block, the surface estimated.
    fn volume_markdown(&self) -> String {
        let mut md = String::from(
            "\n## Particles filling a volume (`--surface estimate`)\n\n\
             A block of fluid particles (a jittered lattice), baked as SPH or FPM output is: \
             the surface and its normals estimated from every particle's 24 nearest, on the \
             CPU and with the GPU's stages (which find those neighbours too); medians of the \
             same alternating runs.\n\n\
             | particles | on the surface | CPU bake | GPU bake | speed-up | estimate CPU / GPU |\n\
             |---|---|---|---|---|---|\n",
        );
        let ms = |s: f64| format!("{:.1} ms", s * 1e3);
        for r in &self.volume {
            let (gpu, speedup, estimate) = match r.gpu {
                Some((total, select)) => (
                    ms(total),
                    format!("{:.2}×", r.cpu.0 / total),
                    format!("{} / {}", ms(r.cpu.1), ms(select)),
                ),
                None => ("—".into(), "—".into(), format!("{} / —", ms(r.cpu.1))),
            };
            let _ = writeln!(
                md,
                "| {} | {} | {} | {gpu} | {speedup} | {estimate} |",
                r.particles,
                r.surface,
                ms(r.cpu.0)
            );
        }
        md.push('\n');
        md
    }

    /// The table of bakes with the GPU's stages, or why it was not measured.
    fn gpu_markdown(&self) -> String {
        let mut md = String::from("\n## With the GPU's stages (`--device gpu`)\n\n");
        let adapter = match &self.settings.gpu {
            Ok(search) => search.gpu().describe(),
            Err(why) => {
                let _ = writeln!(md, "Not measured: {why}.");
                return md;
            }
        };
        let _ = writeln!(
            md,
            "`slosh bake --device gpu`: the kNN, radii, neighbour lists, initial fits and the \
             BVH's tree on {adapter} (`crates/gpubake`; each stage's time includes its transfers \
             and host work, the BVH's its leaves, built on the CPU), everything else on the \
             CPU's {} threads; each run alternates with the CPU bake above. splashsurf as \
             above.\n\n\
             *GPU time* is the passes' own (timestamp queries), which the stages' wall times \
             include with their transfers and host work. The BVH is built beside the initial \
             fits, so the stages add up to more than the bake. *First step* is each size's \
             first GPU bake, before the runs: it makes the buffers the later steps of a series \
             find made.\n\n\
             | points | CPU bake | GPU bake | speed-up | first step | GPU time | kNN + radii CPU / GPU | \
             neighbour lists CPU / GPU | initial fits CPU / GPU | BVH CPU / GPU | against splashsurf |\n\
             |---|---|---|---|---|---|---|---|---|---|---|",
            self.threads
        );
        let ms = |s: f64| format!("{:.1} ms", s * 1e3);
        let rows: Vec<(usize, &GpuBakeRow)> = self
            .peers
            .iter()
            .filter_map(|r| r.gpu.as_ref().map(|g| (r.points, g)))
            .collect();
        for r in &self.peers {
            let Some(g) = &r.gpu else { continue };
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.2}× | {} | {} | {} / {} | {} / {} | {} / {} | {} / {} | {} |",
                r.points,
                ms(r.total),
                ms(g.total),
                r.total / g.total,
                ms(g.first),
                g.gpu_time.map_or("no timestamps".into(), ms),
                ms(g.cpu_nearest),
                ms(g.nearest),
                ms(g.cpu_lists),
                ms(g.lists),
                ms(g.cpu_fits),
                ms(g.fits),
                ms(g.cpu_bvh),
                ms(g.bvh),
                r.peer
                    .map_or("—".into(), |(s, _)| format!("{:.1}× faster", s / g.total)),
            );
        }
        // The stages the GPU bake still runs on the CPU, as its runs measured them, and the
        // GPU lists by part.
        stage_table(
            &mut md,
            "The GPU bake's stages still on the CPU (wall time, medians of the same runs):",
            &rows,
            |g| &g.on_cpu,
        );
        stage_table(
            &mut md,
            "The GPU bake's kNN and radii by part (wall time, medians of the same runs; \
             *points* the points recentred, *index* sorted into cells and uploaded, *nearest* \
             the nearest points found and read back, *radii* their distances in f64):",
            &rows,
            |g| &g.knn_parts,
        );
        stage_table(
            &mut md,
            "The GPU bake's neighbour lists by part (wall time, medians of the same runs; \
             *reaches* h and each list's reach from the radii, *write* is the passes until the lists are on the GPU, the initial fits taken out, \
             *read back* the lists copied to the host, *links and reach* their marks taken out \
             on the CPU):",
            &rows,
            |g| &g.list_parts,
        );
        stage_table(
            &mut md,
            "The same parts in each size's first step (one run):",
            &rows,
            |g| &g.first_list_parts,
        );
        stage_table(
            &mut md,
            "The GPU bake's initial fits by part (wall time, medians of the same runs; *on \
             the GPU* from the lists written until the fits are done, *read back* the fits \
             copied to the host, *balls* made from them, beside the BVH's leaves):",
            &rows,
            |g| &g.fit_parts,
        );
        stage_table(
            &mut md,
            "The GPU bake's sections by part (wall time, medians of the same runs; *balls* the \
             fits in the stored layout, *cluster lists* the union of each cluster's neighbour \
             lists, *points* positions with radii and reaches as stored, *arrays* the sections' \
             bytes copied out and the fields):",
            &rows,
            |g| &g.section_parts,
        );
        stage_table(
            &mut md,
            "The GPU time by pass (timestamp queries, medians of the same runs; *lists: cut* \
             where the cap cuts each list, *lists: write* the lists written, *initial fits* \
             fitted where the lists are, *cluster unions* counted then written):",
            &rows,
            |g| &g.gpu_passes,
        );
        md.push('\n');
        md
    }
}

/// A table of named stage times per size: the first row's names as columns, each in ms.
fn stage_table(
    md: &mut String,
    intro: &str,
    rows: &[(usize, &GpuBakeRow)],
    stages: impl Fn(&GpuBakeRow) -> &[(String, f64)],
) {
    let Some((_, first)) = rows.first() else {
        return;
    };
    let names: Vec<&str> = stages(first).iter().map(|(n, _)| n.as_str()).collect();
    if names.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "\n{intro}\n\n| points | {} |\n|---|{}",
        names.join(" | "),
        "---|".repeat(names.len())
    );
    for (points, g) in rows {
        let cells: Vec<String> = names
            .iter()
            .map(|name| {
                stages(g)
                    .iter()
                    .find(|(n, _)| n == name)
                    .map_or("—".into(), |(_, s)| format!("{:.1} ms", s * 1e3))
            })
            .collect();
        let _ = writeln!(md, "| {points} | {} |", cells.join(" | "));
    }
}

impl Report for BakeReport {
    fn markdown(&self) -> String {
        let args = &self.settings;
        let mut md = String::new();
        let threads = self.threads;
        let _ = writeln!(
            md,
            "# Bake speed, size and load time\n\nWritten by `slosh bench bake{}` on this machine ({threads} threads). \
             Point sets are sphere surfaces with normals from `crates/scenes` (every particle a surface particle); \
             default parameters (k 6, h-scale 1.5, neighbour cap 128, quadratic, zstd level 1). Times are medians of \
             {} runs (1 at 1M points), wall clock; the bare baseline and the bake alternate run by run so that \
             their ratio compares like with like on this shared machine.\n",
            if args.quick { " --quick" } else { "" },
            args.runs
        );
        let _ = writeln!(md, "## Stages per step\n");
        let _ = writeln!(
            md,
            "| points | read | kNN + radii | neighbour lists | initial fits | droplets | BVH | order + sections | compress + encode | **total** | bare kNN + lists + fits | total / bare | thesis kNN | thesis MLS | thesis total | speed-up |"
        );
        let _ = writeln!(
            md,
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        );
        let ms = |s: f64| format!("{:.1} ms", s * 1e3);
        for r in &self.stages {
            let [knn, lists, fits, droplets, bvh, sections, encode] = r.stages;
            let _ = writeln!(
                md,
                "| {} | (in memory) | {} | {} | {} | {} | {} | {} | {} | **{}** | {} | {:.2} | {} | {} | {} | {} |",
                r.points,
                ms(knn),
                ms(lists),
                ms(fits),
                ms(droplets),
                ms(bvh),
                ms(sections),
                ms(encode),
                ms(r.total),
                ms(r.bare),
                r.total / r.bare,
                r.thesis.map_or("".into(), |t| format!("{:.3} s", t.0)),
                r.thesis.map_or("".into(), |t| format!("{:.3} s", t.1)),
                r.thesis.map_or("".into(), |t| format!("{:.3} s", t.2)),
                r.thesis
                    .map_or("".into(), |t| format!("{:.0}×", t.2 / r.total)),
            );
        }
        let mut peer_rows = String::new();
        for r in &self.peers {
            let n = r.points;
            let rate = |s: f64| format!("{:.0}k", n as f64 / s / 1e3);
            let _ = match r.peer {
                Some((seconds, triangles)) => writeln!(
                    peer_rows,
                    "| {n} | {:.3} s | {} | {seconds:.3} s ({triangles} triangles) | {} | {:.2}× |",
                    r.total,
                    rate(r.total),
                    rate(seconds),
                    seconds / r.total
                ),
                None => writeln!(
                    peer_rows,
                    "| {n} | {:.3} s | {} | not run: python3 cannot import pysplashsurf (pip install pysplashsurf==0.14.1) | — | — |",
                    r.total,
                    rate(r.total)
                ),
            };
        }
        let _ = writeln!(
            md,
            "\n*bare* is `Surface::build` alone (kiddo kNN and radii, neighbour lists, initial fits) in the same run; \
             *total* adds selection, recentring, Morton order, droplets, BVH and section encoding (compression included). \
             The thesis's rows are its table 4.7 (sloshing tank, 50 nearest neighbours, quadratic; 2012 CPU), \
             its *total* including its OptiX scene graph and context compilation, which slosh does not need: \
             a slosh step is ready when its sections are decoded (next table).\n"
        );
        let _ = writeln!(
            md,
            "## Beside the peer: splashsurf on the same particles and cores\n\n\
             splashsurf (pysplashsurf 0.14.1, the field's standard SPH surface reconstruction) turns the same sphere particles \
             into a triangle mesh on the same machine and threads: particle radius half the mean spacing, smoothing length 2r, \
             marching-cubes cells 0.5r, iso 0.6 (given in particle radii, which pysplashsurf takes despite its docstring). The \
             jobs differ (a memory-mappable cache of MLS balls and a BVH against a mesh), but each is the step that turns a \
             step's particles into a viewable surface. Medians as above; the peer runs in its own process after slosh.\n\n\
             | points | slosh bake | slosh points/s | splashsurf | splashsurf points/s | slosh faster by |\n|---|---|---|---|---|---|\n{peer_rows}"
        );
        md += &self.gpu_markdown();
        md += &self.volume_markdown();
        md += &self.scaling_markdown();
        md += &self.series_markdown();
        let mut size_rows = String::new();
        for r in &self.sizes {
            let per = |b: u64| b as f64 / r.points as f64;
            let mut cells = String::new();
            for (name, stored, raw) in &r.sections {
                let _ = write!(
                    cells,
                    "{name}: {:.1} ({:.1} raw); ",
                    per(*stored),
                    per(*raw)
                );
            }
            let _ = writeln!(
                size_rows,
                "| {} | {:.1} | {cells} |",
                r.points,
                per(r.file_bytes)
            );
        }
        let _ = writeln!(
            md,
            "\n## Stored bytes per point\n\n| points | total B/pt | per section: stored (raw) B/pt |\n|---|---|---|\n{size_rows}"
        );
        let mut load_rows = String::new();
        for r in &self.loads {
            let _ = writeln!(
                load_rows,
                "| {} | {:.2} ms | {:.2} ms | {:.2} GB/s | {:.2} ms | {:.1} ms | {:.1} ms |",
                r.points,
                r.open * 1e3,
                r.load * 1e3,
                r.raw_bytes as f64 / r.load / 1e9,
                r.load_uncompressed * 1e3,
                r.verify * 1e3,
                r.cpu_ready * 1e3
            );
        }
        let _ = writeln!(
            md,
            "## Load time (file in the page cache)\n\n| points | open (map + checks) | open + decode every section into ready buffers | effective rate (raw bytes) | same, written with `--compress none` | open + full verify | open + CPU tracer structures |\n|---|---|---|---|---|---|---|\n{load_rows}"
        );
        let n = self.encodings_points;
        let _ = writeln!(
            md,
            "## Section encodings ({n} points, zstd level 1)\n\nRatio = raw / stored; speeds are raw bytes per second, single thread, median of 5.\n\n| section | raw B/pt | encoding | ratio | compress GB/s | decompress GB/s |\n|---|---|---|---|---|---|"
        );
        for e in &self.encodings {
            let mark = if e.chosen { " (chosen)" } else { "" };
            let _ = writeln!(
                md,
                "| {} | {:.1} | {}{mark} | {:.2} | {:.2} | {:.2} |",
                e.section,
                e.raw_bytes as f64 / n as f64,
                e.encoding,
                e.raw_bytes as f64 / e.stored_bytes.max(1) as f64,
                e.raw_bytes as f64 / e.compress / 1e9,
                e.raw_bytes as f64 / e.decompress / 1e9
            );
        }
        md
    }
}

impl BakeReport {
    fn scaling_markdown(&self) -> String {
        let cores = self.cores;
        let mut scaling = String::new();
        let _ = writeln!(
            scaling,
            "## Scaling with threads\n\nEach step baked and encoded on a rayon pool of that many threads \
             ({cores} cores here); medians of {} runs (1 at 1M points and above). Speed-up is against \
             the fewest threads of the same size.\n",
            self.settings.runs
        );
        let heads: Vec<&str> = STAGE_COLUMNS.iter().map(|c| c.0).collect();
        let _ = writeln!(
            scaling,
            "| points | threads | {} | **total** | points/s | speed-up |\n|{}",
            heads.join(" | "),
            "---|".repeat(heads.len() + 5)
        );
        for r in &self.scaling {
            let cells: Vec<String> = r
                .stages
                .iter()
                .map(|s| format!("{:.1} ms", s * 1e3))
                .collect();
            let _ = writeln!(
                scaling,
                "| {} | {} | {} | **{:.1} ms** | {:.0}k | {:.2}× |",
                r.points,
                r.threads,
                cells.join(" | "),
                r.total * 1e3,
                r.points as f64 / r.total / 1e3,
                r.fewest_threads_total / r.total
            );
        }
        scaling
    }

    fn series_markdown(&self) -> String {
        let mut series = String::new();
        if self.settings.series == 0 {
            return series;
        }
        let _ = writeln!(
            series,
            "\n## A series against one step alone\n\n{} steps of the moving sphere baked by the batch driver \
             as `slosh bake` runs it (generated in memory instead of read; compressed, verified and written \
             to a temporary directory), with the `--jobs` it would choose here, on all {} cores. \
             *One step* is the same size's step alone on all cores, from the first table (baked and encoded, \
             not verified or written); the *gpu* rows bake with the GPU's stages (`--device gpu`), their one \
             step from the GPU table.\n\n| points | device | jobs | wall | per step | steps/s | points/s | one step | per step / one step |\n|---|---|---|---|---|---|---|---|---|",
            self.settings.series, self.cores
        );
        for r in &self.series {
            let _ = writeln!(
                series,
                "| {} | {} | {} | {:.2} s | {:.1} ms | {:.1} | {:.0}k | {:.1} ms | {:.2}× |",
                r.points,
                r.device,
                r.jobs,
                r.wall,
                r.per_step * 1e3,
                1.0 / r.per_step,
                r.points as f64 / r.per_step / 1e3,
                r.one_step * 1e3,
                r.per_step / r.one_step
            );
        }
        series.push('\n');
        series
    }
}
