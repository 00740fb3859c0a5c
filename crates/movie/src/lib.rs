//! Rendered frames into a movie: H.264 (Cisco's OpenH264, built from its bundled source, so a
//! fresh machine needs no system tools) in an MP4 file (the `mp4` crate), which every player
//! and slide tool reads.
//!
//! [`MovieWriter`] takes RGB8 frames one at a time, each with how long it is shown, encodes
//! them as it goes (`encode.rs`) and keeps only the compressed samples; [`MovieWriter::finish`]
//! lays out the MP4 (`mux.rs`) and writes it atomically.

mod encode;
mod mux;
mod timing;

use std::path::{Path, PathBuf};

pub use encode::QUALITY_QP;
pub use timing::{Timing, frame_seconds};

/// What can go wrong making a movie; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {problem}")]
    Frames { path: PathBuf, problem: String },
    #[error("{path}: the H.264 encoder failed: {source}")]
    Encoder {
        path: PathBuf,
        source: openh264::Error,
    },
    #[error("{path}: writing the MP4 failed: {source}")]
    Mux { path: PathBuf, source: mp4::Error },
    #[error(transparent)]
    Io(#[from] slosh_fileio::IoError),
}

pub type Result<T> = std::result::Result<T, Error>;

/// The MP4 track's clock: ticks per second (the usual one for video; 24, 25, 30 and 60 fps
/// divide it).
pub const TIMESCALE: u32 = 90_000;

/// What a finished movie holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovieStats {
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub seconds: f64,
    pub bytes: u64,
}

/// A movie being written: frames encoded as they come, the file written by [`finish`].
///
/// [`finish`]: MovieWriter::finish
pub struct MovieWriter {
    path: PathBuf,
    width: u32,
    height: u32,
    encoder: encode::H264,
    samples: Vec<mux::Sample>,
}

impl std::fmt::Debug for MovieWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MovieWriter")
            .field("path", &self.path)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("frames", &self.samples.len())
            .finish()
    }
}

impl MovieWriter {
    /// A movie of `width` × `height` frames (both even: H.264 stores colour at half
    /// resolution), to be written to `path`, at about `fps` frames a second (the rate
    /// control's hint; each frame's own duration is what the file records).
    pub fn new(path: &Path, width: u32, height: u32, fps: f64) -> Result<MovieWriter> {
        let problem = |problem: String| Error::Frames {
            path: path.to_path_buf(),
            problem,
        };
        if width == 0 || height == 0 || !width.is_multiple_of(2) || !height.is_multiple_of(2) {
            return Err(problem(format!(
                "a {width}×{height} movie: H.264 needs an even width and height (e.g. --size {}x{})",
                width.max(2) & !1,
                height.max(2) & !1
            )));
        }
        if width > u32::from(u16::MAX) || height > u32::from(u16::MAX) {
            return Err(problem(format!(
                "a {width}×{height} movie: MP4 holds at most 65535 pixels a side"
            )));
        }
        if !(fps.is_finite() && fps > 0.0) {
            return Err(problem(format!(
                "{fps} frames a second: expected a positive rate"
            )));
        }
        let encoder = encode::H264::new(width, height, fps).map_err(|source| Error::Encoder {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(MovieWriter {
            path: path.to_path_buf(),
            width,
            height,
            encoder,
            samples: Vec::new(),
        })
    }

    /// Where the movie will be written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frames encoded so far.
    pub fn frames(&self) -> usize {
        self.samples.len()
    }

    /// Encodes one frame, RGB8 row-major with y down, shown for `seconds` (rounded to the
    /// track's clock, at least one tick).
    pub fn push_rgb(&mut self, rgb: &[u8], seconds: f64) -> Result<()> {
        let expected = self.width as usize * self.height as usize * 3;
        if rgb.len() != expected {
            return Err(Error::Frames {
                path: self.path.clone(),
                problem: format!(
                    "frame {} has {} bytes; a {}×{} RGB frame has {expected}",
                    self.samples.len(),
                    rgb.len(),
                    self.width,
                    self.height
                ),
            });
        }
        if !(seconds.is_finite() && seconds > 0.0) {
            return Err(Error::Frames {
                path: self.path.clone(),
                problem: format!(
                    "frame {} is shown for {seconds} s: expected a positive duration",
                    self.samples.len()
                ),
            });
        }
        let ticks = (seconds * f64::from(TIMESCALE))
            .round()
            .clamp(1.0, f64::from(u32::MAX)) as u32;
        let frame = self.encoder.encode(rgb).map_err(|source| Error::Encoder {
            path: self.path.clone(),
            source,
        })?;
        self.samples.push(mux::Sample {
            bytes: frame.avcc,
            ticks,
            sync: frame.sync,
        });
        Ok(())
    }

    /// Lays out the MP4 and writes it atomically (the file appears whole or not at all).
    pub fn finish(self) -> Result<MovieStats> {
        let fail = |problem: String| Error::Frames {
            path: self.path.clone(),
            problem,
        };
        if self.samples.is_empty() {
            return Err(fail("no frames: a movie needs at least one".into()));
        }
        let (sps, pps) = self.encoder.parameter_sets().ok_or_else(|| {
            fail("the encoder gave no sequence and picture parameter sets".into())
        })?;
        let bytes =
            mux::mp4(self.width, self.height, sps, pps, &self.samples).map_err(|source| {
                Error::Mux {
                    path: self.path.clone(),
                    source,
                }
            })?;
        slosh_fileio::atomic_write(&self.path, &bytes)?;
        let ticks: u64 = self.samples.iter().map(|s| u64::from(s.ticks)).sum();
        Ok(MovieStats {
            frames: self.samples.len(),
            width: self.width,
            height: self.height,
            seconds: ticks as f64 / f64::from(TIMESCALE),
            bytes: bytes.len() as u64,
        })
    }
}
