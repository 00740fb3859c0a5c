//! Encoded frames into an MP4 file in memory: one H.264 video track (`avc1`) on the
//! [`TIMESCALE`](crate::TIMESCALE) clock, each sample shown for its own duration.

use std::io::Cursor;

use mp4::{
    AvcConfig, FourCC, MediaConfig, Mp4Config, Mp4Sample, Mp4Writer, TrackConfig, TrackType,
};

use crate::TIMESCALE;

/// One encoded frame and how long it is shown.
pub(crate) struct Sample {
    /// NAL units with 4-byte lengths.
    pub bytes: Vec<u8>,
    pub ticks: u32,
    pub sync: bool,
}

/// The MP4 bytes of `samples`.
pub(crate) fn mp4(
    width: u32,
    height: u32,
    sps: &[u8],
    pps: &[u8],
    samples: &[Sample],
) -> Result<Vec<u8>, mp4::Error> {
    let brand = |s: &str| s.parse::<FourCC>();
    let config = Mp4Config {
        major_brand: brand("isom")?,
        minor_version: 512,
        compatible_brands: vec![
            brand("isom")?,
            brand("iso2")?,
            brand("avc1")?,
            brand("mp41")?,
        ],
        timescale: 1000,
    };
    let mut writer = Mp4Writer::write_start(Cursor::new(Vec::new()), &config)?;
    writer.add_track(&TrackConfig {
        track_type: TrackType::Video,
        timescale: TIMESCALE,
        language: "und".into(),
        media_conf: MediaConfig::AvcConfig(AvcConfig {
            // The caller checked both fit.
            width: width as u16,
            height: height as u16,
            seq_param_set: sps.to_vec(),
            pic_param_set: pps.to_vec(),
        }),
    })?;
    let mut start = 0u64;
    for s in samples {
        writer.write_sample(
            1,
            &Mp4Sample {
                start_time: start,
                duration: s.ticks,
                rendering_offset: 0,
                is_sync: s.sync,
                bytes: bytes::Bytes::copy_from_slice(&s.bytes),
            },
        )?;
        start += u64::from(s.ticks);
    }
    writer.write_end()?;
    Ok(writer.into_writer().into_inner())
}
