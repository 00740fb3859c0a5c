//! The float types the algorithm runs in (f32 and f64) and a 3-vector over them.

use std::fmt::Debug;
use std::ops::{Add, Mul, Neg, Sub};

use num_traits::Float;

/// f32 or f64. The f64 build is the oracle; the f32 build mirrors the GPU.
pub trait Real: Float + Debug + Default + Send + Sync + 'static {
    /// A constant given in f64, rounded to this type.
    fn c(v: f64) -> Self;
    fn to_f64(self) -> f64;
}

impl Real for f32 {
    fn c(v: f64) -> f32 {
        v as f32
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}

impl Real for f64 {
    fn c(v: f64) -> f64 {
        v
    }
    fn to_f64(self) -> f64 {
        self
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct V3<T> {
    pub x: T,
    pub y: T,
    pub z: T,
}

impl<T: Real> V3<T> {
    pub fn new(x: T, y: T, z: T) -> Self {
        V3 { x, y, z }
    }

    pub fn zero() -> Self {
        V3::new(T::zero(), T::zero(), T::zero())
    }

    pub fn from_f64(v: [f64; 3]) -> Self {
        V3::new(T::c(v[0]), T::c(v[1]), T::c(v[2]))
    }

    pub fn to_f64(self) -> [f64; 3] {
        [self.x.to_f64(), self.y.to_f64(), self.z.to_f64()]
    }

    pub fn dot(self, o: Self) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    pub fn cross(self, o: Self) -> Self {
        V3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }

    pub fn length_squared(self) -> T {
        self.dot(self)
    }

    pub fn length(self) -> T {
        self.length_squared().sqrt()
    }

    /// Unit vector, or `None` for zero, tiny or non-finite input.
    pub fn normalized(self) -> Option<Self> {
        let len = self.length();
        (len.is_finite() && len > T::min_positive_value().sqrt()).then(|| self * (T::one() / len))
    }

    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
}

impl<T: Real> Add for V3<T> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl<T: Real> Sub for V3<T> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        V3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl<T: Real> Mul<T> for V3<T> {
    type Output = Self;
    fn mul(self, s: T) -> Self {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
}

impl<T: Real> Neg for V3<T> {
    type Output = Self;
    fn neg(self) -> Self {
        V3::new(-self.x, -self.y, -self.z)
    }
}
