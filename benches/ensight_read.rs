//! Reading EnSight steps: a 1M-point C Binary step (coordinates + normals + one scalar)
//! against `std::fs::read` of the same bytes in the same run, and ASCII parsing throughput.
//!
//! `cargo bench --bench ensight_read`; the ratio read_step / fs_read is the figure of merit
//! (goal ≤ 2), ASCII MB/s the other (goal ≥ 100).

use std::path::{Path, PathBuf};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use slosh_ensight::{Case, CaseWriter, Placement, StepRequest, VarData, VarType, WriteFormat};

fn write_case(dir: &Path, format: WriteFormat, n: usize) -> (PathBuf, Vec<PathBuf>) {
    let mut w = CaseWriter::create(
        dir,
        "bench",
        format,
        Placement::PointPart,
        &[("normal", VarType::Vector), ("pressure", VarType::Scalar)],
    )
    .expect("writer");
    let positions: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            let t = i as f32 * 1e-3;
            [t.sin(), t.cos(), -t * 1e-2]
        })
        .collect();
    let normals: Vec<[f32; 3]> = positions.iter().map(|p| [p[0], p[1], 0.0]).collect();
    let pressure: Vec<f32> = positions.iter().map(|p| -9810.0 * p[2]).collect();
    w.write_step(
        0.0,
        &positions,
        &[
            VarData::Vector("normal", &normals),
            VarData::Scalar("pressure", &pressure),
        ],
    )
    .expect("write");
    let files = ["geo", "normal", "pressure"]
        .iter()
        .map(|s| dir.join(format!("bench.{s}00000")))
        .collect();
    (w.case_path(), files)
}

fn request() -> StepRequest {
    StepRequest {
        normals: Some("normal".into()),
        fields: vec!["pressure".into()],
        ..Default::default()
    }
}

fn binary(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let (case_path, files) = write_case(dir.path(), WriteFormat::E6Binary, 1_000_000);
    let bytes: u64 = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
        .sum();
    let case = Case::open(&case_path).expect("open");
    let mut g = c.benchmark_group("binary_1M");
    g.throughput(Throughput::Bytes(bytes));
    g.sample_size(30);
    g.bench_function("fs_read", |b| {
        b.iter(|| {
            files
                .iter()
                .map(|f| std::fs::read(f).map(|v| v.len()).unwrap_or(0))
                .sum::<usize>()
        })
    });
    g.bench_function("read_step", |b| {
        b.iter(|| case.read_step(0, &request()).expect("read").positions.len())
    });
    g.finish();
}

fn ascii(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let (case_path, files) = write_case(dir.path(), WriteFormat::E6Ascii, 200_000);
    let bytes: u64 = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
        .sum();
    let case = Case::open(&case_path).expect("open");
    let mut g = c.benchmark_group("ascii_200k");
    g.throughput(Throughput::Bytes(bytes));
    g.sample_size(10);
    g.bench_function("read_step", |b| {
        b.iter(|| case.read_step(0, &request()).expect("read").positions.len())
    });
    g.finish();
}

criterion_group!(benches, binary, ascii);
criterion_main!(benches);
