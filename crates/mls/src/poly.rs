//! Bivariate polynomials of degree 0–3 in the local frame:
//! f(x, y) = a0 + a1 x + a2 y + a3 x² + a4 y² + a5 xy + a6 x³ + a7 y³ + a8 x²y + a9 xy²
//! (the thesis's order), and their restriction to a line.

use crate::real::Real;

/// Coefficients used by each degree: 1, 3, 6, 10.
pub const fn coefficient_count(degree: u8) -> usize {
    match degree {
        0 => 1,
        1 => 3,
        2 => 6,
        _ => 10,
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Poly<T> {
    pub degree: u8,
    /// Unused coefficients (beyond the degree) are zero.
    pub c: [T; 10],
}

/// The ten monomials at (x, y), in coefficient order.
pub fn monomials<T: Real>(x: T, y: T) -> [T; 10] {
    let one = T::one();
    [
        one,
        x,
        y,
        x * x,
        y * y,
        x * y,
        x * x * x,
        y * y * y,
        x * x * y,
        x * y * y,
    ]
}

impl<T: Real> Poly<T> {
    pub fn zero(degree: u8) -> Self {
        Poly {
            degree,
            c: [T::zero(); 10],
        }
    }

    pub fn eval(&self, x: T, y: T) -> T {
        let m = monomials(x, y);
        (0..coefficient_count(self.degree)).fold(T::zero(), |acc, k| acc + self.c[k] * m[k])
    }

    /// (∂f/∂x, ∂f/∂y).
    pub fn gradient(&self, x: T, y: T) -> (T, T) {
        let c = &self.c;
        let two = T::c(2.0);
        let three = T::c(3.0);
        let fx = c[1]
            + two * c[3] * x
            + c[5] * y
            + three * c[6] * x * x
            + two * c[8] * x * y
            + c[9] * y * y;
        let fy = c[2]
            + two * c[4] * y
            + c[5] * x
            + three * c[7] * y * y
            + c[8] * x * x
            + two * c[9] * x * y;
        (fx, fy)
    }

    /// Coefficients (ascending powers of s) of s ↦ f(x0 + s·dx, y0 + s·dy).
    pub fn along_line(&self, x0: T, y0: T, dx: T, dy: T) -> [T; 4] {
        let x = [x0, dx, T::zero(), T::zero()];
        let y = [y0, dy, T::zero(), T::zero()];
        let xx = mul(x, x);
        let yy = mul(y, y);
        let xy = mul(x, y);
        let terms: [[T; 4]; 10] = [
            [T::one(), T::zero(), T::zero(), T::zero()],
            x,
            y,
            xx,
            yy,
            xy,
            mul(xx, x),
            mul(yy, y),
            mul(xx, y),
            mul(x, yy),
        ];
        let mut out = [T::zero(); 4];
        for (k, term) in terms
            .iter()
            .enumerate()
            .take(coefficient_count(self.degree))
        {
            for (o, t) in out.iter_mut().zip(term) {
                *o = *o + self.c[k] * *t;
            }
        }
        out
    }
}

/// Product of two univariate polynomials, truncated at s³ (exact for the products used).
fn mul<T: Real>(a: [T; 4], b: [T; 4]) -> [T; 4] {
    let mut out = [T::zero(); 4];
    for i in 0..4 {
        for j in 0..4 - i {
            out[i + j] = out[i + j] + a[i] * b[j];
        }
    }
    out
}
