//! Element types of the GPU sections: `#[repr(C)]` Pod structs laid out exactly as the WGSL
//! storage-buffer structs of the same names (vec3 + scalar packs into 16 bytes there).

use bytemuck::{Pod, Zeroable};

/// `struct Point { position: vec3<f32>, radius: f32 }`: a point and its radius of trust.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuPoint {
    pub position: [f32; 3],
    pub radius: f32,
}

/// `struct Normal { normal: vec3<f32>, pad: f32 }`: a unit data normal (zero when unusable).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuNormal {
    pub normal: [f32; 3],
    pub pad: f32,
}

/// `struct Ball { normal: vec3<f32>, h: f32, coeffs: array<f32, 10>, degree: u32, state: u32 }`:
/// the initial support normal and polynomial of a ball (coefficients in coordinates scaled
/// by 1/h, unused ones zero).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuBall {
    pub normal: [f32; 3],
    pub h: f32,
    pub coeffs: [f32; 10],
    /// Degree of the stored polynomial (lower than requested where the data could not carry it).
    pub degree: u32,
    /// Low 2 bits: [`BallState`]; for droplets, bits 2.. hold the sphere index.
    pub state: u32,
}

/// `struct Sphere { centre: vec3<f32>, radius: f32 }`: a droplet.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuSphere {
    pub centre: [f32; 3],
    pub radius: f32,
}

/// `struct BvhNode { lo: vec3<f32>, count: u32, hi: vec3<f32>, first: u32 }`: a BVH2 node.
/// `count == 0`: inner node, children at `first` and `first + 1`. `count > 0`: leaf over
/// `bvh_items[first .. first + count]`. Node 0 is the root.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuBvhNode {
    pub lo: [f32; 3],
    pub count: u32,
    pub hi: [f32; 3],
    pub first: u32,
}

/// What a ball is, in the low two bits of [`GpuBall::state`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BallState {
    /// Fitted at the requested degree.
    Full = 0,
    /// Fitted at a lower degree (`GpuBall::degree`).
    Degraded = 1,
    /// No support plane or fit: never a candidate.
    Unfitted = 2,
    /// Member of a droplet drawn as a sphere.
    Droplet = 3,
}

impl GpuBall {
    pub fn kind(&self) -> BallState {
        match self.state & 3 {
            0 => BallState::Full,
            1 => BallState::Degraded,
            2 => BallState::Unfitted,
            _ => BallState::Droplet,
        }
    }

    /// The droplet sphere this ball belongs to.
    pub fn sphere(&self) -> Option<u32> {
        (self.kind() == BallState::Droplet).then_some(self.state >> 2)
    }

    pub fn state_word(kind: BallState, sphere: u32) -> u32 {
        kind as u32 | (sphere << 2)
    }
}

/// Element types a section can hold, by the name the header records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Element {
    Point,
    Normal,
    Ball,
    Sphere,
    BvhNode,
    U32,
    F32,
    Vec4,
}

impl Element {
    pub const ALL: [Element; 8] = [
        Element::Point,
        Element::Normal,
        Element::Ball,
        Element::Sphere,
        Element::BvhNode,
        Element::U32,
        Element::F32,
        Element::Vec4,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Element::Point => "point",
            Element::Normal => "normal",
            Element::Ball => "ball",
            Element::Sphere => "sphere",
            Element::BvhNode => "bvh_node",
            Element::U32 => "u32",
            Element::F32 => "f32",
            Element::Vec4 => "vec4<f32>",
        }
    }

    pub fn size(self) -> usize {
        match self {
            Element::Point | Element::Normal | Element::Sphere | Element::Vec4 => 16,
            Element::Ball => size_of::<GpuBall>(),
            Element::BvhNode => size_of::<GpuBvhNode>(),
            Element::U32 | Element::F32 => 4,
        }
    }

    pub fn from_name(name: &str) -> Option<Element> {
        Element::ALL.into_iter().find(|e| e.name() == name)
    }
}
