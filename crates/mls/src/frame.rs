//! The local frame (u, v, n) at a reference point, derived from n alone (Duff et al. 2017,
//! "Building an Orthonormal Basis, Revisited"), so caches store only n.

use crate::real::{Real, V3};

/// Local frame: `u`, `v` span the support plane, `n` is its unit normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame<T> {
    pub u: V3<T>,
    pub v: V3<T>,
    pub n: V3<T>,
}

impl<T: Real> LocalFrame<T> {
    /// `n` must be unit length. Continuous everywhere except across n.z = 0 with n.z's sign.
    pub fn from_normal(n: V3<T>) -> LocalFrame<T> {
        let one = T::one();
        let sign = one.copysign(n.z);
        let a = -one / (sign + n.z);
        let b = n.x * n.y * a;
        let u = V3::new(one + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let v = V3::new(b, sign + n.y * n.y * a, -n.y);
        LocalFrame { u, v, n }
    }

    /// World vector to local coordinates.
    pub fn to_local(&self, w: V3<T>) -> V3<T> {
        V3::new(self.u.dot(w), self.v.dot(w), self.n.dot(w))
    }

    /// Local coordinates to a world vector.
    pub fn to_world(&self, l: V3<T>) -> V3<T> {
        self.u * l.x + self.v * l.y + self.n * l.z
    }
}
