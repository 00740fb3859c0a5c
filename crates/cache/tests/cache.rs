#![allow(clippy::unwrap_used)]
//! The .slc format against its promises: sections round-trip through every encoding, raw ones
//! are usable in place, truncation and newer versions get clear errors, decoding goes straight
//! into a caller's buffer.

use std::path::Path;

use slosh_cache::*;
use slosh_fileio::FileBytes;

fn header() -> Header {
    Header {
        source: Source {
            path: "test".into(),
            step: 3,
            time: 0.25,
        },
        points: 0,
        transform: Transform {
            origin: [1.0, 2.0, 3.0],
            scale: 2.0,
        },
        bounds: [[0.0; 3], [1.0; 3]],
        smoothing_length: 0.1,
        spacing: 0.05,
        neighbour_cluster: 32,
        mls: MlsSettings::from_params(&slosh_mls::SurfaceParams::default()),
        bake: serde_json::json!({"test": true}),
        params_hash: "0123456789abcdef".into(),
        stats: StepStats::default(),
        sections: Vec::new(),
    }
}

fn sample_sections() -> Vec<SectionInput> {
    let ids: Vec<u32> = (0..5000u32).map(|i| i * 3 + (i % 7)).collect();
    let floats: Vec<f32> = (0..4000).map(|i| (i as f32 * 0.01).sin()).collect();
    let noise: Vec<u32> = (0..1000u32).map(|i| i.wrapping_mul(2654435761)).collect();
    vec![
        SectionInput::new("ids", Element::U32, &ids, Encoding::Delta4Shuffle4Zstd),
        SectionInput::new("floats", Element::F32, &floats, Encoding::Shuffle4Zstd),
        SectionInput::new("plain", Element::F32, &floats, Encoding::Zstd),
        SectionInput::new("raw", Element::F32, &floats, Encoding::Raw),
        // Incompressible: falls back to raw.
        SectionInput::new("noise", Element::U32, &noise, Encoding::Zstd),
    ]
}

fn open(bytes: Vec<u8>) -> Result<CacheFile> {
    CacheFile::from_bytes(FileBytes::from_vec(Path::new("test.slc"), bytes))
}

#[test]
fn sections_round_trip_through_every_encoding() {
    let sections = sample_sections();
    let bytes = encode_step(header(), &sections, Compression::Level(3)).unwrap();
    let file = open(bytes).unwrap();
    file.verify().unwrap_err(); // not a step: no points section; structure and checksums are fine
    assert!(file.body_intact());
    let mut scratch = Vec::new();
    for s in &sections {
        let entry = file.section(&s.name).unwrap();
        assert_eq!(
            entry.offset % ALIGN as u64,
            0,
            "{} not page aligned",
            s.name
        );
        let mut out = vec![0u8; entry.raw as usize];
        file.decode_into(entry, &mut out, &mut scratch).unwrap();
        assert_eq!(out, s.bytes, "{}", s.name);
    }
    let enc = |n: &str| file.section(n).unwrap().encoding;
    assert_eq!(enc("ids"), Encoding::Delta4Shuffle4Zstd);
    assert_eq!(enc("noise"), Encoding::Raw);
    assert_eq!(enc("raw"), Encoding::Raw);
    // Sorted ids compress far better delta-coded.
    assert!(file.section("ids").unwrap().stored * 10 < file.section("ids").unwrap().raw);
    // Raw sections are usable in place.
    assert_eq!(file.raw_bytes("raw").unwrap(), &sections[3].bytes[..]);
    // Typed decoding checks the element size.
    assert_eq!(file.decode::<f32>("floats").unwrap().len(), 4000);
    assert!(file.decode::<[f32; 4]>("floats").is_err());
    // A buffer of the wrong size is refused, not overrun.
    let entry = file.section("ids").unwrap();
    let mut small = vec![0u8; entry.raw as usize - 4];
    assert!(file.decode_into(entry, &mut small, &mut scratch).is_err());
}

#[test]
fn truncation_at_any_length_is_a_clear_error() {
    let bytes = encode_step(header(), &sample_sections(), Compression::Level(1)).unwrap();
    for len in 0..bytes.len() {
        let err = open(bytes[..len].to_vec()).unwrap_err().to_string();
        assert!(
            err.contains("test.slc") && err.contains("at byte"),
            "length {len}: {err}"
        );
    }
    open(bytes).unwrap();
}

#[test]
fn a_newer_major_version_is_refused_by_name() {
    let mut bytes = encode_step(header(), &sample_sections(), Compression::None).unwrap();
    bytes[8] = 2;
    let err = open(bytes).unwrap_err().to_string();
    assert!(err.contains("newer") && err.contains("2.0"), "{err}");
}

#[test]
fn the_wrong_file_is_named_as_such() {
    let err = open(b"solid cube\nfacet normal 0 0 1\n".repeat(4)).unwrap_err();
    assert!(err.to_string().contains("magic"), "{err}");
}

#[test]
fn shuffle_groups_bytes_by_position() {
    let words: Vec<u8> = vec![1, 2, 3, 4, 5, 6, 7, 8];
    assert_eq!(shuffle4(&words), vec![1, 5, 2, 6, 3, 7, 4, 8]);
}
