//! A movie written and read back: the MP4's track, sample count, size and duration are what
//! was pushed, and every frame decoded by OpenH264's own decoder is within 35 dB PSNR of the
//! frame given (the field's usual bar for visually lossless).

use std::io::Cursor;

use openh264::OpenH264API;
use openh264::decoder::{Decoder, DecoderConfig};
use slosh_movie::{MovieWriter, TIMESCALE};

const W: u32 = 320;
const H: u32 = 240;

/// A frame like a rendered one: a vertical gradient background and a shaded disc that moves
/// with `k`.
fn frame(k: usize) -> Vec<u8> {
    let mut rgb = Vec::with_capacity((W * H * 3) as usize);
    let (cx, cy, r) = (80.0 + 12.0 * k as f64, 120.0, 60.0);
    for y in 0..H {
        for x in 0..W {
            let (dx, dy) = ((f64::from(x) - cx) / r, (f64::from(y) - cy) / r);
            let d2 = dx * dx + dy * dy;
            let px = if d2 < 1.0 {
                let nz = (1.0 - d2).sqrt();
                let light = (0.3 + 0.7 * (0.4 * -dx + 0.3 * -dy + 0.85 * nz).max(0.0)) * 255.0;
                [light * 0.35, light * 0.6, light]
            } else {
                let t = f64::from(y) / f64::from(H);
                [40.0 + 60.0 * t, 50.0 + 60.0 * t, 70.0 + 80.0 * t]
            };
            rgb.extend(px.map(|c| c.round().clamp(0.0, 255.0) as u8));
        }
    }
    rgb
}

#[test]
fn frames_come_back_in_an_mp4_of_their_count_size_and_duration() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("movie.mp4");
    let frames: Vec<Vec<u8>> = (0..12).map(frame).collect();
    // Variable durations, as a series' own times give them.
    let seconds: Vec<f64> = (0..12).map(|k| 0.04 + 0.01 * (k % 3) as f64).collect();
    let mut movie = MovieWriter::new(&path, W, H, 24.0).unwrap();
    for (f, s) in frames.iter().zip(&seconds) {
        movie.push_rgb(f, *s).unwrap();
    }
    let stats = movie.finish().unwrap();
    let total: f64 = seconds.iter().sum();
    assert_eq!((stats.frames, stats.width, stats.height), (12, W, H));
    assert!((stats.seconds - total).abs() < 1e-4, "{} s", stats.seconds);

    let bytes = std::fs::read(&path).unwrap();
    let mut reader = mp4::Mp4Reader::read_header(Cursor::new(&bytes), bytes.len() as u64).unwrap();
    let tracks: Vec<_> = reader.tracks().values().collect();
    assert_eq!(tracks.len(), 1);
    let track = tracks[0];
    assert_eq!(track.media_type().unwrap(), mp4::MediaType::H264);
    assert_eq!(
        (u32::from(track.width()), u32::from(track.height())),
        (W, H)
    );
    assert_eq!(track.sample_count(), 12);
    assert_eq!(track.timescale(), TIMESCALE);
    let duration = track.duration().as_secs_f64();
    assert!((duration - total).abs() < 1e-3, "track lasts {duration} s");
    let (sps, pps) = (
        track.sequence_parameter_set().unwrap().to_vec(),
        track.picture_parameter_set().unwrap().to_vec(),
    );
    let id = track.track_id();

    let mut decoder =
        Decoder::with_api_config(OpenH264API::from_source(), DecoderConfig::new()).unwrap();
    let mut annex_b = Vec::new();
    for nal in [&sps, &pps] {
        annex_b.extend_from_slice(&[0, 0, 0, 1]);
        annex_b.extend_from_slice(nal);
    }
    let mut decoded = Vec::new();
    for i in 1..=12 {
        let sample = reader.read_sample(id, i).unwrap().unwrap();
        let mut rest = &sample.bytes[..];
        while rest.len() >= 4 {
            let n = u32::from_be_bytes([rest[0], rest[1], rest[2], rest[3]]) as usize;
            annex_b.extend_from_slice(&[0, 0, 0, 1]);
            annex_b.extend_from_slice(&rest[4..4 + n]);
            rest = &rest[4 + n..];
        }
        if let Some(image) = decoder.decode(&annex_b).unwrap() {
            let mut rgb = vec![0u8; (W * H * 3) as usize];
            image.write_rgb8(&mut rgb);
            decoded.push(rgb);
        }
        annex_b.clear();
    }
    for image in decoder.flush_remaining().unwrap() {
        let mut rgb = vec![0u8; (W * H * 3) as usize];
        image.write_rgb8(&mut rgb);
        decoded.push(rgb);
    }
    assert_eq!(decoded.len(), 12, "decoded frames");
    for (k, (got, want)) in decoded.iter().zip(&frames).enumerate() {
        let db = slosh_testkit::psnr_db(got, want);
        eprintln!("frame {k}: {db:.1} dB");
        assert!(db >= 35.0, "frame {k}: {db:.1} dB PSNR");
    }
}

#[test]
fn bad_sizes_and_frames_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odd.mp4");
    let message = MovieWriter::new(&path, 321, 240, 24.0)
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("odd.mp4") && message.contains("even"),
        "{message}"
    );
    let mut movie = MovieWriter::new(&path, W, H, 24.0).unwrap();
    let message = movie.push_rgb(&[0; 10], 0.1).unwrap_err().to_string();
    assert!(
        message.contains("odd.mp4") && message.contains("230400"),
        "{message}"
    );
    let message = movie.push_rgb(&frame(0), f64::NAN).unwrap_err().to_string();
    assert!(message.contains("positive duration"), "{message}");
    let message = movie.finish().unwrap_err().to_string();
    assert!(message.contains("no frames"), "{message}");
    assert!(!path.exists(), "a failed movie left a file");
}
