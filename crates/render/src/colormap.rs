//! The field colour maps, one source for the shade pass and any legend: viridis (perceptually
//! uniform, sequential), a degree-6 fit of matplotlib's table (of its sRGB values); cool–warm
//! (Moreland 2009, diverging: blue through a neutral grey to red, for signed fields such as
//! pressure around zero), tabulated from his Msh interpolation (`diverging.rs`); and
//! greyscale. The shade pass lights the colour and encodes it to sRGB as it does every colour,
//! so a legend that matches the frame applies that same encoding. `shade.wgsl` gets its
//! `colormap` function generated from these definitions.

/// The colour of a hit whose field value is missing (no finite value among its neighbours':
/// `slosh_cache::FIELD_MISSING`), before lighting: magenta, which none of the maps holds.
pub const MISSING_FIELD_COLOUR: [f32; 3] = [0.85, 0.0, 0.85];

/// A field colour map, as the shade pass's `colormap` uniform selects it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u32)]
pub enum Colormap {
    #[default]
    Viridis = 0,
    CoolWarm = 1,
    Grey = 2,
}

impl Colormap {
    pub const ALL: [Colormap; 3] = [Colormap::Viridis, Colormap::CoolWarm, Colormap::Grey];

    /// The name flags and menus use.
    pub fn name(self) -> &'static str {
        match self {
            Colormap::Viridis => "viridis",
            Colormap::CoolWarm => "coolwarm",
            Colormap::Grey => "grey",
        }
    }

    /// The map at `t` (clamped to [0, 1]), as the shader computes it before lighting.
    pub fn at(self, t: f32) -> [f32; 3] {
        match self {
            Colormap::Viridis => viridis(t),
            Colormap::CoolWarm => {
                let table = crate::diverging::cool_warm_table();
                let x = t.clamp(0.0, 1.0) * (table.len() - 1) as f32;
                let i = (x.floor() as usize).min(table.len() - 2);
                let f = x - i as f32;
                std::array::from_fn(|c| table[i][c] + f * (table[i + 1][c] - table[i][c]))
            }
            Colormap::Grey => [t.clamp(0.0, 1.0); 3],
        }
    }
}

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

/// The WGSL `colormap(which, t)` of [`Colormap::at`]: `viridis` over [`VIRIDIS`], the
/// cool–warm table interpolated the same way, and grey.
pub fn colormap_wgsl() -> String {
    let table = crate::diverging::cool_warm_table();
    let n = table.len();
    let mut out = viridis_wgsl();
    out += &format!(
        "const FIELD_MISSING: f32 = {:e};\nconst MISSING_FIELD_COLOUR: vec3<f32> = {};\n",
        slosh_cache::FIELD_MISSING,
        vec3_literal(&MISSING_FIELD_COLOUR)
    );
    out += &format!("const COOL_WARM: array<vec3<f32>, {n}> = array<vec3<f32>, {n}>(\n");
    for c in table {
        out += &format!("    {},\n", vec3_literal(c));
    }
    out += ");\n";
    for m in Colormap::ALL {
        out += &format!(
            "const COLORMAP_{}: u32 = {}u;\n",
            m.name().to_uppercase(),
            m as u32
        );
    }
    out += &format!(
        "fn colormap(which: u32, t_in: f32) -> vec3<f32> {{
    let t = clamp(t_in, 0.0, 1.0);
    if which == COLORMAP_COOLWARM {{
        let x = t * {last}.0;
        let i = min(u32(floor(x)), {below}u);
        let f = x - f32(i);
        return COOL_WARM[i] + f * (COOL_WARM[i + 1u] - COOL_WARM[i]);
    }}
    if which == COLORMAP_GREY {{
        return vec3<f32>(t);
    }}
    return viridis(t);
}}
",
        last = n - 1,
        below = n - 2
    );
    out
}

/// `vec3<f32>(…)` of `c`, each component written so that WGSL reads back the same f32.
fn vec3_literal(c: &[f32; 3]) -> String {
    let lit = |v: f32| {
        let s = format!("{v:?}");
        if s.contains('.') { s } else { format!("{s}.0") }
    };
    format!("vec3<f32>({}, {}, {})", lit(c[0]), lit(c[1]), lit(c[2]))
}

/// The WGSL `viridis` function over [`VIRIDIS`].
fn viridis_wgsl() -> String {
    let mut out =
        String::from("fn viridis(t_in: f32) -> vec3<f32> {\n    let t = clamp(t_in, 0.0, 1.0);\n");
    for (i, c) in VIRIDIS.iter().enumerate() {
        out += &format!("    let c{i} = {};\n", vec3_literal(c));
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
        let wgsl = colormap_wgsl();
        let table = crate::diverging::cool_warm_table();
        for c in VIRIDIS.iter().flatten().chain(table.iter().flatten()) {
            assert!(wgsl.contains(&format!("{c:?}")), "{c} missing from {wgsl}");
        }
    }
}

#[cfg(test)]
mod map_tests {
    use super::Colormap;

    /// Each map runs from its published first colour to its last; the diverging one passes
    /// through a neutral grey at the middle, and grey is the identity.
    #[test]
    fn maps_have_their_published_ends() {
        let close =
            |a: [f32; 3], b: [f32; 3], tol: f32| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol);
        let cw = Colormap::CoolWarm;
        assert!(
            close(cw.at(0.0), [0.230, 0.299, 0.754], 2e-3),
            "{:?}",
            cw.at(0.0)
        );
        assert!(
            close(cw.at(1.0), [0.706, 0.016, 0.150], 2e-3),
            "{:?}",
            cw.at(1.0)
        );
        // Moreland's table: 221, 221, 221 at the middle.
        assert!(close(cw.at(0.5), [0.8667; 3], 0.01), "{:?}", cw.at(0.5));
        assert_eq!(Colormap::Grey.at(0.25), [0.25; 3]);
        assert_eq!(Colormap::Viridis.at(0.3), super::viridis(0.3));
    }
}
