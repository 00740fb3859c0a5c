//! Scenes: what they are, how they move, and how they are sampled into particles.

use std::str::FromStr;

use glam::DVec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::truth::{Truth, Wave};

mod bodies;
mod flat;
mod hard;
mod tank;

/// Scenes that share a module: how they are sampled, spaced and what their truth is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Family {
    /// Closed bodies: sphere, torus, ellipsoid (`bodies.rs`).
    Body,
    /// The sloshing tank, with or without droplets (`tank.rs`).
    Tank,
    /// Flat squares: the thin sheet and the plane (`flat.rs`).
    Flat,
}

use tank::{slosh_waves, tank_spacing, tank_waves};

/// Gravity used by the tank and the droplets (m/s²).
pub const GRAVITY: f64 = 9.81;
/// Density used for the pressure-like field (kg/m³).
pub const DENSITY: f64 = 1000.0;
/// The most particles a scene makes.
pub const MAX_POINTS: usize = 200_000_000;

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
    /// The tank sloshing hard: one large standing wave whose crests throw droplets (the
    /// demo's scene).
    Wave,
    /// Two parallel squares closer than the smoothing length, normals opposing.
    Sheet,
    /// One flat square: every neighbourhood exactly coplanar.
    Plane,
}

impl SceneKind {
    pub const ALL: [SceneKind; 8] = [
        SceneKind::Sphere,
        SceneKind::Torus,
        SceneKind::Ellipsoid,
        SceneKind::Tank,
        SceneKind::Droplets,
        SceneKind::Wave,
        SceneKind::Sheet,
        SceneKind::Plane,
    ];

    /// The family whose module samples this scene and knows its truth.
    fn family(self) -> Family {
        match self {
            SceneKind::Sphere | SceneKind::Torus | SceneKind::Ellipsoid => Family::Body,
            SceneKind::Tank | SceneKind::Droplets | SceneKind::Wave => Family::Tank,
            SceneKind::Sheet | SceneKind::Plane => Family::Flat,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Sphere => "sphere",
            SceneKind::Torus => "torus",
            SceneKind::Ellipsoid => "ellipsoid",
            SceneKind::Tank => "tank",
            SceneKind::Droplets => "droplets",
            SceneKind::Wave => "wave",
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
    /// Droplets (the droplets scene defaults to 40, the wave scene to 80).
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
            droplets: match kind {
                SceneKind::Droplets => 40,
                SceneKind::Wave => 80,
                _ => 0,
            },
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
        if spec.points == 0 || spec.points > MAX_POINTS {
            return Err(SceneError::Invalid(format!(
                "points must be in 1..={MAX_POINTS}, got {}",
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
        let spacing = match spec.kind.family() {
            Family::Body => bodies::spacing(spec.kind, n),
            Family::Tank => tank_spacing(spec.points),
            Family::Flat => flat::spacing(spec.kind, n),
        };
        let waves = match spec.kind {
            SceneKind::Tank | SceneKind::Droplets => tank_waves(),
            SceneKind::Wave => slosh_waves(),
            _ => Vec::new(),
        };
        let mut scene = Scene {
            spec,
            spacing,
            waves,
            droplets: Vec::new(),
        };
        if scene.spec.kind.family() == Family::Tank {
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
        let body = match self.spec.kind.family() {
            Family::Body => self.body_truth(time),
            Family::Tank => self.tank_truth(time),
            Family::Flat => self.flat_truth(time),
        };
        body.translated(self.offset())
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
        match self.spec.kind.family() {
            Family::Body => self.body_particles(t, &mut out),
            Family::Tank => self.tank_particles(t, &mut rng, &mut out),
            Family::Flat => self.flat_particles(t, &mut rng, &mut out),
        }
        for d in &self.droplets {
            self.droplet_particles(d, t, &mut out);
        }
        self.apply_hard_cases(step, &mut out);
        out
    }
}
