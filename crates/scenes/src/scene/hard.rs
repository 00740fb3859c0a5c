//! The hard cases a scene can carry (noise, flipped or bad normals, duplicates, offsets,
//! degenerate extras, density jumps), applied after the family's own particles.

use glam::DVec3;
use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::{Extra, HardCases, Particles, Scene, SceneSpec};

impl Scene {
    pub(super) fn bounds(p: &Particles) -> (DVec3, DVec3) {
        p.positions.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &q| (lo.min(q), hi.max(q)),
        )
    }

    /// The extra point sets the hard-case options add, in scene coordinates (offset included).
    pub fn extras(&self) -> Vec<Extra> {
        let (_, hi) = Self::bounds(&self.particles_without_hard(0));
        let s = self.spacing;
        let o = self.offset();
        let h = &self.spec.hard;
        let mut out = Vec::new();
        if h.collinear > 0 {
            let start = hi + DVec3::new(4.0 * s, 0.0, 0.0);
            let end = start + DVec3::X * (h.collinear.saturating_sub(1)) as f64 * 0.5 * s;
            out.push(Extra::Segment {
                start: start + o,
                end: end + o,
                points: h.collinear,
            });
        }
        if h.coplanar > 0 {
            let side = (h.coplanar as f64).sqrt().ceil();
            let half = 0.5 * (side - 1.0) * s;
            out.push(Extra::Square {
                center: hi + DVec3::new(0.0, 0.0, 4.0 * s + half) + o,
                normal: DVec3::Z,
                half,
                points: h.coplanar,
            });
        }
        if h.isolated {
            out.push(Extra::Point {
                position: hi + DVec3::splat(20.0 * s) + o,
            });
        }
        out
    }

    pub(super) fn particles_without_hard(&self, step: usize) -> Particles {
        let plain = Scene {
            spec: SceneSpec {
                hard: HardCases::default(),
                ..self.spec.clone()
            },
            ..self.clone()
        };
        plain.particles(step)
    }

    pub(super) fn apply_hard_cases(&self, step: usize, out: &mut Particles) {
        let h = self.spec.hard.clone();
        if h == HardCases::default() {
            return;
        }
        let mut rng = self.rng(step, 2);
        let s = self.spacing;
        if h.density_jump > 1.0 {
            let (lo, hi) = Self::bounds(out);
            let mid = 0.5 * (lo.x + hi.x);
            let keep: Vec<bool> = out
                .positions
                .iter()
                .map(|p| p.x <= mid || rng.random::<f64>() < 1.0 / h.density_jump)
                .collect();
            out.retain(&keep);
        }
        for extra in self.extras() {
            match extra {
                Extra::Segment { start, end, points } => {
                    for i in 0..points {
                        let a = if points > 1 {
                            i as f64 / (points - 1) as f64
                        } else {
                            0.0
                        };
                        out.push(start.lerp(end, a) - self.offset(), DVec3::Z, 0.0, true);
                    }
                }
                Extra::Square {
                    center,
                    half,
                    points,
                    ..
                } => {
                    let side = (points as f64).sqrt().ceil() as usize;
                    for k in 0..points {
                        let (i, j) = (k % side, k / side);
                        let q = DVec3::new(i as f64 * s - half, j as f64 * s - half, 0.0);
                        out.push(center - self.offset() + q, DVec3::Z, 0.0, true);
                    }
                }
                Extra::Point { position } => {
                    out.push(position - self.offset(), DVec3::Z, 0.0, true)
                }
            }
        }
        if h.duplicates > 0.0 {
            let n = out.len();
            for i in 0..n {
                if rng.random::<f64>() < h.duplicates {
                    let (p, nn, pr, sf) = (
                        out.positions[i],
                        out.normals[i],
                        out.pressure[i],
                        out.surface[i],
                    );
                    out.positions.push(p);
                    out.normals.push(nn);
                    out.pressure.push(pr);
                    out.surface.push(sf);
                }
            }
        }
        if h.noise > 0.0
            && let Ok(normal) = Normal::new(0.0, h.noise * s)
        {
            for p in &mut out.positions {
                *p += DVec3::new(
                    normal.sample(&mut rng),
                    normal.sample(&mut rng),
                    normal.sample(&mut rng),
                );
            }
        }
        for n in &mut out.normals {
            if rng.random::<f64>() < h.flip_normals {
                *n = -*n;
            }
        }
        let mut nan_next = true;
        for n in &mut out.normals {
            if rng.random::<f64>() < h.bad_normals {
                *n = if nan_next { DVec3::NAN } else { DVec3::ZERO };
                nan_next = !nan_next;
            }
        }
        let o = self.offset();
        if o != DVec3::ZERO {
            for p in &mut out.positions {
                *p += o;
            }
        }
    }
}
