//! `slosh inspect`: a step file's header, sections and statistics, or a cache directory's
//! per-step table; `--verify` checks everything; `--json` is documented in
//! docs/inspect-json.md.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::Serialize;
use slosh_cache::{
    CacheFile, GpuPoint, Header, Manifest, SectionEntry, SeriesKey, names, parse_step_file_name,
};

use crate::config::inspect::InspectConfig;
use slosh_fileio::stdout::print;

#[derive(Debug, Serialize)]
struct Verification {
    ok: bool,
    error: Option<String>,
}

#[derive(Debug, Serialize)]
struct FileReport {
    file: PathBuf,
    version: [u16; 2],
    bytes: u64,
    header: Header,
    statistics: slosh_cache::Statistics,
    verify: Option<Verification>,
}

fn verification(file: &CacheFile) -> Verification {
    match file.verify() {
        Ok(_) => Verification {
            ok: true,
            error: None,
        },
        Err(e) => Verification {
            ok: false,
            error: Some(e.to_string()),
        },
    }
}

fn section_row(s: &SectionEntry) -> String {
    format!(
        "  {:<18} {:<9} {:>10} {:>12} {:>12} {:>6.2}x  {}",
        s.name,
        s.element,
        s.count,
        s.raw,
        s.stored,
        s.raw as f64 / (s.stored.max(1)) as f64,
        s.encoding.name()
    )
}

fn human_file(r: &FileReport) -> String {
    let h = &r.header;
    let st = &r.statistics;
    let m = &h.mls;
    let mut o = String::new();
    let mut line = |s: String| {
        o.push_str(&s);
        o.push('\n');
    };
    line(format!(
        "file       {} (cache format {}.{}, {} bytes)",
        r.file.display(),
        r.version[0],
        r.version[1],
        r.bytes
    ));
    line(format!(
        "source     {} step {}, time {}",
        h.source.path, h.source.step, h.source.time
    ));
    let far = match h.stats.dropped_far {
        0 => String::new(),
        n => format!(", {n} {}", slosh_bake::FAR_PARTICLES),
    };
    let too_few = match h.stats.dropped_too_few {
        0 => String::new(),
        n => format!(", {n} too few to size a surface"),
    };
    line(format!(
        "points     {} kept of {} read ({} non-finite{far}, {} not on the surface{too_few} dropped)",
        h.points, h.stats.input_points, h.stats.dropped_non_finite, h.stats.dropped_interior
    ));
    line(format!(
        "bounds     [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]",
        h.bounds[0][0],
        h.bounds[0][1],
        h.bounds[0][2],
        h.bounds[1][0],
        h.bounds[1][1],
        h.bounds[1][2]
    ));
    line(format!(
        "transform  world = [{:.6}, {:.6}, {:.6}] + {:.6} × local",
        h.transform.origin[0], h.transform.origin[1], h.transform.origin[2], h.transform.scale
    ));
    line(format!(
        "mls        degree {}, k {}, h-scale {} (h = {:.4e} world), support {}h, cap {}, normals {}, {} h, droplets below {} points, surface offset {} particle radii ({:.4e} world)",
        m.degree,
        m.k,
        m.h_scale,
        h.smoothing_length * h.transform.scale,
        m.support,
        m.neighbour_cap,
        m.normals,
        if m.per_point_h { "per-point" } else { "global" },
        m.droplet_below,
        m.offset,
        h.surface_offset * h.transform.scale
    ));
    line(format!("params     hash {}", h.params_hash));
    line(format!(
        "sections   {:<18} {:<9} {:>10} {:>12} {:>12} {:>7}  encoding",
        "name", "element", "count", "raw bytes", "stored", "ratio"
    ));
    for s in &h.sections {
        line(section_row(s));
    }
    let total = |f: fn(&SectionEntry) -> u64| h.sections.iter().map(f).sum::<u64>();
    // A step without particles has bytes (headers, empty sections) but no bytes per point.
    let sizes = match h.points {
        0 => format!(
            "no points: {} bytes decoded, {} stored",
            total(|s| s.raw),
            total(|s| s.stored)
        ),
        n => format!(
            "{:.1} bytes per point decoded, {:.1} stored",
            total(|s| s.raw) as f64 / n as f64,
            total(|s| s.stored) as f64 / n as f64
        ),
    };
    line(format!(
        "           {sizes}; {} of {} clusters store runs from 32-bit starts, the rest from 16-bit offsets",
        st.wide_clusters, st.clusters
    ));
    line(format!(
        "neighbours per point min {} mean {:.1} max {}; capped at {}: {} points ({:.1} %)",
        st.neighbours.min,
        st.neighbours.mean,
        st.neighbours.max,
        m.neighbour_cap,
        h.stats.capped,
        100.0 * h.stats.capped as f64 / h.points.max(1) as f64
    ));
    line(format!(
        "           histogram by 16: {:?}",
        st.neighbour_histogram
    ));
    line(format!(
        "radii      min {:.4e} mean {:.4e} max {:.4e} (world)",
        st.radii.min, st.radii.mean, st.radii.max
    ));
    line(format!(
        "normals    {} reversed to agree with their neighbourhood ({} in {} patches reversed whole)",
        h.stats.orientation_flipped, h.stats.orientation_patch_points, h.stats.orientation_patches
    ));
    line(format!(
        "fits       {} full, {} degraded, {} unfitted; degrees 0/1/2/3: {:?}",
        st.fit_full, st.fit_degraded, st.fit_none, st.degrees
    ));
    line(format!(
        "droplets   {} spheres from {} points",
        st.droplets, st.droplet_points
    ));
    line(format!(
        "bvh        {} nodes, {} leaves, depth {}",
        st.bvh_nodes, st.bvh_leaves, st.bvh_depth
    ));
    for (view, [lo, hi]) in &h.field_ranges {
        line(format!("field      {view}: {lo:e} to {hi:e}"));
    }
    let stages: Vec<String> = h
        .stats
        .stage_seconds
        .iter()
        .map(|(n, s)| format!("{n} {:.1} ms", s * 1e3))
        .collect();
    line(format!("bake       {}", stages.join(", ")));
    if let Some(v) = &r.verify {
        line(match &v.error {
            None => "verify     ok: footer checksum, every section checksum, invariants".into(),
            Some(e) => format!("verify     FAILED: {e}"),
        });
    }
    o
}

fn point_record(file: &CacheFile, i: usize) -> Result<serde_json::Value> {
    let h = file.header();
    if i >= h.points as usize {
        bail!(
            "--point {i}: the step has {} points (0..{})",
            h.points,
            h.points
        );
    }
    let points: Vec<GpuPoint> = file.decode(names::POINTS)?;
    let balls = file.balls()?;
    let cubic = file.cubic_words()?;
    let (start, neighbours) = file.neighbour_lists()?;
    let p = points[i];
    let b = balls[i];
    let local = p.position.map(f64::from);
    let mut rec = serde_json::json!({
        "point": i,
        "local": p.position,
        "world": h.transform.to_world(local),
        "radius_local": p.radius(), "reach_local": p.reach(),
        "ball": {
            "normal": b.normal(), "h": b.h, "degree": b.degree(),
            "state": format!("{:?}", b.kind()), "sphere": b.sphere(),
            "coefficients": b.coeffs(cubic[i]),
        },
        "neighbours": &neighbours[start[i] as usize..start[i + 1] as usize],
    });
    if file.section(names::NORMALS).is_some() {
        let ns: Vec<u32> = file.decode(names::NORMALS)?;
        rec["normal"] = serde_json::json!(slosh_cache::octahedral::decode_unit(ns[i]));
    }
    for s in &h.sections {
        if let Some(field) = s.name.strip_prefix(names::FIELD_PREFIX) {
            let value = if s.element == "f32" {
                serde_json::json!(file.decode::<f32>(&s.name)?[i])
            } else {
                serde_json::json!(file.decode::<[f32; 4]>(&s.name)?[i][..3])
            };
            rec["fields"][field] = value;
        }
    }
    Ok(rec)
}

fn inspect_file(path: &Path, args: &InspectConfig) -> Result<bool> {
    let file = CacheFile::open(path)?;
    if let Some(i) = args.point {
        let rec = point_record(&file, i)?;
        print(&format!("{}\n", serde_json::to_string_pretty(&rec)?))?;
        return Ok(true);
    }
    let verify = args.verify.then(|| verification(&file));
    let ok = verify.as_ref().is_none_or(|v| v.ok);
    // Statistics decode sections; a file that failed verification may not decode.
    let statistics = match slosh_cache::Statistics::of(&file) {
        Ok(s) => s,
        Err(e) if !ok => {
            let msg = verify.and_then(|v| v.error).unwrap_or_default();
            // The decoding error often is the verification's own (the file changed): once.
            let e = e.to_string();
            if msg.contains(&e) || e.contains(&msg) {
                bail!(
                    "verification failed: {}",
                    if e.len() > msg.len() { e } else { msg }
                );
            }
            bail!("verification failed: {msg} ({e})");
        }
        Err(e) => return Err(e.into()),
    };
    let report = FileReport {
        file: path.to_path_buf(),
        version: {
            let (a, b) = file.version();
            [a, b]
        },
        bytes: file.file_len(),
        header: file.header().clone(),
        statistics,
        verify,
    };
    if args.json {
        print(&format!("{}\n", serde_json::to_string_pretty(&report)?))?;
    } else {
        print(&human_file(&report))?;
    }
    Ok(ok)
}

#[derive(Debug, Serialize)]
struct DirStep {
    index: usize,
    file: String,
    time: f64,
    points: u64,
    bytes: u64,
    params_hash: String,
    verify: Option<Verification>,
    error: Option<String>,
    /// Why the step does not belong to the series (checked with --verify).
    series: Vec<String>,
}

#[derive(Debug, Serialize)]
struct DirReport {
    directory: PathBuf,
    manifest: bool,
    /// Why the manifest is unusable, where it is.
    manifest_error: Option<String>,
    /// Problems of the series as a whole (no steps, steps the manifest lists but that are
    /// gone).
    series: Vec<String>,
    params_hash: Option<String>,
    steps: Vec<DirStep>,
    total_points: u64,
    total_bytes: u64,
    failed: usize,
}

fn inspect_dir(dir: &Path, args: &InspectConfig) -> Result<bool> {
    let mut files: Vec<(usize, PathBuf)> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            parse_step_file_name(&e.file_name().to_string_lossy()).map(|i| (i, e.path()))
        })
        .collect();
    files.sort();
    let (manifest, manifest_error) = match Manifest::read(dir) {
        Ok(m) => (Some(m), None),
        Err(slosh_cache::Error::Io(e)) if e.source.kind() == std::io::ErrorKind::NotFound => {
            (None, None)
        }
        Err(e) => (None, Some(e.to_string())),
    };
    let mut series = Vec::new();
    if args.verify {
        if files.is_empty() {
            series.push(format!(
                "{} holds no step files (step-NNNNN.slc)",
                dir.display()
            ));
        }
        // No manifest at all is a bake interrupted or in progress: the steps are checked one
        // by one (the header says "manifest missing"); a manifest that is there must be right.
        match (&manifest, &manifest_error) {
            (None, None) => {}
            (None, Some(e)) => series.push(format!("manifest unusable: {e}")),
            (Some(m), _) => {
                for entry in &m.steps {
                    if !files.iter().any(|(i, _)| *i == entry.index) {
                        series.push(format!(
                            "the manifest lists {}, which is missing",
                            entry.file
                        ));
                    }
                }
            }
        }
    }
    // Steps are checked against the manifest, or, where there is none, against each other
    // (the first readable step's series): a directory holds one bake either way.
    let opened: Vec<(usize, PathBuf, slosh_cache::Result<CacheFile>)> = files
        .into_iter()
        .map(|(index, path)| {
            let file = CacheFile::open(&path);
            (index, path, file)
        })
        .collect();
    let reference = manifest.as_ref().map(Manifest::key).or_else(|| {
        opened
            .iter()
            .find_map(|(_, _, f)| f.as_ref().ok().map(|f| SeriesKey::of(f.header())))
    });
    if args.verify
        && let Some(key) = &reference
    {
        let present: Vec<usize> = opened.iter().map(|(i, _, _)| *i).collect();
        if let Some(gaps) = key.describe_missing(&key.missing(&present)) {
            series.push(gaps);
        }
    }
    let mut steps = Vec::new();
    for (index, path, opened) in opened {
        let file_name = path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default();
        match opened {
            Ok(f) => steps.push(DirStep {
                index,
                file: file_name,
                time: f.header().source.time,
                points: f.header().points,
                bytes: f.file_len(),
                params_hash: f.header().params_hash.clone(),
                verify: args.verify.then(|| verification(&f)),
                error: None,
                series: match (&manifest, &reference, args.verify) {
                    (Some(m), _, true) => m.step_problems(index, &f),
                    (None, Some(key), true) => key.differences(index, f.header()),
                    _ => Vec::new(),
                },
            }),
            Err(e) => steps.push(DirStep {
                index,
                file: file_name,
                time: f64::NAN,
                points: 0,
                bytes: 0,
                params_hash: String::new(),
                verify: None,
                error: Some(e.to_string()),
                series: Vec::new(),
            }),
        }
    }
    let failed = steps
        .iter()
        .filter(|s| {
            s.error.is_some() || s.verify.as_ref().is_some_and(|v| !v.ok) || !s.series.is_empty()
        })
        .count()
        + series.len();
    let report = DirReport {
        directory: dir.to_path_buf(),
        manifest: manifest.is_some(),
        manifest_error,
        series,
        params_hash: manifest.map(|m| m.params_hash),
        total_points: steps.iter().map(|s| s.points).sum(),
        total_bytes: steps.iter().map(|s| s.bytes).sum(),
        failed,
        steps,
    };
    if args.json {
        print(&format!("{}\n", serde_json::to_string_pretty(&report)?))?;
    } else {
        let mut o = format!(
            "directory  {} ({} steps, manifest {})\n  step         time     points        bytes  bytes/pt  params            status\n",
            dir.display(),
            report.steps.len(),
            match (&report.manifest_error, report.manifest) {
                (Some(_), _) => "INVALID",
                (None, true) => "present",
                (None, false) => "missing",
            }
        );
        for s in &report.steps {
            let status = match (&s.error, &s.verify) {
                (Some(e), _) => format!("UNREADABLE: {e}"),
                (None, _) if !s.series.is_empty() => {
                    format!("NOT OF THIS SERIES: {}", s.series.join("; "))
                }
                (None, Some(Verification { ok: true, .. })) => "verified".into(),
                (None, Some(Verification { error, .. })) => {
                    format!("FAILED: {}", error.clone().unwrap_or_default())
                }
                (None, None) => "readable".into(),
            };
            let per_point = match s.points {
                0 => "-".to_string(),
                n => format!("{:.1}", s.bytes as f64 / n as f64),
            };
            o.push_str(&format!(
                "  {:>5} {:>12.6} {:>10} {:>12} {:>9}  {:<16}  {status}\n",
                s.index, s.time, s.points, s.bytes, per_point, s.params_hash
            ));
        }
        for problem in &report.series {
            o.push_str(&format!("  SERIES: {problem}\n"));
        }
        let per_point = match report.total_points {
            0 => "no points".to_string(),
            n => format!(
                "{:.1} bytes per point",
                report.total_bytes as f64 / n as f64
            ),
        };
        o.push_str(&format!(
            "total      {} points, {} bytes ({per_point}), {} failed\n",
            report.total_points, report.total_bytes, report.failed
        ));
        print(&o)?;
    }
    Ok(report.failed == 0)
}

pub fn run(args: &InspectConfig) -> Result<()> {
    let ok = if args.path.is_dir() {
        inspect_dir(&args.path, args)?
    } else {
        inspect_file(&args.path, args)?
    };
    if !ok {
        bail!("{}: verification failed", args.path.display());
    }
    Ok(())
}
