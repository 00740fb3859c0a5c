//! Frames to files: PNG images and `.npy` hit buffers, written atomically.

use std::path::Path;

use crate::error::{Error, Result};
use crate::tracer::Frame;

fn io(path: &Path, what: impl std::fmt::Display) -> Error {
    Error::Output {
        path: path.to_path_buf(),
        problem: what.to_string(),
    }
}

/// RGB8 pixels, row-major, as a PNG.
pub fn write_rgb_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(|e| io(path, e))?;
        w.write_image_data(rgb).map_err(|e| io(path, e))?;
    }
    slosh_fileio::atomic_write(path, &bytes).map_err(|e| io(path, e))
}

/// A frame's pixels (RGBA words) as an RGB PNG.
pub fn write_frame_png(path: &Path, frame: &Frame) -> Result<()> {
    let rgb: Vec<u8> = bytemuck::cast_slice::<u32, u8>(&frame.rgba)
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    write_rgb_png(path, frame.width, frame.height, &rgb)
}

/// float32 H×W×C little-endian `.npy`.
pub fn write_npy(
    path: &Path,
    height: u32,
    width: u32,
    channels: usize,
    data: &[f32],
) -> Result<()> {
    let dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({height}, {width}, {channels}), }}"
    );
    // Magic (6) + version (2) + length (2) + dict + newline, padded to 64 bytes.
    let total = (10 + dict.len() + 1).div_ceil(64) * 64;
    let mut bytes = Vec::with_capacity(total + data.len() * 4);
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&((total - 10) as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.resize(total - 1, b' ');
    bytes.push(b'\n');
    bytes.extend_from_slice(bytemuck::cast_slice(data));
    slosh_fileio::atomic_write(path, &bytes).map_err(|e| io(path, e))
}
