//! Integration tests of the EnSight reader and writer: round trips through every written
//! flavour, hand-written files in the shapes real solvers produce, and bad input.

#![allow(clippy::unwrap_used)] // helpers of tests, where a failed unwrap is a failed test

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use slosh_ensight::*;

fn sample(n: usize, seed: u32) -> (Vec<[f32; 3]>, Vec<f32>, Vec<[f32; 3]>) {
    let mut x = seed.wrapping_mul(2654435761).max(1);
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        (x as f32 / u32::MAX as f32) * 2.0 - 1.0
    };
    let pos: Vec<[f32; 3]> = (0..n)
        .map(|_| [next() * 10.0, next() * 1e-3, next() * 1e4])
        .collect();
    let p: Vec<f32> = (0..n).map(|_| next() * 1e5).collect();
    let nrm: Vec<[f32; 3]> = (0..n).map(|_| [next(), next(), next()]).collect();
    (pos, p, nrm)
}

/// ASCII files keep 6 significant digits (`%12.5e`).
fn close(a: f32, b: f32, ascii: bool) -> bool {
    if ascii {
        (a - b).abs() <= 6e-6 * a.abs().max(b.abs()) + 1e-30
    } else {
        a.to_bits() == b.to_bits()
    }
}

fn roundtrip(format: WriteFormat, placement: Placement, order: ByteOrder) {
    roundtrip_sizes(format, placement, order, &[50, 57, 64]);
}

/// Writes one step of each size in `sizes` and reads every step back, bit for bit.
fn roundtrip_sizes(format: WriteFormat, placement: Placement, order: ByteOrder, sizes: &[usize]) {
    let dir = tempfile::tempdir().unwrap();
    let mut w = CaseWriter::create(
        dir.path(),
        "run",
        format,
        placement,
        &[("pressure", VarType::Scalar), ("normal", VarType::Vector)],
    )
    .unwrap()
    .with_byte_order(order);
    let steps: Vec<_> = sizes
        .iter()
        .enumerate()
        .map(|(s, &n)| sample(n, s as u32 + 1))
        .collect();
    for (s, (pos, p, n)) in steps.iter().enumerate() {
        w.write_step(
            0.1 * s as f64,
            pos,
            &[VarData::Scalar("pressure", p), VarData::Vector("normal", n)],
        )
        .unwrap();
    }
    let case = Case::open(w.case_path()).unwrap();
    assert_eq!(case.step_count(), sizes.len());
    assert_eq!(
        case.format(),
        if matches!(format, WriteFormat::GoldAscii | WriteFormat::GoldBinary) {
            Format::Gold
        } else {
            Format::Ensight6
        }
    );
    let ascii = matches!(format, WriteFormat::E6Ascii | WriteFormat::GoldAscii);
    let request = StepRequest {
        normals: Some("normal".into()),
        fields: vec!["pressure".into()],
        ..Default::default()
    };
    for (s, (pos, p, n)) in steps.iter().enumerate() {
        let step = case.read_step(s, &request).unwrap();
        assert!((step.time - 0.1 * s as f64).abs() < 1e-12);
        let expected_source = if placement == Placement::Measured {
            PointSource::Measured
        } else {
            PointSource::PointElements
        };
        assert_eq!(step.source, expected_source);
        assert_eq!(step.positions.len(), pos.len());
        for (a, b) in step.positions.iter().flatten().zip(pos.iter().flatten()) {
            assert!(
                close(*a, *b, ascii),
                "{format:?} {placement:?} position {a} vs {b}"
            );
        }
        let normals = step.normals.as_ref().unwrap();
        for (a, b) in normals.iter().flatten().zip(n.iter().flatten()) {
            assert!(close(*a, *b, ascii), "normal {a} vs {b}");
        }
        let FieldValues::Scalar(values) = &step.fields[0].values else {
            panic!("scalar expected")
        };
        for (a, b) in values.iter().zip(p) {
            assert!(close(*a, *b, ascii), "pressure {a} vs {b}");
        }
    }
    if !ascii {
        let detected = match placement {
            Placement::PointPart => case.read_geometry(0, false).unwrap().byte_order,
            Placement::Measured => case.read_measured(0, false).unwrap().byte_order,
        };
        assert_eq!(detected, Some(order), "byte order detected");
    }
}

#[test]
fn every_written_flavour_reads_back() {
    for format in [
        WriteFormat::E6Ascii,
        WriteFormat::E6Binary,
        WriteFormat::GoldAscii,
        WriteFormat::GoldBinary,
    ] {
        for placement in [Placement::PointPart, Placement::Measured] {
            roundtrip(format, placement, ByteOrder::Little);
        }
    }
}

#[test]
fn big_endian_binary_is_detected() {
    for format in [WriteFormat::E6Binary, WriteFormat::GoldBinary] {
        for placement in [Placement::PointPart, Placement::Measured] {
            roundtrip(format, placement, ByteOrder::Big);
        }
    }
}

/// A count whose bytes, swapped, are a smaller count that the file also has room for: 131 328
/// is 0x00020100, which the other byte order reads as 66 048 (so is 4 000 000, read as
/// 605 440). Guessing by the smaller value alone refused such files (a 4M-point `slosh gen`
/// sphere: "expected a finite number"); the other order is tried where the first fails.
#[test]
fn counts_that_read_plausibly_in_both_byte_orders_are_read_right() {
    let ambiguous = 0x0002_0100;
    assert_eq!(u32::swap_bytes(ambiguous as u32), 66_048);
    for order in [ByteOrder::Little, ByteOrder::Big] {
        for placement in [Placement::PointPart, Placement::Measured] {
            for format in [WriteFormat::E6Binary, WriteFormat::GoldBinary] {
                roundtrip_sizes(format, placement, order, &[ambiguous, 66_048]);
            }
        }
    }
}

fn write(dir: &Path, name: &str, content: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, content).unwrap();
    p
}

/// EnSight 6 ASCII as FPM codes write it: given ids, fixed width with touching negative
/// numbers, a mesh part before the particle part, and a per-node variable over all nodes.
#[test]
fn e6_ascii_fixed_width_given_ids_mixed_parts() {
    let dir = tempfile::tempdir().unwrap();
    let geo = "\
FPM output
second line
node id given
element id given
coordinates
       4
      10-1.00000e+00-2.00000e+00-3.00000e+00
      20 1.00000e+00 2.00000e+00 3.00000e+00
      30 4.00000e+00 5.00000e+00 6.00000e+00
      40 7.00000e+00 8.00000e+00 9.00000e+00
part       1
wall
tria3
       1
       1      10      20      30
part       2
fluid
point
       2
       1      40
       2      10
";
    write(dir.path(), "a.geo0001", geo.as_bytes());
    let var = "pressure\n 1.00000e+00-2.00000e+00 3.00000e+00 4.00000e+00\n";
    write(dir.path(), "a.p0001", var.as_bytes());
    let case = "FORMAT\ntype: ensight\nGEOMETRY\nmodel: 1 a.geo****\nVARIABLE\nscalar per node: 1 p a.p****\n\
        TIME\ntime set: 1\nnumber of steps: 1\nfilename start number: 1\nfilename increment: 1\ntime values: 0.5\n";
    let path = write(dir.path(), "a.case", case.as_bytes());
    let case = Case::open(&path).unwrap();
    let step = case
        .read_step(
            0,
            &StepRequest {
                fields: vec!["p".into()],
                ..Default::default()
            },
        )
        .unwrap();
    // Particles are the point elements only, referenced by node id.
    assert_eq!(step.positions, vec![[7.0, 8.0, 9.0], [-1.0, -2.0, -3.0]]);
    assert_eq!(step.fields[0].values, FieldValues::Scalar(vec![4.0, 1.0]));
    let all = case
        .read_step(
            0,
            &StepRequest {
                points: PointSource::AllNodes,
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(all.positions.len(), 4);
    let g = case.read_geometry(0, false).unwrap();
    assert_eq!(g.parts[0].blocks[0].kind, "tria3");
    assert_eq!(g.parts[1].blocks[0].count, 2);
}

/// Gold ASCII with extents, element ids, an nsided block and two parts, per-part variables.
#[test]
fn gold_ascii_parts_and_polygons() {
    let dir = tempfile::tempdir().unwrap();
    let geo = "\
desc
desc
node id off
element id given
extents
 0.00000e+00 1.00000e+00
 0.00000e+00 1.00000e+00
 0.00000e+00 1.00000e+00
part
         1
mesh
coordinates
         3
 0.0
 1.0
 0.0
 0.0
 0.0
 1.0
 0.0
 0.0
 0.0
nsided
         1
        99
         3
         1         2         3
part
         2
particles
coordinates
         2
 5.0
 6.0
 7.0
 8.0
 9.0
 1.0e1
point
         2
         7
         8
         2
         1
";
    write(dir.path(), "g.geo", geo.as_bytes());
    let var = "vel\npart\n         1\ncoordinates\n1\n2\n3\n4\n5\n6\n7\n8\n9\npart\n         2\ncoordinates\n10\n11\n12\n13\n14\n15\n";
    write(dir.path(), "g.vel", var.as_bytes());
    let case = "FORMAT\ntype: ensight gold\nGEOMETRY\nmodel: g.geo\nVARIABLE\nvector per node: vel g.vel\n";
    let path = write(dir.path(), "g.case", case.as_bytes());
    let case = Case::open(&path).unwrap();
    assert_eq!(case.step_count(), 1);
    let step = case
        .read_step(
            0,
            &StepRequest {
                fields: vec!["vel".into()],
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(step.positions, vec![[6.0, 8.0, 10.0], [5.0, 7.0, 9.0]]);
    assert_eq!(
        step.fields[0].values,
        FieldValues::Vector(vec![[11.0, 13.0, 15.0], [10.0, 12.0, 14.0]])
    );
}

/// Single-file transient data: every step in one file between BEGIN/END TIME STEP.
#[test]
fn single_file_transient_ascii_and_binary() {
    let dir = tempfile::tempdir().unwrap();
    // ASCII measured particles, two steps in one file.
    let m = "BEGIN TIME STEP\nstep a\nparticle coordinates\n       1\n       1 1.00000e+00 2.00000e+00 3.00000e+00\nEND TIME STEP\n\
             BEGIN TIME STEP\nstep b\nparticle coordinates\n       2\n       1 4.00000e+00 5.00000e+00 6.00000e+00\n       2-1.00000e+00-2.00000e+00-3.00000e+00\nEND TIME STEP\n";
    write(dir.path(), "m.mgeo", m.as_bytes());
    write(
        dir.path(),
        "empty.geo",
        b"d\nd\nnode id off\nelement id off\ncoordinates\n       0\n",
    );
    let case = "FORMAT\ntype: ensight\nGEOMETRY\nmodel: empty.geo\nmeasured: 1 1 m.mgeo\nTIME\ntime set: 1\nnumber of steps: 2\ntime values: 0 1\nFILE\nfile set: 1\nnumber of steps: 2\n";
    let path = write(dir.path(), "m.case", case.as_bytes());
    let c = Case::open(&path).unwrap();
    let s1 = c.read_step(1, &StepRequest::default()).unwrap();
    assert_eq!(s1.positions, vec![[4.0, 5.0, 6.0], [-1.0, -2.0, -3.0]]);
    assert_eq!(s1.source, PointSource::Measured);

    // Binary Gold geometry, two steps.
    let mut b = Vec::new();
    let s = |b: &mut Vec<u8>, t: &str| {
        let mut r = [0u8; 80];
        r[..t.len()].copy_from_slice(t.as_bytes());
        b.extend_from_slice(&r);
    };
    let i = |b: &mut Vec<u8>, v: i32| b.extend_from_slice(&v.to_le_bytes());
    let f = |b: &mut Vec<u8>, v: f32| b.extend_from_slice(&v.to_le_bytes());
    s(&mut b, "C Binary");
    for step in 0..2 {
        s(&mut b, "BEGIN TIME STEP");
        s(&mut b, "d1");
        s(&mut b, "d2");
        s(&mut b, "node id off");
        s(&mut b, "element id off");
        s(&mut b, "part");
        i(&mut b, 1);
        s(&mut b, "p");
        s(&mut b, "coordinates");
        i(&mut b, 1);
        for axis in 0..3 {
            f(&mut b, (step * 10 + axis) as f32);
        }
        s(&mut b, "point");
        i(&mut b, 1);
        i(&mut b, 1);
        s(&mut b, "END TIME STEP");
    }
    write(dir.path(), "t.geo", &b);
    let case = "FORMAT\ntype: ensight gold\nGEOMETRY\nmodel: 1 1 t.geo\nTIME\ntime set: 1\nnumber of steps: 2\ntime values: 0.0\n 2.0\nFILE\nfile set: 1\nnumber of steps: 2\n";
    let path = write(dir.path(), "t.case", case.as_bytes());
    let c = Case::open(&path).unwrap();
    assert_eq!(
        c.read_step(1, &StepRequest::default()).unwrap().positions,
        vec![[10.0, 11.0, 12.0]]
    );
    assert_eq!(
        c.read_step(0, &StepRequest::default()).unwrap().positions,
        vec![[0.0, 1.0, 2.0]]
    );
}

fn error_of(case_dir: &Path, case: &str) -> String {
    let path = write(case_dir, "bad.case", case.as_bytes());
    match Case::open(&path).and_then(|c| {
        c.read_step(
            0,
            &StepRequest {
                fields: vec![],
                ..Default::default()
            },
        )
    }) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

const BIN_CASE: &str = "FORMAT\ntype: ensight\nGEOMETRY\nmodel: 1 b.geo*****\nTIME\ntime set: 1\nnumber of steps: 1\nfilename start number: 0\ntime values: 0\n";

fn binary_geo(n: i32, coords: &[f32]) -> Vec<u8> {
    let mut b = Vec::new();
    for t in [
        "C Binary",
        "d",
        "d",
        "node id off",
        "element id off",
        "coordinates",
    ] {
        let mut r = [0u8; 80];
        r[..t.len()].copy_from_slice(t.as_bytes());
        b.extend_from_slice(&r);
    }
    b.extend_from_slice(&n.to_le_bytes());
    for c in coords {
        b.extend_from_slice(&c.to_le_bytes());
    }
    b
}

#[test]
fn bad_input_names_file_and_place() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Unknown keyword in the case file: its line.
    let e = error_of(d, "FORMAT\ntype: ensight\nGEOMETRY\nmodle: x.geo\n");
    assert!(e.contains("bad.case: line 4") && e.contains("modle"), "{e}");
    // Missing step file: its name.
    let e = error_of(d, BIN_CASE);
    assert!(e.contains("b.geo00000"), "{e}");
    // Count larger than the file: byte offset of the count.
    write(d, "b.geo00000", &binary_geo(1000, &[1.0, 2.0, 3.0]));
    let e = error_of(d, BIN_CASE);
    assert!(
        e.contains("byte offset 480") && e.contains("1000 items"),
        "{e}"
    );
    // NaN coordinate: byte offset of the value.
    write(d, "b.geo00000", &binary_geo(1, &[1.0, f32::NAN, 3.0]));
    let e = error_of(d, BIN_CASE);
    assert!(e.contains("byte offset 488") && e.contains("finite"), "{e}");
    // Truncated inside the header strings.
    write(d, "b.geo00000", &binary_geo(1, &[1.0, 2.0, 3.0])[..200]);
    let e = error_of(d, BIN_CASE);
    assert!(
        e.contains("byte offset 160") && e.contains("end of file"),
        "{e}"
    );
    // Fortran binary: refused by name.
    let mut fortran = 80i32.to_le_bytes().to_vec();
    fortran.extend_from_slice(b"Fortran Binary");
    fortran.resize(200, b' ');
    write(d, "b.geo00000", &fortran);
    let e = error_of(d, BIN_CASE);
    assert!(e.contains("Fortran"), "{e}");
    // Unparsable ASCII number: its line.
    write(
        d,
        "b.geo00000",
        b"d\nd\nnode id off\nelement id off\ncoordinates\n       1\n 1.0 2.0 x3\n",
    );
    let e = error_of(d, BIN_CASE);
    assert!(e.contains("line 7") && e.contains("x3"), "{e}");
    // A point element naming a node that does not exist.
    write(d, "b.geo00000", b"d\nd\nnode id off\nelement id off\ncoordinates\n       1\n 1.0 2.0 3.0\npart 1\np\npoint\n       1\n       5\n");
    let e = error_of(d, BIN_CASE);
    assert!(e.contains("line 12") && e.contains("node 5"), "{e}");
    // Wrong number of time values.
    let e = error_of(
        d,
        "FORMAT\ntype: ensight\nGEOMETRY\nmodel: 1 b.geo*****\nTIME\ntime set: 1\nnumber of steps: 3\ntime values: 0 1\n",
    );
    assert!(e.contains("3 time values"), "{e}");
}

#[test]
fn fuzz_corpus_files_never_panic() {
    // Every prefix of valid files of each flavour: truncation at any byte is an error that
    // names the file, never a panic and never a silently shorter step.
    let dir = tempfile::tempdir().unwrap();
    for format in [
        WriteFormat::E6Ascii,
        WriteFormat::E6Binary,
        WriteFormat::GoldAscii,
        WriteFormat::GoldBinary,
    ] {
        let sub = dir.path().join(format!("{format:?}"));
        let mut w = CaseWriter::create(&sub, "f", format, Placement::PointPart, &[]).unwrap();
        let (pos, _, _) = sample(4, 9);
        w.write_step(0.0, &pos, &[]).unwrap();
        let geo = sub.join("f.geo00000");
        let bytes = std::fs::read(&geo).unwrap();
        let case_path = w.case_path().to_path_buf();
        let full = Case::open(&case_path)
            .and_then(|c| c.read_step(0, &StepRequest::default()))
            .unwrap()
            .positions;
        for cut in 0..bytes.len() {
            fuzzing::geometry(&bytes[..cut]);
            // Through the reader: an error naming the file (or the case, where the cut
            // leaves a well-formed geometry without particles), unless the cut only took
            // trailing whitespace, which leaves the same points.
            std::fs::write(&geo, &bytes[..cut]).unwrap();
            match Case::open(&case_path).and_then(|c| c.read_step(0, &StepRequest::default())) {
                Err(e) => {
                    let e = e.to_string();
                    assert!(
                        e.contains("f.geo00000") || e.contains("f.case"),
                        "{format:?} cut at {cut}: {e}"
                    );
                }
                Ok(step) => {
                    assert!(
                        bytes[cut..].iter().all(u8::is_ascii_whitespace),
                        "{format:?} cut at {cut} of {} read without an error",
                        bytes.len()
                    );
                    assert_eq!(step.positions, full, "{format:?} cut at {cut}");
                }
            }
        }
        fuzzing::case(std::fs::read(w.case_path()).unwrap().as_slice());
    }
}

proptest! {
    #[test]
    fn random_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..600)) {
        fuzzing::geometry(&data);
        fuzzing::measured(&data);
        fuzzing::case(&data);
    }

    #[test]
    fn random_binary_after_header_never_panics(tail in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut data = binary_geo(2, &[]);
        data.truncate(480);
        data.extend_from_slice(&tail);
        fuzzing::geometry(&data);
    }
}
