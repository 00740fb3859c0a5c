//! The size a viewport is traced at: its pixels where the device can hold them, else fewer,
//! keeping the aspect.

/// The most pixels a frame is traced at (8K: 7680 × 4320).
pub const MAX_FRAME_PIXELS: u64 = 7680 * 4320;

/// The frame size for a viewport of `width` × `height` physical pixels (render scale
/// applied): as it is where the device can hold it, else scaled down, keeping its aspect, to
/// the device's largest texture (the texture is stretched over the viewport).
pub fn fit_texture(width: f32, height: f32, max_side: u32, max_pixels: u64) -> (u32, u32) {
    let (width, height) = (f64::from(width).max(1.0), f64::from(height).max(1.0));
    // And at most an 8K display's pixels, or what the device can bind for a frame's hits if
    // less: the hit buffers grow with the pixels (a window an X client sizes to 16000² would
    // ask for gigabytes), and past 8K a person cannot tell.
    let most = (MAX_FRAME_PIXELS as f64).min(max_pixels as f64);
    let shrink = (f64::from(max_side) / width.max(height))
        .min((most / (width * height)).sqrt())
        .min(1.0);
    // Rounded down when shrunk, so that the sides' product stays within the pixels allowed.
    let side = |v: f64| {
        let scaled = if shrink < 1.0 {
            (v * shrink).floor()
        } else {
            v.round()
        };
        (scaled as u32).clamp(1, max_side.max(1))
    };
    (side(width), side(height))
}

#[cfg(test)]
mod tests {
    use super::fit_texture;

    /// A viewport larger than the device's largest texture renders at the largest size that
    /// fits, keeping its aspect, instead of failing validation (issue 25, item 6).
    #[test]
    fn frames_fit_the_largest_texture_keeping_their_aspect() {
        let any = u64::MAX;
        assert_eq!(fit_texture(1600.0, 1000.0, 8192, any), (1600, 1000));
        assert_eq!(fit_texture(9000.0, 1000.0, 8192, any), (8192, 910));
        // Within the pixels allowed, however the sides round.
        let (w, h) = fit_texture(5730.0, 5856.0, 16384, 8_388_608);
        assert!(u64::from(w) * u64::from(h) <= 8_388_608, "{w}x{h}");
        assert_eq!(fit_texture(5000.0, 5000.0, 16384, any), (5000, 5000));
        // 16000² is past an 8K display's pixels: traced at 5760² and stretched.
        assert_eq!(fit_texture(16000.0, 16000.0, 16384, any), (5760, 5760));
        // A device that binds fewer pixels for a frame (lavapipe: 8M): fewer.
        assert_eq!(
            fit_texture(16000.0, 16000.0, 16384, 4_000_000),
            (2000, 2000)
        );
        assert_eq!(fit_texture(0.0, 0.0, 8192, any), (1, 1));
    }
}
