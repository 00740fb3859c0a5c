//! RGB frames into H.264 access units, as MP4 stores them: NAL units with 4-byte big-endian
//! lengths (not Annex-B start codes), the sequence and picture parameter sets kept apart for
//! the track's `avcC` box.

use openh264::OpenH264API;
use openh264::encoder::{
    BitRate, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, QpRange,
    RateControlMode,
};
use openh264::formats::{RgbSliceU8, YUVBuffer};

/// The coarsest quantiser the encoder may use. Rendered frames are smooth gradients with
/// sharp silhouettes; at 20 and finer a decoded frame stays above 35 dB PSNR against its
/// PNG (the movie test checks it).
pub const QUALITY_QP: u8 = 20;

/// Bits a pixel per frame the stream declares (what a player sizes its buffers and level
/// checks by); rate control is off, so it never coarsens a frame to meet it.
const BITS_PER_PIXEL: f64 = 0.6;

/// NAL unit types (H.264 table 7-1).
const NAL_SPS: u8 = 7;
const NAL_PPS: u8 = 8;

/// One frame encoded.
pub(crate) struct EncodedFrame {
    pub avcc: Vec<u8>,
    /// An IDR frame: a player may start decoding here.
    pub sync: bool,
}

pub(crate) struct H264 {
    encoder: Encoder,
    yuv: YUVBuffer,
    width: usize,
    height: usize,
    sps: Option<Vec<u8>>,
    pps: Option<Vec<u8>>,
}

/// `nal` without its Annex-B start code (00 00 01 or 00 00 00 01).
fn payload(nal: &[u8]) -> &[u8] {
    let zeros = nal.iter().take_while(|&&b| b == 0).count();
    if zeros >= 2 && nal.get(zeros) == Some(&1) {
        &nal[zeros + 1..]
    } else {
        nal
    }
}

impl H264 {
    pub(crate) fn new(width: u32, height: u32, fps: f64) -> Result<H264, openh264::Error> {
        let (w, h) = (width as usize, height as usize);
        let bits = (w as f64 * h as f64 * fps * BITS_PER_PIXEL).min(f64::from(u32::MAX)) as u32;
        // A key frame every two seconds, so that a player can seek.
        let period = (fps * 2.0).round().clamp(1.0, 1e6) as u32;
        // Rate control off: a rendered frame is quantised within the range alone, never
        // degraded or dropped to meet a bit rate.
        let config = EncoderConfig::new()
            .rate_control_mode(RateControlMode::Off)
            .bitrate(BitRate::from_bps(bits))
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            .qp(QpRange::new(0, QUALITY_QP))
            // Every frame is a step of the series: none may be dropped to meet the rate.
            .skip_frames(false)
            .intra_frame_period(IntraFramePeriod::from_num_frames(period));
        Ok(H264 {
            encoder: Encoder::with_api_config(OpenH264API::from_source(), config)?,
            yuv: YUVBuffer::new(w, h),
            width: w,
            height: h,
            sps: None,
            pps: None,
        })
    }

    /// Encodes `rgb` (width × height × 3 bytes; the caller checks the length).
    pub(crate) fn encode(&mut self, rgb: &[u8]) -> Result<EncodedFrame, openh264::Error> {
        self.yuv
            .read_rgb8(RgbSliceU8::new(rgb, (self.width, self.height)));
        let stream = self.encoder.encode(&self.yuv)?;
        let sync = stream.frame_type() == FrameType::IDR;
        let mut avcc = Vec::new();
        for l in 0..stream.num_layers() {
            let Some(layer) = stream.layer(l) else {
                continue;
            };
            for n in 0..layer.nal_count() {
                let Some(nal) = layer.nal_unit(n).map(payload) else {
                    continue;
                };
                let Some(&header) = nal.first() else {
                    continue;
                };
                match header & 0x1f {
                    NAL_SPS => {
                        self.sps.get_or_insert_with(|| nal.to_vec());
                    }
                    NAL_PPS => {
                        self.pps.get_or_insert_with(|| nal.to_vec());
                    }
                    _ => {
                        avcc.extend_from_slice(&(nal.len() as u32).to_be_bytes());
                        avcc.extend_from_slice(nal);
                    }
                }
            }
        }
        Ok(EncodedFrame { avcc, sync })
    }

    /// The sequence and picture parameter sets, once a frame has been encoded.
    pub(crate) fn parameter_sets(&self) -> Option<(&[u8], &[u8])> {
        Some((self.sps.as_deref()?, self.pps.as_deref()?))
    }
}
