//! What an exported frame or movie can carry besides the picture: a time label (top left)
//! and, where a field colours the surface, its colour legend with the field's name and range
//! (bottom right). Drawn on the CPU into the frame's sRGB bytes, with a font compiled in
//! (egui's Ubuntu Light), so that no system font is needed.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use slosh_render::{Colormap, Frame, GpuStep, TraceParams, cpu_shade};

/// A field's legend: its name, the values at the map's ends and the map.
#[derive(Debug, Clone, PartialEq)]
pub struct Legend {
    pub field: String,
    /// The range the map spans; `None` where the field has no finite value to span.
    pub range: Option<(f32, f32)>,
    pub colormap: Colormap,
}

/// What to draw over a frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Overlay {
    /// The step's simulated time and its bake index.
    pub time: Option<(f64, usize)>,
    pub legend: Option<Legend>,
}

/// A frame's RGB8 bytes, row-major, y down.
#[derive(Debug)]
struct Canvas<'a> {
    rgb: &'a mut [u8],
    width: u32,
    height: u32,
}

impl Canvas<'_> {
    /// Blends `colour` over pixel (x, y) with opacity `alpha`; outside the frame, nothing.
    fn blend(&mut self, x: i64, y: i64, colour: [u8; 3], alpha: f32) {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        let a = alpha.clamp(0.0, 1.0);
        for (c, &v) in self.rgb[i..i + 3].iter_mut().zip(&colour) {
            *c = (f32::from(*c) * (1.0 - a) + f32::from(v) * a).round() as u8;
        }
    }

    /// `text` with its top-left corner at (x, y), `size` pixels tall, in `colour` over a
    /// one-pixel dark shadow (legible on any background); the width it took.
    fn text(&mut self, text: &str, x: f32, y: f32, size: f32, colour: [u8; 3]) -> f32 {
        let Ok(font) = FontRef::try_from_slice(epaint_default_fonts::UBUNTU_LIGHT) else {
            return 0.0;
        };
        let scaled = font.as_scaled(PxScale::from(size));
        let baseline = y + scaled.ascent();
        for (offset, shade) in [(1.0, [0u8; 3]), (0.0, colour)] {
            let mut pen = x + offset;
            let mut previous = None;
            for ch in text.chars() {
                let id = font.glyph_id(ch);
                if let Some(prev) = previous {
                    pen += scaled.kern(prev, id);
                }
                let glyph = id.with_scale_and_position(size, point(pen, baseline + offset));
                if let Some(outline) = font.outline_glyph(glyph) {
                    let bounds = outline.px_bounds();
                    outline.draw(|gx, gy, coverage| {
                        let px = bounds.min.x as i64 + i64::from(gx);
                        let py = bounds.min.y as i64 + i64::from(gy);
                        self.blend(px, py, shade, coverage);
                    });
                }
                pen += scaled.h_advance(id);
                previous = Some(id);
            }
        }
        scaled_width(&font, text, size)
    }
}

fn scaled_width(font: &FontRef, text: &str, size: f32) -> f32 {
    let scaled = font.as_scaled(PxScale::from(size));
    text.chars()
        .map(|c| scaled.h_advance(font.glyph_id(c)))
        .sum()
}

impl Overlay {
    /// The time label of step `index` at `time`, and the legend of the field `step` is
    /// coloured by (its range as `params` maps it), if any.
    pub fn for_step(time: f64, index: usize, step: &GpuStep, params: &TraceParams) -> Overlay {
        Overlay {
            time: Some((time, index)),
            legend: step.field.as_ref().map(|(name, _, _)| Legend {
                field: name.clone(),
                range: params.field_range.or(step.field_range()),
                colormap: params.colormap,
            }),
        }
    }
}

/// A traced frame's RGB8 bytes, with `overlay` drawn over them where given.
pub fn frame_rgb(frame: &Frame, overlay: Option<&Overlay>) -> Vec<u8> {
    let mut rgb: Vec<u8> = frame
        .rgba
        .iter()
        .flat_map(|p| {
            let [r, g, b, _] = p.to_le_bytes();
            [r, g, b]
        })
        .collect();
    if let Some(overlay) = overlay {
        draw(&mut rgb, frame.width, frame.height, overlay);
    }
    rgb
}

/// The legend bar's colour at `t`: the map's value encoded to sRGB as the shade pass encodes
/// a lit colour, unlit.
pub fn legend_colour(colormap: Colormap, t: f32) -> [u8; 3] {
    colormap.at(t).map(|c| cpu_shade::srgb(f64::from(c)))
}

/// Draws `overlay` into a `width` × `height` frame's RGB8 bytes. Sizes follow the frame's
/// height, so a label reads the same at every export size.
pub fn draw(rgb: &mut [u8], width: u32, height: u32, overlay: &Overlay) {
    let canvas = &mut Canvas { rgb, width, height };
    let size = (canvas.height as f32 / 28.0).clamp(10.0, 64.0);
    let margin = size * 0.6;
    let white = [240, 240, 240];
    if let Some((time, step)) = overlay.time {
        canvas.text(
            &format!("t = {time:.4} s   step {step}"),
            margin,
            margin,
            size,
            white,
        );
    }
    if let Some(legend) = &overlay.legend {
        let (w, h) = (canvas.width as f32, canvas.height as f32);
        let bar_w = (w * 0.3).max(40.0);
        let bar_h = size * 0.8;
        let x0 = w - margin - bar_w;
        let y0 = h - margin - bar_h - size * 1.3;
        let (xa, xb) = (x0.round() as i64, (x0 + bar_w).round() as i64);
        for x in xa..xb {
            let t = (x - xa) as f32 / (xb - xa - 1).max(1) as f32;
            let colour = legend_colour(legend.colormap, t);
            for y in y0.round() as i64..(y0 + bar_h).round() as i64 {
                canvas.blend(x, y, colour, 1.0);
            }
        }
        let labels_y = y0 + bar_h + size * 0.2;
        let (low, high) = match legend.range {
            Some((min, max)) => (format!("{min:.4e}"), format!("{max:.4e}")),
            None => ("no finite value".to_string(), String::new()),
        };
        canvas.text(&low, x0, labels_y, size * 0.8, white);
        let font = FontRef::try_from_slice(epaint_default_fonts::UBUNTU_LIGHT);
        let high_w = font.map_or(0.0, |f| scaled_width(&f, &high, size * 0.8));
        canvas.text(&high, x0 + bar_w - high_w, labels_y, size * 0.8, white);
        canvas.text(&legend.field, x0, y0 - size * 1.2, size * 0.9, white);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The label and the legend change only their own corners; the bar's ends are the map's
    /// ends as the shade pass encodes them; labels are light on a dark frame.
    #[test]
    fn labels_and_the_legend_land_in_their_corners() {
        let (w, h) = (640u32, 400u32);
        let mut rgb = vec![20u8; (w * h * 3) as usize];
        let overlay = Overlay {
            time: Some((0.15, 12)),
            legend: Some(Legend {
                field: "pressure".into(),
                range: Some((-1.0, 2.5)),
                colormap: Colormap::CoolWarm,
            }),
        };
        draw(&mut rgb, w, h, &overlay);
        let px = |x: u32, y: u32| {
            let i = ((y * w + x) * 3) as usize;
            [rgb[i], rgb[i + 1], rgb[i + 2]]
        };
        let changed = |x0: u32, x1: u32, y0: u32, y1: u32| {
            (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|&(x, y)| px(x, y) != [20; 3])
                .count()
        };
        // The time label: top left, light.
        assert!(changed(0, w / 2, 0, h / 8) > 200);
        let brightest = (0..h / 8)
            .flat_map(|y| (0..w / 2).map(move |x| (x, y)))
            .map(|(x, y)| px(x, y)[0])
            .max()
            .unwrap();
        assert!(brightest > 200, "{brightest}");
        // The middle of the frame is untouched.
        assert_eq!(changed(w / 8, w / 2, h / 4, 3 * h / 4), 0);
        // The bar: the map's ends at its ends (row through its middle).
        let size = h as f32 / 28.0;
        let margin = size * 0.6;
        let bar_w = w as f32 * 0.3;
        let y = (h as f32 - margin - size * 1.3 - size * 0.4) as u32;
        let x0 = (w as f32 - margin - bar_w).round() as u32;
        let x1 = (w as f32 - margin).round() as u32 - 1;
        assert_eq!(px(x0, y), legend_colour(Colormap::CoolWarm, 0.0));
        assert_eq!(px(x1, y), legend_colour(Colormap::CoolWarm, 1.0));
    }
}
