//! Near-uniform point sets on the unit sphere, a torus and a unit square.

use glam::{DVec2, DVec3};
use std::f64::consts::{PI, TAU};

/// The golden ratio's fractional step, for Fibonacci lattices.
const GOLDEN: f64 = 0.618_033_988_749_894_8;

/// `n` points of a spherical Fibonacci lattice on the unit sphere (also their normals).
pub fn fibonacci_sphere(n: usize) -> Vec<DVec3> {
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = TAU * ((i as f64 * GOLDEN).fract());
            DVec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// `n` (u, v) angles of a Fibonacci lattice on a torus, with v distributed by the area element
/// (R + r cos v) so that the points are near-uniform on the surface.
pub fn fibonacci_torus(n: usize, major: f64, minor: f64) -> Vec<DVec2> {
    (0..n)
        .map(|i| {
            let target = (i as f64 + 0.5) / n as f64;
            // Invert CDF(v) = (R v + r sin v) / (2πR) by Newton from the uniform guess.
            let mut v = TAU * target;
            for _ in 0..30 {
                let f = (major * v + minor * v.sin()) / (TAU * major) - target;
                let df = (major + minor * v.cos()) / (TAU * major);
                v -= f / df;
            }
            let u = TAU * ((i as f64 * GOLDEN).fract());
            DVec2::new(u, v.rem_euclid(TAU))
        })
        .collect()
}

/// A regular grid over [0, a] × [0, b] with spacing close to `s`, cell centred.
pub fn grid(a: f64, b: f64, s: f64) -> Vec<DVec2> {
    let nx = ((a / s).round() as usize).max(1);
    let ny = ((b / s).round() as usize).max(1);
    let mut out = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            out.push(DVec2::new(
                (i as f64 + 0.5) * a / nx as f64,
                (j as f64 + 0.5) * b / ny as f64,
            ));
        }
    }
    out
}

/// Surface area of a torus.
pub fn torus_area(major: f64, minor: f64) -> f64 {
    4.0 * PI * PI * major * minor
}

/// Knud Thomsen's approximation of an ellipsoid's area (relative error ≤ 1.1 %), used only to
/// report a mean spacing.
pub fn ellipsoid_area(r: DVec3) -> f64 {
    let p = 1.6075;
    let (a, b, c) = (r.x.powf(p), r.y.powf(p), r.z.powf(p));
    4.0 * PI * ((a * b + a * c + b * c) / 3.0).powf(1.0 / p)
}

/// A lattice whose distances tie many times over (so a neighbour cap cuts through ties, and
/// the tie-breaking rule decides): `nx × ny × nz` points 1 apart in x and y and ½ in z, the
/// first `duplicates` of them twice, in a fixed shuffled order (multiplication by a prime
/// that does not divide the count).
pub fn tied_lattice(nx: usize, ny: usize, nz: usize, duplicates: usize) -> Vec<[f64; 3]> {
    const STRIDE: usize = 7919;
    let mut lattice: Vec<[f64; 3]> = Vec::with_capacity(nx * ny * nz + duplicates);
    for x in 0..nx {
        for y in 0..ny {
            for z in 0..nz {
                lattice.push([x as f64, y as f64, 0.5 * z as f64]);
            }
        }
    }
    lattice.extend_from_within(..duplicates.min(lattice.len()));
    let n = lattice.len();
    assert_ne!(
        n % STRIDE,
        0,
        "the shuffle needs a count {STRIDE} does not divide"
    );
    (0..n).map(|i| lattice[i * STRIDE % n]).collect()
}

/// A block of fluid particles: `side³` points `spacing` apart from `corner`, each moved by up
/// to a fifth of the spacing on every axis (a fixed pseudo-random pattern), so that no
/// distances tie: what an SPH or FPM solver's particles filling a volume look like.
pub fn jittered_block(side: usize, spacing: f64, corner: [f64; 3]) -> Vec<[f64; 3]> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut jitter = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state % 10_000) as f64 / 10_000.0 * 0.4 - 0.2) * spacing
    };
    let mut points = Vec::with_capacity(side * side * side);
    for x in 0..side {
        for y in 0..side {
            for z in 0..side {
                let p = [x, y, z].map(|c| c as f64 * spacing);
                points.push([
                    corner[0] + p[0] + jitter(),
                    corner[1] + p[1] + jitter(),
                    corner[2] + p[2] + jitter(),
                ]);
            }
        }
    }
    points
}
