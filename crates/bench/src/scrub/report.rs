//! What `slosh bench scrub` measured, series by series, and its markdown.

use std::fmt::Write as _;

use super::Settings;
use crate::report::Report;
use crate::stats::Spread;

/// One zstd level over a step's sections: stored bytes and single-core speeds.
#[derive(Debug, Clone, PartialEq)]
pub struct CodecRow {
    pub level: i32,
    pub raw: u64,
    pub stored: u64,
    pub encode_mb_s: f64,
    pub decode_gb_s: f64,
}

/// One series measured: a step's costs and floors, playback, jumps and the codec table.
#[derive(Debug, Clone)]
pub struct SeriesReport {
    pub label: String,
    pub points: usize,
    pub steps: usize,
    pub step_gpu_bytes: u64,
    pub section_bytes: u64,
    pub stored_bytes: u64,
    pub host_ms: f64,
    pub record_ms: f64,
    pub copy_ms: f64,
    pub pass_ms: f64,
    /// GPU time of the neighbour-mask pass (0 without timestamps), which a step's first
    /// refined frame records, and the bytes of the masks (the tracer holds one step's).
    pub mask_pass_ms: f64,
    pub mask_bytes: u64,
    pub read_ms: f64,
    pub read_gbps: f64,
    pub write_buffer_ms: f64,
    pub trace_ms: f64,
    pub sequential_steps_per_s: f64,
    pub sequential: Spread,
    /// Medians of the loaders' host and record ms during sequential playback.
    pub streaming_host_ms: f64,
    pub streaming_record_ms: f64,
    /// Jumps within a pool that holds the whole series, or why the device cannot hold it.
    pub jumps_pool: Result<Spread, String>,
    pub jumps_page_cache: Spread,
    pub jump_parts: JumpBreakdown,
    /// Jumps read from storage, where asked (`--cold`).
    pub cold: Option<Cold>,
    pub codecs: Vec<CodecRow>,
}

/// Where the page-cache jumps' time went: ms of the host half, the record half and the rest
/// (waiting for a loader, the frame loop taking the step in, copies, the frame), as medians
/// over all jumps and as means over the slowest tenth (total first).
#[derive(Debug, Clone)]
pub struct JumpBreakdown {
    pub median: [f64; 3],
    pub slowest_tenth: [f64; 4],
    /// Buffers the engine created during the jumps (none kept fitted), the engine's first
    /// step excluded.
    pub fresh: slosh_play::FreshBuffers,
}

/// Jumps with the page cache dropped before each, and the disk's floor in the same run.
#[derive(Debug, Clone)]
pub struct Cold {
    pub jumps: Spread,
    /// Median ms of one step file read cold, and the rate over those reads.
    pub read_ms: f64,
    pub read_gbps: f64,
}

/// A pool jump's cells: the spread's p50 / p99, or why there is none.
fn pool_cells(r: &SeriesReport) -> String {
    match &r.jumps_pool {
        Ok(j) => format!("{:.2} / {:.2}", j.p50, j.p99),
        Err(_) => "not possible".into(),
    }
}

/// What `slosh bench scrub` measured.
#[derive(Debug, Clone)]
pub struct ScrubReport {
    /// The adapter, as `Gpu::describe` gives it.
    pub adapter: String,
    pub cores: usize,
    pub size: (u32, u32),
    /// The settings it ran with.
    pub settings: Settings,
    pub series: Vec<SeriesReport>,
    /// Raw EnSight cases baked as played (`--raw-case`).
    pub raw_cases: Vec<super::RawCaseReport>,
}

impl Report for ScrubReport {
    fn markdown(&self) -> String {
        let (cores, size, args) = (self.cores, self.size, &self.settings);
        let mut md = String::new();
        let _ = writeln!(
            md,
            "# Scrubbing: the streaming engine\n\nWritten by `slosh bench scrub{}{}` on {} ({cores} host cores). Frames of {}×{} at 1 iteration (the baked polynomial), shaded; every file read from the page cache. {} loader threads; sequential playback and page-cache jumps stream through a pool of {} steps, pool jumps use a pool that holds the whole series. Latency is from the request (the timeline set to the step) to the frame that shows it finished on the GPU; frames run back to back meanwhile, each submitted and waited for. Each series starts with 2 s of frames, so that the GPU has left its idle clocks.\n",
            if args.quick { " --quick" } else { "" },
            if args.raw_case_only {
                " --raw-case-only"
            } else {
                ""
            },
            self.adapter,
            size.0,
            size.1,
            args.loaders.unwrap_or_else(slosh_play::default_loaders),
            args.pool_steps.max(3)
        );
        // `--raw-case-only` measures no baked series: none of its tables.
        if !self.series.is_empty() {
            self.series_tables(&mut md);
        }
        if !self.raw_cases.is_empty() {
            self.raw_case_table(&mut md);
        }
        if !self.series.is_empty() {
            self.step_tables(&mut md);
        }
        md
    }
}

impl ScrubReport {
    /// The baked series' throughput, goals, jumps' parts and (`--cold`) storage tables.
    fn series_tables(&self, md: &mut String) {
        let (args, reports) = (&self.settings, &self.series);
        let _ = writeln!(md, "## Throughput and latency\n");
        let _ = writeln!(
            md,
            "| series | GPU B/pt | sequential steps/s | sequential latency p50 / p90 / p99 / max ms | jump in pool p50 / p99 ms | jump from page cache p50 / p99 / max ms | frame (trace + shade) ms |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|");
        for r in reports {
            let _ = writeln!(
                md,
                "| {} | {:.1} | {:.1} | {:.2} / {:.2} / {:.2} / {:.2} | {} | {:.2} / {:.2} / {:.2} | {:.2} |",
                r.label,
                r.step_gpu_bytes as f64 / r.points as f64,
                r.sequential_steps_per_s,
                r.sequential.p50,
                r.sequential.p90,
                r.sequential.p99,
                r.sequential.max,
                pool_cells(r),
                r.jumps_page_cache.p50,
                r.jumps_page_cache.p99,
                r.jumps_page_cache.max,
                r.trace_ms
            );
        }
        let _ = writeln!(md, "\n### Goals (page cache, 1280×800, 1 iteration)\n");
        let _ = writeln!(md, "| series | measure | goal | measured | met |");
        let _ = writeln!(md, "|---|---|---|---|---|");
        let met = |ok: bool| if ok { "yes" } else { "no" };
        for r in reports {
            // Issue 27's goals: 4M points 40 steps/s and 40 ms; 1M points 150 steps/s and
            // 12 ms; 100k points 4 ms.
            let goal = match r.points {
                p if p >= 4_000_000 => Some((Some(40.0), 40.0)),
                p if p >= 1_000_000 => Some((Some(150.0), 12.0)),
                p if p >= 100_000 => Some((None, 4.0)),
                _ => None,
            };
            if let Some((rate, jump)) = goal {
                if let Some(rate) = rate {
                    let _ = writeln!(
                        md,
                        "| {} | sequential steps/s | ≥ {rate} | {:.1} | {} |",
                        r.label,
                        r.sequential_steps_per_s,
                        met(r.sequential_steps_per_s >= rate)
                    );
                }
                let _ = writeln!(
                    md,
                    "| {} | jump from page cache, p99 | ≤ {jump} ms | {:.2} ms | {} |",
                    r.label,
                    r.jumps_page_cache.p99,
                    met(r.jumps_page_cache.p99 <= jump)
                );
            }
            let (measured, ok) = match &r.jumps_pool {
                Ok(j) => (format!("{:.2} ms", j.p99), met(j.p99 <= 2.0 + r.trace_ms)),
                Err(why) => (format!("not possible: {why}"), "no"),
            };
            let _ = writeln!(
                md,
                "| {} | jump to a resident step, p99 | ≤ 2 ms + frame ({:.2} ms) | {measured} | {ok} |",
                r.label,
                2.0 + r.trace_ms,
            );
        }
        let _ = writeln!(
            md,
            "\nJumps: {} in the pool and {} from the page cache per series (seed {}).\n",
            reports
                .first()
                .and_then(|r| r.jumps_pool.as_ref().ok())
                .map_or(0, |j| j.count),
            reports.first().map_or(0, |r| r.jumps_page_cache.count),
            args.seed
        );
        let _ = writeln!(
            md,
            "Where the page-cache jumps' time went: the host and record halves of the step asked for (run one after the other by a loader), and the rest (waiting for a loader, the frame loop taking the step in, the copies, the frame).\n\n| series | median host / record / rest ms | slowest tenth: mean total / host / record / rest ms | buffers created during the jumps: staging / sections |\n|---|---|---|---|"
        );
        for r in reports {
            let (m, s) = (r.jump_parts.median, r.jump_parts.slowest_tenth);
            let fresh = r.jump_parts.fresh;
            let _ = writeln!(
                md,
                "| {} | {:.2} / {:.2} / {:.2} | {:.2} / {:.2} / {:.2} / {:.2} | {} / {} |",
                r.label, m[0], m[1], m[2], s[0], s[1], s[2], s[3], fresh.staging, fresh.sections
            );
        }
        let _ = writeln!(md);
        if reports.iter().any(|r| r.cold.is_some()) {
            let _ = writeln!(
                md,
                "## From storage\n\nThe page cache dropped (`sync`, then 3 into /proc/sys/vm/drop_caches) before each jump, in the page-cache engine's pool; the floor is one step file read with `std::fs::read` after the same drop. Medians and spreads of the jumps.\n"
            );
            let _ = writeln!(
                md,
                "| series | jump from storage p50 / p99 / max ms | cold fs::read of a step ms (GB/s) |\n|---|---|---|"
            );
            for r in reports {
                if let Some(c) = &r.cold {
                    let _ = writeln!(
                        md,
                        "| {} | {:.2} / {:.2} / {:.2} | {:.2} ({:.2}) |",
                        r.label, c.jumps.p50, c.jumps.p99, c.jumps.max, c.read_ms, c.read_gbps
                    );
                }
            }
            md.push('\n');
        }
    }

    /// The raw EnSight cases' table (`--raw-case`).
    fn raw_case_table(&self, md: &mut String) {
        let _ = writeln!(
            md,
            "## Raw EnSight, baked as played\n\nThe same sphere written as an EnSight 6 binary case with its normals, played by the engine with no bake first (`slosh play CASE.case`): each step is baked by the loader that first needs it (its neighbours and initial fits found where the table says: `--raw-case-gpu` puts them on the engine's GPU, and then the process keeps the memory it frees for the rest of the run, as `slosh play CASE.case` does where it bakes on a GPU), into an emptied cache directory. The engine has as many loaders as steps its bake takes at once (`--loaders`, else `slosh_bake::viewer_jobs`: what `slosh bake` would take, at most half the cores), each baking a step ahead on its share of the cores, and asks for as many steps ahead. Sequential: playback from step 0 with nothing baked; jumps: to steps not baked yet. *One step*: reading it from the case, and reading and baking it into its file, alone on all cores (medians of 3).\n"
        );
        let _ = writeln!(
            md,
            "| case | neighbours on | EnSight MB per step | loaders | sequential steps/s | sequential p50 / p99 ms | jump p50 / p99 / max ms | one step: read ms | read and bake ms |\n|---|---|---|---|---|---|---|---|---|"
        );
        for r in &self.raw_cases {
            let _ = writeln!(
                md,
                "| {} points, {} steps | {} | {:.1} | {} | {:.2} | {:.0} / {:.0} | {} | {:.1} | {:.0} |",
                r.points,
                r.steps,
                r.bake_device,
                r.case_step_bytes as f64 / 1e6,
                r.loaders,
                r.sequential_steps_per_s,
                r.sequential.p50,
                r.sequential.p99,
                if r.jumps.count == 0 {
                    // Every loader bakes a step ahead: a short series is baked whole
                    // before a jump can find a step that is not.
                    "none: every step was baked or baking before a jump".to_string()
                } else {
                    format!(
                        "{:.0} / {:.0} / {:.0}",
                        r.jumps.p50, r.jumps.p99, r.jumps.max
                    )
                },
                r.read_ms,
                r.bake_ms
            );
        }
        md.push('\n');
    }

    /// The baked series' step costs and floors, and the codec table.
    fn step_tables(&self, md: &mut String) {
        let reports = &self.series;
        let _ = writeln!(md, "## A step, and the floors\n");
        let _ = writeln!(
            md,
            "Host: `HostStep::open` (map, checks, raw sections checksummed, the BVH nodes and cluster offsets decoded where compressed, the tree checked). Record: `GpuStep::create` (buffers; the staging buffer filled in parallel, compressed sections decoded run by run straight into it; copies recorded). Both halves timed alone, and as the engine's loaders reported them during sequential playback (several loads at once, beside the frame loop). GPU copies submitted and waited for; then, apart, the neighbour-mask pass that a step's first refined frame records (no upload runs it; the tracer holds the masks of one step, the bytes in the last column). Floors in the same run: `std::fs::read` of each step file, and one `Queue::write_buffer` of as many bytes as the step holds on the GPU, waited for. Medians.\n"
        );
        let _ = writeln!(
            md,
            "| series | bytes on the GPU (sections / all) | bytes stored | host ms | record ms | host / record ms while streaming | GPU copies ms | mask pass ms (GPU) | fs::read ms (GB/s) | write_buffer ms | mask bytes |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|");
        for r in reports {
            let _ = writeln!(
                md,
                "| {} | {} / {} | {} | {:.2} | {:.2} | {:.2} / {:.2} | {:.2} | {:.2} ({:.2}) | {:.2} ({:.1}) | {:.2} | {} |",
                r.label,
                r.section_bytes,
                r.step_gpu_bytes,
                r.stored_bytes,
                r.host_ms,
                r.record_ms,
                r.streaming_host_ms,
                r.streaming_record_ms,
                r.copy_ms,
                r.pass_ms,
                r.mask_pass_ms,
                r.read_ms,
                r.read_gbps,
                r.write_buffer_ms,
                r.mask_bytes
            );
        }
        let _ = writeln!(
            md,
            "\nSteps per series: {}.",
            reports.first().map_or(0, |r| r.steps)
        );
        let _ = writeln!(
            md,
            "\n## Codec\n\nThe compressed sections of each series' first step (their filters kept: byte shuffle, word delta) re-encoded with zstd at each level in chunks of 1 MiB, then decoded on one core. Bakes use level -1 by default.\n"
        );
        let _ = writeln!(
            md,
            "| series | zstd level | raw bytes | stored bytes | ratio | encode MB/s per core | decode GB/s per core |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|");
        // A series stored raw has no compressed section to re-encode.
        for r in reports {
            for c in r.codecs.iter().filter(|c| c.raw > 0) {
                let _ = writeln!(
                    md,
                    "| {} | {} | {} | {} | {:.2} | {:.0} | {:.2} |",
                    r.label,
                    c.level,
                    c.raw,
                    c.stored,
                    c.raw as f64 / c.stored.max(1) as f64,
                    c.encode_mb_s,
                    c.decode_gb_s
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--raw-case-only`: the raw case's table, and none of the baked series' (an empty
    /// table or a header without rows would read as a series that measured nothing).
    #[test]
    fn a_raw_case_only_report_has_no_series_tables() {
        let spread = |p50: f64| Spread {
            p50,
            p90: p50,
            p99: p50,
            max: p50,
            count: 3,
        };
        let report = ScrubReport {
            adapter: "an adapter".into(),
            cores: 16,
            size: (1280, 800),
            settings: Settings {
                out: "scrub.md".into(),
                points: vec![1_000_000],
                steps: 64,
                distinct: None,
                size: (1280, 800),
                jumps: 20,
                seed: 1,
                loaders: None,
                pool_steps: 3,
                dir: None,
                quick: false,
                adapter: None,
                cold: false,
                raw: false,
                raw_case: true,
                raw_case_gpu: true,
                raw_case_only: true,
            },
            series: Vec::new(),
            raw_cases: vec![super::super::RawCaseReport {
                bake_device: "the GPU".into(),
                points: 1_000_000,
                steps: 64,
                case_step_bytes: 24_000_000,
                loaders: 8,
                read_ms: 16.4,
                bake_ms: 516.0,
                sequential_steps_per_s: 6.18,
                sequential: spread(92.0),
                jumps: spread(579.0),
            }],
        };
        let md = report.markdown();
        assert!(md.contains("`slosh bench scrub --raw-case-only`"), "{md}");
        assert!(
            md.contains("| 1000000 points, 64 steps | the GPU | 24.0 | 8 | 6.18 | 92 / 92 | 579 / 579 / 579 | 16.4 | 516 |"),
            "{md}"
        );
        for section in [
            "## Throughput and latency",
            "### Goals",
            "## A step, and the floors",
            "## Codec",
        ] {
            assert!(!md.contains(section), "{section}: {md}");
        }
    }
}
