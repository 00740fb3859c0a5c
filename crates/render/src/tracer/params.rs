//! What a frame is traced and shaded with: the shade mode, the trace parameters, and the
//! uniforms they become with the camera in a step's local coordinates.

use slosh_mls::Camera;

use crate::colormap::Colormap;
use crate::field_map::FieldMap;
use crate::layout::{DEFAULT_KEY_LIGHT, GpuSettings};
use crate::upload::GpuStep;

/// What the shade pass draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ShadeMode {
    /// Blinn–Phong, coloured by the uploaded field if there is one.
    #[default]
    Shade,
    /// Normals as colours.
    Normals,
    /// Status and iteration heat map: green converged, yellow iteration limit, red no
    /// support or degenerate fit, blue droplet; brighter for more iterations.
    Status,
    /// Back-facing hits (normal along the ray) in magenta.
    Backfaces,
    /// Water over a checkerboard floor: Fresnel reflection and refraction by secondary
    /// rays, and the floor shadowed under the key light (`shaders/water.wgsl`).
    Water,
}

/// Tracing parameters, passed to the shaders as uniforms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceParams {
    /// Iterations counting the initial polynomial (1 = the baked polynomial only).
    pub iterations: u32,
    /// Degree of the refinement fits (the baked polynomial keeps its own).
    pub degree: u8,
    /// Multiplies each ball's baked smoothing length during refinement.
    pub h_factor: f32,
    /// Support normals from the covariance instead of the data normals.
    pub covariance: bool,
    /// Converged when successive hits differ by less than `epsilon` · h.
    pub epsilon: f32,
    pub mode: ShadeMode,
    /// The field values mapped to the ends of the colour map; `None`: the step's own range.
    pub field_range: Option<(f32, f32)>,
    pub colormap: Colormap,
    /// Direction towards the key light (normalised here); `DEFAULT_KEY_LIGHT` by default.
    pub key_light: [f32; 3],
}

impl Default for TraceParams {
    /// One iteration, quadratic fits, the baked smoothing length, data normals, shaded, the
    /// step's field range and the default key light.
    fn default() -> TraceParams {
        TraceParams {
            iterations: 1,
            degree: 2,
            h_factor: 1.0,
            covariance: false,
            epsilon: 1e-4,
            mode: ShadeMode::Shade,
            field_range: None,
            colormap: Colormap::Viridis,
            key_light: DEFAULT_KEY_LIGHT,
        }
    }
}

impl TraceParams {
    /// The step's baked settings with `iterations`.
    pub fn for_step(step: &GpuStep, iterations: u32) -> TraceParams {
        TraceParams {
            iterations,
            degree: step.info.degree,
            covariance: step.info.covariance,
            ..TraceParams::default()
        }
    }
}

fn to_f32(a: [f64; 3]) -> [f32; 3] {
    a.map(|c| c as f32)
}

/// The uniforms of a frame: the camera moved into the step's local coordinates.
pub fn settings(step: &GpuStep, camera: &Camera, params: &TraceParams) -> GpuSettings {
    let basis = camera.basis();
    let info = &step.info;
    let eye = info.transform.to_local(camera.eye);
    let (field_min, field_max) = params
        .field_range
        .or(step.field_range())
        .unwrap_or((0.0, 0.0));
    let field_map = FieldMap::new(field_min, field_max);
    GpuSettings {
        eye: to_f32(eye),
        width: camera.width,
        right: to_f32(basis.right),
        height: camera.height,
        up: to_f32(basis.up),
        iterations: params.iterations.max(1),
        forward: to_f32(basis.forward),
        degree: u32::from(params.degree.min(3)),
        epsilon: params.epsilon,
        h_factor: params.h_factor,
        normals_mode: u32::from(params.covariance || !info.has_normals),
        has_normals: u32::from(info.has_normals),
        point_count: info.point_count,
        sphere_count: info.sphere_count,
        cluster_size: info.cluster_size,
        mode: params.mode as u32,
        field_low: field_map.low,
        field_inverse_span: field_map.inverse_span,
        has_field: u32::from(step.field.is_some()),
        mask_words: info.mask_words,
        node_count: info.node_count,
        item_count: info.item_count,
        colormap: params.colormap as u32,
        first_row: 0,
        key_light: unit_or_default(params.key_light),
        row_stride: 1,
        surface_offset: info.surface_offset,
        h: info.h,
        per_point_h: u32::from(info.per_point_h),
        ball_degree: info.ball_degree.map_or(4, u32::from),
        field_exponent: field_map.exponent,
        field_clamp_low: field_map.clamp.0,
        field_clamp_high: field_map.clamp.1,
        pad: 0,
    }
}

/// `v` normalised; the default key light where `v` has no direction.
fn unit_or_default(v: [f32; 3]) -> [f32; 3] {
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len.is_finite() && len > 1e-6 {
        v.map(|c| c / len)
    } else {
        DEFAULT_KEY_LIGHT
    }
}
