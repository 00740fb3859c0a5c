//! The tank family (tank, droplets, wave): a sloshing free surface in a box with walls and an
//! interior, standing waves, and ballistic droplets leaving the crests.

use std::f64::consts::PI;

use glam::DVec3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{Droplet, GRAVITY, Particles, Scene, SceneKind};
use crate::sampling::{fibonacci_sphere, grid};
use crate::truth::{Truth, Wave, height, height_gradient};

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct TankShape {
    pub(super) size: [f64; 2],
    pub(super) depth: f64,
}

pub(super) const TANK: TankShape = TankShape {
    size: [2.0, 1.0],
    depth: 0.5,
};

impl Scene {
    /// The free surface's truth at `time`, with the droplets in flight.
    pub(super) fn tank_truth(&self, time: f64) -> Truth {
        let field = Truth::HeightField {
            origin: DVec3::ZERO,
            size: TANK.size,
            depth: TANK.depth,
            time,
            waves: self.waves.clone(),
        };
        let spheres: Vec<Truth> = self
            .droplets
            .iter()
            .filter_map(|d| {
                self.droplet_center(d, time).map(|c| Truth::Sphere {
                    center: c,
                    radius: d.radius,
                })
            })
            .collect();
        if spheres.is_empty() {
            field
        } else {
            let mut parts = vec![field];
            parts.extend(spheres);
            Truth::Union { parts }
        }
    }

    pub(super) fn tank_particles(&self, t: f64, rng: &mut ChaCha8Rng, out: &mut Particles) {
        let s = self.spacing;
        let [lx, ly] = TANK.size;
        let d = TANK.depth;
        let jitter = 0.15 * s;
        // Free surface: jittered grid, exactly on the surface. Flagged.
        for q in grid(lx, ly, s) {
            let x = (q.x + rng.random_range(-jitter..=jitter)).clamp(0.0, lx);
            let y = (q.y + rng.random_range(-jitter..=jitter)).clamp(0.0, ly);
            let z = d + height(&self.waves, t, x, y);
            let (hx, hy) = height_gradient(&self.waves, t, x, y);
            out.push(
                DVec3::new(x, y, z),
                DVec3::new(-hx, -hy, 1.0).normalize(),
                d,
                true,
            );
        }
        // Interior: lattice below the surface, normals of the surface above. Unflagged.
        for q in grid(lx, ly, s) {
            let top = d + height(&self.waves, t, q.x, q.y);
            let (hx, hy) = height_gradient(&self.waves, t, q.x, q.y);
            let n = DVec3::new(-hx, -hy, 1.0).normalize();
            let mut z = s;
            while z < top - 0.75 * s {
                out.push(DVec3::new(q.x, q.y, z), n, d, false);
                z += s;
            }
        }
        // Walls and floor, below the surface; outward normals of the fluid body. Unflagged.
        for q in grid(lx, ly, s) {
            out.push(DVec3::new(q.x, q.y, 0.0), -DVec3::Z, d, false);
        }
        let walls: [(f64, bool, DVec3); 4] = [
            (0.0, true, -DVec3::X),
            (lx, true, DVec3::X),
            (0.0, false, -DVec3::Y),
            (ly, false, DVec3::Y),
        ];
        for (at, along_y, normal) in walls {
            let length = if along_y { ly } else { lx };
            let n_along = ((length / s).round() as usize).max(1);
            for i in 0..n_along {
                let a = (i as f64 + 0.5) * length / n_along as f64;
                let (x, y) = if along_y { (at, a) } else { (a, at) };
                let top = d + height(&self.waves, t, x, y);
                let mut z = 0.5 * s;
                while z < top - 0.5 * s {
                    out.push(DVec3::new(x, y, z), normal, d, false);
                    z += s;
                }
            }
        }
    }

    /// Whether droplets leave the wave's surface where they are (the wave scene) or start
    /// above the highest crest any wave makes (tank, droplets).
    fn droplets_from_the_surface(&self) -> bool {
        self.spec.kind == SceneKind::Wave
    }

    /// The height a droplet of `radius` at (x, y) flies above at `time` (it is drawn only
    /// above it): the highest the surface reaches under it.
    fn droplet_floor(&self, time: f64, x: f64, y: f64, radius: f64) -> f64 {
        if self.droplets_from_the_surface() {
            let under = [(0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)];
            under
                .iter()
                .map(|(dx, dy)| height(&self.waves, time, x + dx * radius, y + dy * radius))
                .fold(f64::NEG_INFINITY, f64::max)
                + TANK.depth
        } else {
            TANK.depth + self.waves.iter().map(|w| w.amplitude.abs()).sum::<f64>()
        }
    }

    pub(super) fn make_droplets(&self) -> Vec<Droplet> {
        let mut rng = self.rng(0, 3);
        let [lx, ly] = TANK.size;
        // The wave scene throws droplets over the first 4 s (the demo's 200 steps of 0.02 s).
        let launches = if self.droplets_from_the_surface() {
            -0.2..4.0
        } else {
            -0.5..2.0
        };
        (0..self.spec.droplets)
            .map(|_| {
                let launch_time = rng.random_range(launches.clone());
                // Leave from the highest of a few candidate points: a crest.
                let (x, y) = (0..8)
                    .map(|_| {
                        (
                            rng.random_range(0.1 * lx..0.9 * lx),
                            rng.random_range(0.1 * ly..0.9 * ly),
                        )
                    })
                    .max_by(|a, b| {
                        height(&self.waves, launch_time, a.0, a.1).total_cmp(&height(
                            &self.waves,
                            launch_time,
                            b.0,
                            b.1,
                        ))
                    })
                    .unwrap_or((0.5 * lx, 0.5 * ly));
                let particles = rng.random_range(1..=20usize);
                let radius = self.spacing * (particles as f64 / (4.0 * PI)).sqrt().max(0.5);
                let floor = self.droplet_floor(launch_time, x, y, radius);
                Droplet {
                    launch_time,
                    launch: DVec3::new(x, y, floor + 2.0 * self.spacing + radius),
                    velocity: DVec3::new(
                        rng.random_range(-0.4..0.4),
                        rng.random_range(-0.2..0.2),
                        rng.random_range(1.0..2.0),
                    ),
                    particles,
                    radius,
                }
            })
            .collect()
    }

    /// Centre of a droplet at `time`, while it is in flight above the waves.
    pub fn droplet_center(&self, d: &Droplet, time: f64) -> Option<DVec3> {
        let tau = time - d.launch_time;
        if tau < 0.0 {
            return None;
        }
        let c = d.launch + d.velocity * tau + DVec3::new(0.0, 0.0, -0.5 * GRAVITY * tau * tau);
        let [lx, ly] = TANK.size;
        let above = c.z - d.radius > self.droplet_floor(time, c.x, c.y, d.radius) + self.spacing;
        let inside = (0.0..=lx).contains(&c.x) && (0.0..=ly).contains(&c.y);
        (above && inside).then_some(c)
    }

    pub(super) fn droplet_particles(&self, d: &Droplet, t: f64, out: &mut Particles) {
        let Some(c) = self.droplet_center(d, t) else {
            return;
        };
        if d.particles == 1 {
            // On its sphere, as every surface particle lies on the truth: at the top.
            out.push(c + DVec3::Z * d.radius, DVec3::Z, TANK.depth, true);
            return;
        }
        for n in fibonacci_sphere(d.particles) {
            out.push(c + n * d.radius, n, TANK.depth, true);
        }
    }
}

/// Three standing modes of a 2 × 1 × 0.5 m tank with slip walls (dispersion ω² = g k tanh(k d)).
pub(super) fn tank_waves() -> Vec<Wave> {
    standing_waves(&[
        (1.0, 0.0, 0.06, 0.0),
        (2.0, 1.0, 0.015, 1.0),
        (0.0, 1.0, 0.02, 2.0),
    ])
}

/// Standing modes (mx, my, amplitude, phase) of the tank with slip walls.
fn standing_waves(modes: &[(f64, f64, f64, f64)]) -> Vec<Wave> {
    let [lx, ly] = TANK.size;
    modes
        .iter()
        .map(|&(mx, my, amplitude, phase)| {
            let kx = mx * PI / lx;
            let ky = my * PI / ly;
            let k = f64::hypot(kx, ky);
            Wave {
                amplitude,
                kx,
                ky,
                omega: (GRAVITY * k * (k * TANK.depth).tanh()).sqrt(),
                phase,
            }
        })
        .collect()
}

/// The wave scene's modes: the tank's first mode sloshing hard (the crest at each end wall
/// rises 0.22 m above the still level and falls as far below it, once every 2 s; the highest
/// point of the surface moves by more than a tenth of the tank's 2 m width), with two smaller
/// cross modes for a surface that is not a plain sheet (linear waves, as the tank's).
pub(super) fn slosh_waves() -> Vec<Wave> {
    standing_waves(&[
        (1.0, 0.0, 0.22, 0.0),
        (2.0, 1.0, 0.02, 1.0),
        (1.0, 1.0, 0.025, 2.0),
    ])
}

/// Spacing s at which surface + walls (area / s²) and interior (volume / s³) make `n` points.
pub(super) fn tank_spacing(n: usize) -> f64 {
    let [lx, ly] = TANK.size;
    let d = TANK.depth;
    let area = 2.0 * lx * ly + 2.0 * (lx + ly) * d;
    let volume = lx * ly * d;
    let count = |s: f64| area / (s * s) + volume / (s * s * s);
    let (mut lo, mut hi) = (1e-5_f64, 1.0_f64);
    for _ in 0..100 {
        let mid = (lo * hi).sqrt();
        if count(mid) > n as f64 {
            lo = mid
        } else {
            hi = mid
        }
    }
    hi
}
