//! The water pass's stage and optics (`shaders/water.wgsl`), defined once: the shader gets
//! them as generated constants (`shaders::shared_constants_wgsl`), and whoever predicts the
//! pass's image (its tests) reads them here.

/// The floor lies this fraction of the scene's extent (the BVH root box's largest side)
/// below the scene's lowest point.
pub const FLOOR_BELOW: f32 = 0.02;
/// Checker squares per scene extent.
pub const SQUARES_PER_EXTENT: f32 = 8.0;
/// Linear albedo of the light and the dark checker squares.
pub const CHECKER_LIGHT: f32 = 0.8;
pub const CHECKER_DARK: f32 = 0.3;
/// Light on the floor where the fluid shadows the key light; in the open, this plus
/// (1 − this) × the key light's height (its z).
pub const FLOOR_AMBIENT: f32 = 0.25;
/// The fluid's refractive index.
pub const WATER_IOR: f32 = 1.33;
/// Light absorbed per unit of path through the fluid, per channel, in scene extents: water's
/// red absorption, exaggerated to read at the scale of a tank.
pub const ABSORPTION: [f32; 3] = [0.9, 0.25, 0.12];
/// The sky at the horizon and at the zenith.
pub const SKY_HORIZON: [f32; 3] = [0.55, 0.62, 0.7];
pub const SKY_ZENITH: [f32; 3] = [0.18, 0.32, 0.55];
/// The key light's highlight on the water: strength and Blinn–Phong exponent.
pub const HIGHLIGHT: f32 = 0.8;
pub const HIGHLIGHT_EXPONENT: f32 = 120.0;

/// The constants above as WGSL declarations (names prefixed `WATER_` where bare).
pub(crate) fn water_wgsl() -> String {
    let v3 = |v: [f32; 3]| format!("vec3<f32>({:?}, {:?}, {:?})", v[0], v[1], v[2]);
    [
        format!("const WATER_FLOOR_BELOW: f32 = {FLOOR_BELOW:?};"),
        format!("const WATER_SQUARES_PER_EXTENT: f32 = {SQUARES_PER_EXTENT:?};"),
        format!("const WATER_CHECKER_LIGHT: f32 = {CHECKER_LIGHT:?};"),
        format!("const WATER_CHECKER_DARK: f32 = {CHECKER_DARK:?};"),
        format!("const WATER_FLOOR_AMBIENT: f32 = {FLOOR_AMBIENT:?};"),
        format!("const WATER_IOR: f32 = {WATER_IOR:?};"),
        format!("const WATER_ABSORPTION: vec3<f32> = {};", v3(ABSORPTION)),
        format!("const WATER_SKY_HORIZON: vec3<f32> = {};", v3(SKY_HORIZON)),
        format!("const WATER_SKY_ZENITH: vec3<f32> = {};", v3(SKY_ZENITH)),
        format!("const WATER_HIGHLIGHT: f32 = {HIGHLIGHT:?};"),
        format!("const WATER_HIGHLIGHT_EXPONENT: f32 = {HIGHLIGHT_EXPONENT:?};"),
    ]
    .join("\n")
        + "\n"
}
