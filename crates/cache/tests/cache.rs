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
            identity: None,
        },
        points: 0,
        transform: Transform {
            origin: [1.0, 2.0, 3.0],
            scale: 2.0,
        },
        bounds: [[0.0; 3], [1.0; 3]],
        smoothing_length: 0.1,
        spacing: 0.05,
        surface_offset: 0.0,
        bvh_grid: BvhGrid::default(),
        neighbour_cluster: 32,
        mls: MlsSettings::from_params(&slosh_mls::SurfaceParams::default()),
        bake: serde_json::json!({"test": true}),
        params_hash: "0123456789abcdef".into(),
        series: None,
        stats: StepStats::default(),
        sections: Vec::new(),
        up: None,
        field_ranges: Default::default(),
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
    bytes[8..12].copy_from_slice(&[10, 0, 0, 0]);
    let err = open(bytes).unwrap_err().to_string();
    assert!(err.contains("newer") && err.contains("10.0"), "{err}");
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
    // Two 16-byte elements: byte k of each, side by side.
    let elements: Vec<u8> = (0..32).collect();
    let want: Vec<u8> = (0..16).flat_map(|k| [k, k + 16]).collect();
    assert_eq!(shuffle(&elements, 16), want);
}

/// Element shuffles of every width round-trip at counts that are not whole transpose blocks,
/// and refuse bytes that are not whole elements.
#[test]
fn element_shuffles_round_trip_whole_elements_only() {
    for (encoding, width) in [
        (Encoding::Shuffle4Zstd, 4),
        (Encoding::Shuffle16Zstd, 16),
        (Encoding::Shuffle20Zstd, 20),
        (Encoding::Shuffle24Zstd, 24),
        (Encoding::Shuffle32Zstd, 32),
        (Encoding::Shuffle64Zstd, 64),
    ] {
        assert_eq!(encoding.shuffle_width(), Some(width));
        assert_eq!(Encoding::shuffled_elements(width), encoding);
        for count in [0usize, 1, 63, 64, 65, 1000] {
            let raw: Vec<u8> = (0..count * width).map(|i| (i * 7 % 251) as u8).collect();
            let stored = encode_bytes(&raw, encoding, 1).unwrap();
            let mut out = vec![0u8; raw.len()];
            decode_bytes(&stored, encoding, &mut out, &mut Vec::new()).unwrap();
            assert!(out == raw, "{} at {count} elements", encoding.name());
        }
        if width > 4 {
            // 36 bytes are no whole number of elements of any of these widths.
            let err = encode_bytes(&[0u8; 36], encoding, 1).unwrap_err();
            assert!(err.to_string().contains("whole"), "{err}");
        }
    }
}

/// A section's chunks: never under 64 KiB, a sixteenth of the section between, never over
/// 1 MiB (or, for elements that do not divide it, the most whole elements within it).
#[test]
fn chunks_are_a_sixteenth_of_a_section_within_their_bounds() {
    for (encoding, step) in [
        (Encoding::Raw, 8),
        (Encoding::Shuffle4Zstd, 8),
        (Encoding::Shuffle16Zstd, 16),
        (Encoding::Shuffle20Zstd, 40),
        (Encoding::Shuffle24Zstd, 24),
    ] {
        assert_eq!(encoding.chunk_step(), step);
        assert_eq!(encoding.chunk_raw(0), CHUNK_RAW_MIN.next_multiple_of(step));
        assert_eq!(
            encoding.chunk_raw(1000),
            CHUNK_RAW_MIN.next_multiple_of(step)
        );
        // 100k 16-byte balls: 1.6 MB in sixteen chunks of 100,000 bytes.
        assert_eq!(
            encoding.chunk_raw(1_600_000),
            100_000u64.next_multiple_of(step)
        );
        // A sixteenth of 1M 12-byte points, 750,000 bytes, is no multiple of 8: such chunks
        // could not be mapped where they go in a staging buffer.
        let chunk = encoding.chunk_raw(12_000_000);
        assert!(chunk >= 750_000 && chunk % CHUNK_ALIGN == 0, "{chunk}");
        let most = encoding.chunk_raw(u64::MAX / 2);
        assert_eq!(most, CHUNK_RAW - CHUNK_RAW % step);
        assert_eq!(encoding.chunk_raw(64 * CHUNK_RAW), most);
    }
    // 20-byte elements do not divide 1 MiB: their largest chunks hold 1,048,560 bytes.
    assert_eq!(Encoding::Shuffle20Zstd.chunk_raw(1 << 30), 1_048_560);
}

/// Sections of several chunks: every encoding round-trips, and a flip in any chunk is caught
/// naming that chunk.
#[test]
fn chunked_sections_round_trip_and_name_the_damaged_chunk() {
    let n = (3 * CHUNK_RAW as usize + 12_345) / 4;
    let ids: Vec<u32> = (0..n as u32).map(|i| i * 5 + (i % 11)).collect();
    let floats: Vec<f32> = (0..n).map(|i| (i as f32 * 1e-3).sin()).collect();
    let sections = vec![
        SectionInput::new("ids", Element::U32, &ids, Encoding::Delta4Shuffle4Zstd),
        SectionInput::new("floats", Element::F32, &floats, Encoding::Shuffle4Zstd),
        SectionInput::new("plain", Element::F32, &floats, Encoding::Zstd),
        SectionInput::new("raw", Element::F32, &floats, Encoding::Raw),
        SectionInput::new(
            "points",
            Element::Point,
            bytemuck::cast_slice::<f32, [f32; 4]>(&floats[..n / 4 * 4]),
            Encoding::Shuffle16Zstd,
        ),
        SectionInput::new(
            "nodes",
            Element::BvhNode,
            bytemuck::cast_slice::<f32, [f32; 4]>(&floats[..n / 8 * 8]),
            Encoding::Shuffle32Zstd,
        ),
        SectionInput::new(
            "balls",
            Element::Ball,
            bytemuck::cast_slice::<f32, [f32; 4]>(&floats[..n / 20 * 20]),
            Encoding::Shuffle20Zstd,
        ),
    ];
    let bytes = encode_step(header(), &sections, Compression::Level(1)).unwrap();
    let file = open(bytes.clone()).unwrap();
    for (entry, input) in file.header().sections.iter().zip(&sections) {
        // About 3 MiB each: a sixteenth of the section per chunk, rounded up to whole
        // elements and 8 bytes, so sixteen chunks, the last holding the rest.
        let width = input.encoding.chunk_step();
        assert_eq!(
            entry.chunks.len() as u64,
            CHUNKS_PER_SECTION,
            "{}",
            entry.name
        );
        assert_eq!(
            entry.chunk_raw,
            entry
                .raw
                .div_ceil(CHUNKS_PER_SECTION)
                .next_multiple_of(width),
            "{}",
            entry.name
        );
        let mut out = vec![0u8; entry.raw as usize];
        file.decode_into(entry, &mut out, &mut Vec::new()).unwrap();
        assert!(out == input.bytes, "{} differs after decoding", entry.name);
    }
    for entry in &file.header().sections {
        let spans = entry.chunk_spans();
        // The first, a middle and the last chunk (the last is the short one).
        let last = spans.len() - 1;
        for k in [0, last / 2, last] {
            let stored = &spans[k].0;
            let mut damaged = bytes.clone();
            damaged[entry.offset as usize + stored.start + stored.len() / 2] ^= 0x01;
            let file = open(damaged).unwrap();
            let victim = file.section(&entry.name).unwrap();
            let mut out = vec![0u8; victim.raw as usize];
            let err = file
                .decode_into(victim, &mut out, &mut Vec::new())
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(&format!("chunk {k} ")) && err.contains(&entry.name),
                "{err}"
            );
            if entry.encoding == Encoding::Raw {
                assert!(file.checked_stored(victim).is_err());
            }
        }
    }
}

/// Every single-byte flip of a file is detected: opening fails, or the footer hash no longer
/// matches, and a flip inside a section's stored bytes also fails that section's decoding
/// (which is all a streaming reader checks).
#[test]
fn every_single_byte_flip_is_detected() {
    let bytes = encode_step(header(), &sample_sections(), Compression::Level(3)).unwrap();
    let file = open(bytes.clone()).unwrap();
    let ranges: Vec<(String, std::ops::Range<usize>)> = file
        .header()
        .sections
        .iter()
        .map(|s| {
            (
                s.name.clone(),
                s.offset as usize..(s.offset + s.stored) as usize,
            )
        })
        .collect();
    for at in 0..bytes.len() {
        let mut damaged = bytes.clone();
        damaged[at] ^= 0x20;
        let Ok(file) = open(damaged) else { continue };
        assert!(
            !file.body_intact(),
            "flip at byte {at} passes the footer hash"
        );
        if let Some((name, _)) = ranges.iter().find(|(_, r)| r.contains(&at)) {
            let entry = file.section(name).unwrap();
            let mut out = vec![0u8; entry.raw as usize];
            assert!(
                file.decode_into(entry, &mut out, &mut Vec::new()).is_err(),
                "flip at byte {at} inside section '{name}' decodes"
            );
        }
    }
}

/// A file of an older major version (format 8.0 stored BVH nodes of 32 bytes, boxes in f32,
/// where 9.x stores 16-byte nodes on a grid) is refused with both versions and the command
/// that re-bakes it from its source.
#[test]
fn an_older_major_version_is_refused_with_the_rebake_command() {
    let mut bytes = encode_step(header(), &sample_sections(), Compression::None).unwrap();
    bytes[8..12].copy_from_slice(&[8, 0, 0, 0]);
    let err = open(bytes).unwrap_err().to_string();
    for part in ["test.slc", "8.0", "9.1", "older", "slosh bake test --out"] {
        assert!(err.contains(part), "{part}: {err}");
    }
}

/// A step file truncated under its map (`cp`, `rsync --inplace`, NFS) or rewritten in place:
/// reading it is an error naming the file, never a SIGBUS (issue 25, item 5).
#[test]
fn a_file_changed_under_its_map_is_an_error_not_a_crash() {
    let sections: Vec<SectionInput> = (0..4)
        .map(|k| {
            let v: Vec<u32> = (0..200_000u32)
                .map(|i| i.wrapping_mul(2654435761 + k))
                .collect();
            SectionInput::new(&format!("s{k}"), Element::U32, &v, Encoding::Raw)
        })
        .collect();
    let bytes = encode_step(header(), &sections, Compression::None).unwrap();
    assert!(bytes.len() > 3_000_000);
    let mut changed = 0;
    for cut in [0u8, 1, 60, 128, 200, 254] {
        for rewrite in [0u8, 1] {
            let mut data = vec![cut, rewrite];
            data.extend_from_slice(&bytes);
            changed += usize::from(fuzzing::changed_while_mapped(&data));
        }
    }
    // Every truncation without a rewrite leaves pages past the end that the reads meet.
    assert!(changed >= 6, "{changed}");
    // Directly: the error names the file and says what happened.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.slc");
    std::fs::write(&path, &bytes).unwrap();
    let file = CacheFile::open(&path).unwrap();
    assert!(file.is_mapped());
    std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(8000)
        .unwrap();
    let err = file.verify().unwrap_err().to_string();
    assert!(
        err.contains("v.slc") && err.contains("changed while it was read"),
        "{err}"
    );
}

/// Sections with a raw rank are stored raw, rank by rank, while the sections' stored bytes,
/// each padded to its page, stay within `RAW_BUDGET_BYTES_PER_POINT` per point; a rank that
/// would overrun it is skipped and a later, smaller one still taken; without compression
/// everything is raw.
#[test]
fn ranked_sections_go_raw_in_rank_order_within_the_budget() {
    // 2000 "points": a budget of 92,000 bytes. Compressible sections of 64,000, 32,000 and
    // 8,000 raw bytes (16, 8 and 2 pages), each one page compressed.
    let small: Vec<u32> = (0..2000u32).map(|i| i / 8).collect();
    let middle: Vec<u32> = (0..8000u32).map(|i| i / 8).collect();
    let large: Vec<u32> = (0..16000u32).map(|i| i / 8).collect();
    let mut header = header();
    header.points = 2000;
    let sections = vec![
        SectionInput::new("large", Element::U32, &large, Encoding::Shuffle4Zstd)
            .raw_within_budget(0),
        SectionInput::new("middle", Element::U32, &middle, Encoding::Shuffle4Zstd)
            .raw_within_budget(1),
        SectionInput::new("small", Element::U32, &small, Encoding::Shuffle4Zstd)
            .raw_within_budget(2),
        SectionInput::new("unranked", Element::U32, &small, Encoding::Shuffle4Zstd),
    ];
    let file =
        open(encode_step(header.clone(), &sections, Compression::Level(1)).unwrap()).unwrap();
    let encoding = |file: &CacheFile, name: &str| file.section(name).unwrap().encoding;
    // Rank 0 fits (4 pages + 15 more); rank 1 (8 more pages) would pass 92,000; rank 2 (one
    // more) fits.
    assert_eq!(encoding(&file, "large"), Encoding::Raw);
    assert_eq!(encoding(&file, "middle"), Encoding::Shuffle4Zstd);
    assert_eq!(encoding(&file, "small"), Encoding::Raw);
    assert_eq!(encoding(&file, "unranked"), Encoding::Shuffle4Zstd);
    let pages = |file: &CacheFile| -> u64 {
        file.header()
            .sections
            .iter()
            .map(|s| s.stored.div_ceil(ALIGN as u64) * ALIGN as u64)
            .sum()
    };
    assert!(
        pages(&file) <= 2000 * RAW_BUDGET_BYTES_PER_POINT,
        "{}",
        pages(&file)
    );
    // 1000 points, a budget of 46,000, and sections of 32,000, 16,000 and 8,000 bytes: the
    // first raw, the second compressed and the third raw would be some 40,200 bytes, within
    // it, but 12 pages (49,152 bytes) as laid out, so the third stays compressed too.
    header.points = 1000;
    let few = vec![
        SectionInput::new("large", Element::U32, &middle, Encoding::Shuffle4Zstd)
            .raw_within_budget(0),
        SectionInput::new(
            "middle",
            Element::U32,
            &middle[..4000],
            Encoding::Shuffle4Zstd,
        )
        .raw_within_budget(1),
        SectionInput::new("small", Element::U32, &small, Encoding::Shuffle4Zstd)
            .raw_within_budget(2),
        SectionInput::new("unranked", Element::U32, &small, Encoding::Shuffle4Zstd),
    ];
    let file = open(encode_step(header.clone(), &few, Compression::Level(1)).unwrap()).unwrap();
    assert_eq!(encoding(&file, "large"), Encoding::Raw);
    assert_eq!(encoding(&file, "middle"), Encoding::Shuffle4Zstd);
    assert_eq!(encoding(&file, "small"), Encoding::Shuffle4Zstd);
    assert!(
        pages(&file) <= 1000 * RAW_BUDGET_BYTES_PER_POINT,
        "{}",
        pages(&file)
    );
    // A step of no points has no budget: every ranked section stays compressed.
    header.points = 0;
    let file =
        open(encode_step(header.clone(), &sections, Compression::Level(1)).unwrap()).unwrap();
    assert!(
        file.header()
            .sections
            .iter()
            .all(|s| s.encoding != Encoding::Raw)
    );
    let file = open(encode_step(header, &sections, Compression::None).unwrap()).unwrap();
    assert!(
        file.header()
            .sections
            .iter()
            .all(|s| s.encoding == Encoding::Raw)
    );
}

/// A chunk table whose chunks would start off 8 bytes is refused when the file opens, naming
/// the section: such a run cannot be mapped where it goes in a GPU staging buffer (a bake of
/// 4-byte-multiple chunks made the H100's upload fail, then the process crash at exit).
#[test]
fn chunks_off_eight_bytes_are_refused_by_section() {
    let mut bytes = encode_step(header(), &sample_sections(), Compression::None).unwrap();
    // The preamble: the header's length at bytes 16..24, its hash at 24..32.
    let header_len = u64::from_le_bytes(bytes[16..24].try_into().unwrap()) as usize;
    let json = PREAMBLE_LEN..PREAMBLE_LEN + header_len;
    let text = String::from_utf8(bytes[json.clone()].to_vec()).unwrap();
    // Same length, so every offset stays: 65532 is a multiple of 4, not of 8.
    let patched = text.replacen("\"chunk_raw\":65536", "\"chunk_raw\":65532", 1);
    assert_ne!(patched, text, "no chunk_raw of 65536 in {text}");
    bytes[json.clone()].copy_from_slice(patched.as_bytes());
    let hash = xxhash_rust::xxh3::xxh3_64(patched.as_bytes());
    bytes[24..32].copy_from_slice(&hash.to_le_bytes());
    let err = open(bytes).unwrap_err().to_string();
    for part in ["test.slc", "'ids'", "65532", "positive multiple of 8"] {
        assert!(err.contains(part), "{part}: {err}");
    }
}
