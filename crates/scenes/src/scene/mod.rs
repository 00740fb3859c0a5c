//! Scenes: what they are, how they move, and how they are sampled into particles.

use std::f64::consts::PI;
use std::str::FromStr;

use glam::{DMat3, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::sampling::{ellipsoid_area, fibonacci_sphere, fibonacci_torus, torus_area};
use crate::truth::{Truth, Wave};

mod flat;
mod hard;
mod tank;

use flat::square_points;
use tank::{TANK, tank_spacing, tank_waves};

/// Gravity used by the tank and the droplets (m/s²).
pub const GRAVITY: f64 = 9.81;
/// Density used for the pressure-like field (kg/m³).
pub const DENSITY: f64 = 1000.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneKind {
    Sphere,
    Torus,
    Ellipsoid,
    /// Sloshing free surface in a box, with walls and interior particles.
    Tank,
    /// The tank plus ballistic droplets leaving its crests.
    Droplets,
    /// Two parallel squares closer than the smoothing length, normals opposing.
    Sheet,
    /// One flat square: every neighbourhood exactly coplanar.
    Plane,
}

impl SceneKind {
    pub const ALL: [SceneKind; 7] = [
        SceneKind::Sphere,
        SceneKind::Torus,
        SceneKind::Ellipsoid,
        SceneKind::Tank,
        SceneKind::Droplets,
        SceneKind::Sheet,
        SceneKind::Plane,
    ];

    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Sphere => "sphere",
            SceneKind::Torus => "torus",
            SceneKind::Ellipsoid => "ellipsoid",
            SceneKind::Tank => "tank",
            SceneKind::Droplets => "droplets",
            SceneKind::Sheet => "sheet",
            SceneKind::Plane => "plane",
        }
    }
}

impl FromStr for SceneKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SceneKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown scene {s:?} (one of: {})",
                    SceneKind::ALL.map(SceneKind::name).join(", ")
                )
            })
    }
}

/// Ways to make a scene hard for MLS; all off by default.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct HardCases {
    /// Gaussian position noise, σ as a fraction of the mean spacing.
    pub noise: f64,
    /// Fraction of normals reversed.
    pub flip_normals: f64,
    /// Translation added to every coordinate (e.g. 1e5), truth included.
    pub offset: f64,
    /// Fraction of points written twice at exactly the same place.
    pub duplicates: f64,
    /// Fraction of normals replaced by NaN (half) or zero (half).
    pub bad_normals: f64,
    /// Points on an isolated straight segment (a collinear neighbourhood).
    pub collinear: usize,
    /// Points on an isolated flat patch (an exactly coplanar neighbourhood).
    pub coplanar: usize,
    /// Density ratio between the two halves of the scene (1 = none, 100 = a 100× jump).
    pub density_jump: f64,
    /// One point far from everything else.
    pub isolated: bool,
}

/// Everything that defines a scene; the same spec gives the same particles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSpec {
    pub kind: SceneKind,
    /// Particles of the main body (extras and droplets come on top).
    pub points: usize,
    pub seed: u64,
    /// Time between steps (s).
    pub dt: f64,
    /// Droplets (the droplets scene defaults to 40).
    pub droplets: usize,
    pub hard: HardCases,
}

impl SceneSpec {
    pub fn new(kind: SceneKind, points: usize, seed: u64) -> SceneSpec {
        SceneSpec {
            kind,
            points,
            seed,
            dt: 0.05,
            droplets: if kind == SceneKind::Droplets { 40 } else { 0 },
            hard: HardCases::default(),
        }
    }
}

/// Particles of one step. Normals are outward unit normals of the true surface (for surface
/// particles) before any hard-case corruption.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Particles {
    pub positions: Vec<DVec3>,
    pub normals: Vec<DVec3>,
    /// Hydrostatic pressure ρ g (z_ref − z) relative to the scene's reference height (Pa).
    pub pressure: Vec<f64>,
    /// True for particles on the free surface.
    pub surface: Vec<bool>,
}

impl Particles {
    fn push(&mut self, p: DVec3, n: DVec3, z_ref: f64, surface: bool) {
        self.positions.push(p);
        self.normals.push(n);
        self.pressure.push(DENSITY * GRAVITY * (z_ref - p.z));
        self.surface.push(surface);
    }

    /// Positions and normals of the free-surface particles only, as plain arrays (what a
    /// surface reconstruction is given).
    pub fn surface_arrays(&self) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let keep = |v: &[DVec3]| -> Vec<[f64; 3]> {
            v.iter()
                .zip(&self.surface)
                .filter(|(_, s)| **s)
                .map(|(q, _)| q.to_array())
                .collect()
        };
        (keep(&self.positions), keep(&self.normals))
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    fn retain(&mut self, keep: &[bool]) {
        fn by_mask<T>(v: &mut Vec<T>, keep: &[bool]) {
            let mut k = keep.iter();
            v.retain(|_| *k.next().unwrap_or(&true));
        }
        by_mask(&mut self.positions, keep);
        by_mask(&mut self.normals, keep);
        by_mask(&mut self.pressure, keep);
        by_mask(&mut self.surface, keep);
    }
}

/// A point set added by a hard-case option, away from the analytic surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Extra {
    Segment {
        start: DVec3,
        end: DVec3,
        points: usize,
    },
    Square {
        center: DVec3,
        normal: DVec3,
        half: f64,
        points: usize,
    },
    Point {
        position: DVec3,
    },
}

/// One ballistic droplet.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Droplet {
    pub launch_time: f64,
    pub launch: DVec3,
    pub velocity: DVec3,
    pub particles: usize,
    pub radius: f64,
}

#[derive(Debug, Clone, thiserror::Error)]
pub enum SceneError {
    #[error("{0}")]
    Invalid(String),
}

/// A scene ready to be sampled at any step.
#[derive(Debug, Clone)]
pub struct Scene {
    spec: SceneSpec,
    spacing: f64,
    waves: Vec<Wave>,
    droplets: Vec<Droplet>,
}

impl Scene {
    pub fn new(spec: SceneSpec) -> Result<Scene, SceneError> {
        let h = &spec.hard;
        let fraction = |v: f64, name: &str| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(SceneError::Invalid(format!(
                    "{name} must be a fraction in [0, 1], got {v}"
                )))
            }
        };
        fraction(h.flip_normals, "flip-normals")?;
        fraction(h.duplicates, "duplicates")?;
        fraction(h.bad_normals, "bad-normals")?;
        if !(h.noise >= 0.0 && h.noise.is_finite() && h.offset.is_finite()) {
            return Err(SceneError::Invalid(
                "noise must be ≥ 0 and offset finite".into(),
            ));
        }
        if !(h.density_jump == 0.0 || h.density_jump >= 1.0) {
            return Err(SceneError::Invalid(format!(
                "density-jump is a ratio ≥ 1, got {}",
                h.density_jump
            )));
        }
        if spec.points == 0 || spec.points > 200_000_000 {
            return Err(SceneError::Invalid(format!(
                "points must be in 1..=200000000, got {}",
                spec.points
            )));
        }
        if !(spec.dt > 0.0 && spec.dt.is_finite()) {
            return Err(SceneError::Invalid(format!(
                "dt must be > 0, got {}",
                spec.dt
            )));
        }
        let n = spec.points as f64;
        let spacing = match spec.kind {
            SceneKind::Sphere => (4.0 * PI / n).sqrt(),
            SceneKind::Torus => (torus_area(TORUS.0, TORUS.1) / n).sqrt(),
            SceneKind::Ellipsoid => (ellipsoid_area(ELLIPSOID) / n).sqrt(),
            SceneKind::Tank | SceneKind::Droplets => tank_spacing(spec.points),
            SceneKind::Sheet => (2.0 * 4.0 / n).sqrt(),
            SceneKind::Plane => (4.0 / n).sqrt(),
        };
        let waves = if matches!(spec.kind, SceneKind::Tank | SceneKind::Droplets) {
            tank_waves()
        } else {
            Vec::new()
        };
        let mut scene = Scene {
            spec,
            spacing,
            waves,
            droplets: Vec::new(),
        };
        if matches!(scene.spec.kind, SceneKind::Tank | SceneKind::Droplets) {
            // The area/volume estimate ignores lattice rounding and the wavy top: calibrate on
            // the real count so that `points` is what the user gets (to about 1 %).
            let target = scene.spec.points as f64;
            for _ in 0..3 {
                let mut count = Particles::default();
                scene.tank_particles(0.0, &mut scene.rng(0, 1), &mut count);
                scene.spacing *= (count.len() as f64 / target).cbrt();
            }
        }
        scene.droplets = scene.make_droplets();
        Ok(scene)
    }

    pub fn spec(&self) -> &SceneSpec {
        &self.spec
    }

    /// Mean spacing of the main body's surface particles.
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    pub fn time(&self, step: usize) -> f64 {
        step as f64 * self.spec.dt
    }

    pub fn droplets(&self) -> &[Droplet] {
        &self.droplets
    }

    fn offset(&self) -> DVec3 {
        DVec3::splat(self.spec.hard.offset)
    }

    /// The true surface at `time`, offset included.
    pub fn truth(&self, time: f64) -> Truth {
        let body = match self.spec.kind {
            SceneKind::Sphere => Truth::Sphere {
                center: sphere_center(time),
                radius: 1.0,
            },
            SceneKind::Torus => Truth::Torus {
                center: DVec3::ZERO,
                rotation: torus_rotation(time),
                major: TORUS.0,
                minor: TORUS.1,
            },
            SceneKind::Ellipsoid => Truth::Ellipsoid {
                center: DVec3::ZERO,
                rotation: ellipsoid_rotation(time),
                radii: ELLIPSOID,
            },
            SceneKind::Tank | SceneKind::Droplets => {
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
            SceneKind::Sheet => {
                let gap = self.sheet_gap();
                let c = DVec3::new(0.0, 0.0, 0.1 * time);
                Truth::Union {
                    parts: vec![
                        Truth::Square {
                            center: c + DVec3::Z * gap / 2.0,
                            normal: DVec3::Z,
                            half: 1.0,
                        },
                        Truth::Square {
                            center: c - DVec3::Z * gap / 2.0,
                            normal: -DVec3::Z,
                            half: 1.0,
                        },
                    ],
                }
            }
            SceneKind::Plane => Truth::Square {
                center: DVec3::new(0.05 * time, 0.0, 0.0),
                normal: DVec3::Z,
                half: 1.0,
            },
        };
        body.translated(self.offset())
    }

    /// Gap of the thin sheet: half the mean spacing, well inside any smoothing length.
    pub fn sheet_gap(&self) -> f64 {
        0.5 * self.spacing
    }

    fn rng(&self, step: usize, stream: u64) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::seed_from_u64(self.spec.seed);
        rng.set_stream(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ step as u64);
        rng
    }

    /// The particles of step `step` (deterministic for the spec's seed).
    pub fn particles(&self, step: usize) -> Particles {
        let t = self.time(step);
        let mut rng = self.rng(step, 1);
        let mut out = Particles::default();
        match self.spec.kind {
            SceneKind::Sphere => {
                let c = sphere_center(t);
                let spin = DMat3::from_rotation_z(0.3 * t) * self.pattern_rotation();
                for d in fibonacci_sphere(self.spec.points) {
                    let n = spin * d;
                    out.push(c + n, n, c.z, true);
                }
            }
            SceneKind::Torus => {
                let rot = torus_rotation(t);
                for uv in fibonacci_torus(self.spec.points, TORUS.0, TORUS.1) {
                    let (su, cu) = uv.x.sin_cos();
                    let (sv, cv) = uv.y.sin_cos();
                    let n = DVec3::new(cv * cu, cv * su, sv);
                    let p = DVec3::new(
                        (TORUS.0 + TORUS.1 * cv) * cu,
                        (TORUS.0 + TORUS.1 * cv) * su,
                        TORUS.1 * sv,
                    );
                    out.push(rot * p, rot * n, 0.0, true);
                }
            }
            SceneKind::Ellipsoid => {
                let frame = ellipsoid_rotation(t);
                for d in fibonacci_sphere(self.spec.points) {
                    // Pattern on the unit sphere, mapped onto the body's ellipsoid.
                    let local = self.pattern_rotation() * d * ELLIPSOID;
                    let n = (frame * (local / (ELLIPSOID * ELLIPSOID))).normalize();
                    out.push(frame * local, n, 0.0, true);
                }
            }
            SceneKind::Tank | SceneKind::Droplets => self.tank_particles(t, &mut rng, &mut out),
            SceneKind::Sheet => {
                let gap = self.sheet_gap();
                let c = DVec3::new(0.0, 0.0, 0.1 * t);
                let half_n = self.spec.points / 2;
                for (side, normal) in [(1.0, DVec3::Z), (-1.0, -DVec3::Z)] {
                    for q in square_points(half_n, self.spacing, &mut rng) {
                        out.push(
                            c + DVec3::new(q.x, q.y, side * gap / 2.0),
                            normal,
                            c.z,
                            true,
                        );
                    }
                }
            }
            SceneKind::Plane => {
                let c = DVec3::new(0.05 * t, 0.0, 0.0);
                for q in square_points(self.spec.points, self.spacing, &mut rng) {
                    out.push(c + DVec3::new(q.x, q.y, 0.0), DVec3::Z, 0.0, true);
                }
            }
        }
        for d in &self.droplets {
            self.droplet_particles(d, t, &mut out);
        }
        self.apply_hard_cases(step, &mut out);
        out
    }

    /// A fixed random rotation of the sampling pattern (so that lattice axes do not line up
    /// with the coordinate axes), drawn from the seed.
    fn pattern_rotation(&self) -> DMat3 {
        let mut rng = self.rng(0, 7);
        let axis = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(DVec3::Z);
        DMat3::from_axis_angle(axis, rng.random_range(0.0..PI))
    }
}

const TORUS: (f64, f64) = (1.0, 0.35);
const ELLIPSOID: DVec3 = DVec3::new(1.2, 0.8, 0.5);

fn sphere_center(t: f64) -> DVec3 {
    DVec3::new(0.25 * t.sin(), 0.1 * t, 0.0)
}

fn torus_rotation(t: f64) -> DMat3 {
    DMat3::from_rotation_x(0.4 * t)
}

fn ellipsoid_rotation(t: f64) -> DMat3 {
    DMat3::from_rotation_x(0.2 * t) * DMat3::from_rotation_z(0.5 * t)
}
