//! The field colour map, one source for the shade pass and any legend: viridis (perceptually
//! uniform), a degree-6 fit of matplotlib's table (of its sRGB values). The shade pass lights
//! the colour and encodes it to sRGB as it does every colour, so a legend that matches the
//! frame applies that same encoding. `shade.wgsl` gets its `viridis` function generated from
//! these coefficients.

/// Coefficients c0..c6 of `c0 + t (c1 + t (c2 + …))`, per channel, with the digits of the
/// published fit (rounded to f32 here as WGSL rounds them).
#[allow(clippy::excessive_precision)]
pub const VIRIDIS: [[f32; 3]; 7] = [
    [0.2777273, 0.0054073, 0.3340998],
    [0.1050930, 1.4046135, 1.3845901],
    [-0.3308618, 0.2148476, 0.0950952],
    [-4.6342305, -5.7991009, -19.3324410],
    [6.2282699, 14.1799333, 56.6905526],
    [4.7763849, -13.7451453, -65.3530327],
    [-5.4354558, 4.6458524, 26.3124352],
];

/// The colour map at `t` (clamped to [0, 1]), as the shader computes it before lighting.
pub fn viridis(t: f32) -> [f32; 3] {
    let t = t.clamp(0.0, 1.0);
    std::array::from_fn(|c| {
        let v = VIRIDIS.iter().rev().fold(0.0f32, |acc, k| k[c] + t * acc);
        v.max(0.0)
    })
}

/// The WGSL `viridis` function over [`VIRIDIS`].
pub fn viridis_wgsl() -> String {
    let lit = |v: f32| {
        let s = format!("{v:?}");
        if s.contains('.') { s } else { format!("{s}.0") }
    };
    let mut out =
        String::from("fn viridis(t_in: f32) -> vec3<f32> {\n    let t = clamp(t_in, 0.0, 1.0);\n");
    for (i, c) in VIRIDIS.iter().enumerate() {
        out += &format!(
            "    let c{i} = vec3<f32>({}, {}, {});\n",
            lit(c[0]),
            lit(c[1]),
            lit(c[2])
        );
    }
    out += "    return max(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), vec3<f32>(0.0));\n}\n";
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_are_the_matplotlib_ends() {
        // matplotlib's viridis(0) is #440154 and viridis(1) #fde725.
        let to8 = |c: [f32; 3]| c.map(|v| (v * 255.0).round() as i32);
        let (lo, hi) = (to8(viridis(0.0)), to8(viridis(1.0)));
        for (got, want) in lo
            .iter()
            .zip([0x44, 0x01, 0x54])
            .chain(hi.iter().zip([0xfd, 0xe7, 0x25]))
        {
            assert!((got - want).abs() <= 6, "{lo:?} {hi:?}");
        }
        let wgsl = viridis_wgsl();
        for c in VIRIDIS.iter().flatten() {
            assert!(wgsl.contains(&format!("{c:?}")), "{c} missing from {wgsl}");
        }
    }
}
