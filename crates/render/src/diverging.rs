//! Moreland's cool–warm diverging map ("Diverging Color Maps for Scientific Visualization",
//! 2009): his two endpoints interpolated in Msh (polar CIELAB), through an unsaturated
//! midpoint of magnitude at least 88, with the hue spun where one end is unsaturated, then
//! tabulated at 33 points (his table's spacing) and interpolated linearly by the shader.

use std::sync::OnceLock;

/// Entries of the table.
pub const COOL_WARM_ENTRIES: usize = 33;

/// The endpoints, sRGB: his blue and red.
const COOL: [f64; 3] = [0.230, 0.299, 0.754];
const WARM: [f64; 3] = [0.706, 0.016, 0.150];

/// The D65 white point in XYZ.
const WHITE: [f64; 3] = [0.95047, 1.0, 1.08883];

fn to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn to_srgb(c: f64) -> f64 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB to Msh: magnitude, saturation (angle from the L axis), hue.
fn msh(rgb: [f64; 3]) -> [f64; 3] {
    let [r, g, b] = rgb.map(to_linear);
    let xyz = [
        0.4124 * r + 0.3576 * g + 0.1805 * b,
        0.2126 * r + 0.7152 * g + 0.0722 * b,
        0.0193 * r + 0.1192 * g + 0.9505 * b,
    ];
    let f = |t: f64| {
        if t > 0.008856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let [fx, fy, fz] = std::array::from_fn(|i| f(xyz[i] / WHITE[i]));
    let (l, a, bb) = (116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz));
    let m = (l * l + a * a + bb * bb).sqrt();
    [m, (l / m).acos(), bb.atan2(a)]
}

/// Msh back to sRGB, clamped to the gamut.
fn srgb(msh: [f64; 3]) -> [f64; 3] {
    let [m, s, h] = msh;
    let (l, a, b) = (m * s.cos(), m * s.sin() * h.cos(), m * s.sin() * h.sin());
    let fy = (l + 16.0) / 116.0;
    let f = [fy + a / 500.0, fy, fy - b / 200.0];
    let finv = |t: f64| {
        let cube = t * t * t;
        if cube > 0.008856 {
            cube
        } else {
            (t - 16.0 / 116.0) / 7.787
        }
    };
    let [x, y, z]: [f64; 3] = std::array::from_fn(|i| WHITE[i] * finv(f[i]));
    [
        3.2406 * x - 1.5372 * y - 0.4986 * z,
        -0.9689 * x + 1.8758 * y + 0.0415 * z,
        0.0557 * x - 0.2040 * y + 1.0570 * z,
    ]
    .map(to_srgb)
}

/// The hue of the unsaturated end, spun so the path stays perceptually even.
fn adjust_hue(saturated: [f64; 3], m_unsaturated: f64) -> f64 {
    let [m, s, h] = saturated;
    if m >= m_unsaturated {
        return h;
    }
    let spin = s * (m_unsaturated * m_unsaturated - m * m).sqrt() / (m * s.sin());
    if h > -std::f64::consts::FRAC_PI_3 {
        h + spin
    } else {
        h - spin
    }
}

/// The map at `t` in [0, 1], sRGB.
fn cool_warm(t: f64) -> [f64; 3] {
    let (mut a, mut b, mut t) = (msh(COOL), msh(WARM), t);
    // Saturated, distinct hues: through the unsaturated middle.
    if a[1] > 0.05 && b[1] > 0.05 && (a[2] - b[2]).abs() > std::f64::consts::FRAC_PI_3 {
        let middle = a[0].max(b[0]).max(88.0);
        if t < 0.5 {
            b = [middle, 0.0, 0.0];
            t *= 2.0;
        } else {
            a = [middle, 0.0, 0.0];
            t = 2.0 * t - 1.0;
        }
    }
    if a[1] < 0.05 && b[1] > 0.05 {
        a[2] = adjust_hue(b, a[0]);
    } else if b[1] < 0.05 && a[1] > 0.05 {
        b[2] = adjust_hue(a, b[0]);
    }
    srgb(std::array::from_fn(|i| (1.0 - t) * a[i] + t * b[i]))
}

/// The tabulated map, sRGB in f32 (made once).
pub fn cool_warm_table() -> &'static [[f32; 3]; COOL_WARM_ENTRIES] {
    static TABLE: OnceLock<[[f32; 3]; COOL_WARM_ENTRIES]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|k| {
            cool_warm(k as f64 / (COOL_WARM_ENTRIES - 1) as f64).map(|c| c as f32)
        })
    })
}
