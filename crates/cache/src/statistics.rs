//! What `slosh inspect` reports of a step beyond its header: statistics computed from its
//! sections (neighbours, radii, fit degrees, BVH shape, clusters).

use serde::Serialize;

use crate::{BallState, CacheFile, GpuPoint, Result, names};

/// Min, mean and max of a quantity.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    pub min: f64,
    pub mean: f64,
    pub max: f64,
}

impl Summary {
    /// Min, mean and max of `values` (zeros where there are none).
    pub fn of(values: impl Iterator<Item = f64>) -> Summary {
        let (mut min, mut max, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
        for v in values {
            min = min.min(v);
            max = max.max(v);
            sum += v;
            n += 1;
        }
        if n == 0 {
            return Summary {
                min: 0.0,
                mean: 0.0,
                max: 0.0,
            };
        }
        Summary {
            min,
            mean: sum / n as f64,
            max,
        }
    }
}

/// Statistics computed from the sections (not stored in the header).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Statistics {
    /// Neighbours per point.
    pub neighbours: Summary,
    /// Points with 0–15, 16–31, … neighbours (last bucket: 128 and more).
    pub neighbour_histogram: Vec<u64>,
    /// Radii of trust in world units.
    pub radii: Summary,
    /// Balls whose stored polynomial has degree 0, 1, 2, 3 (fitted balls only).
    pub degrees: [u64; 4],
    pub fit_full: u64,
    pub fit_degraded: u64,
    pub fit_none: u64,
    pub droplets: u64,
    pub droplet_points: u64,
    pub bvh_nodes: u64,
    pub bvh_leaves: u64,
    pub bvh_depth: u64,
    /// Clusters, and those storing their runs from 32-bit starts (the others from 16-bit
    /// offsets).
    pub clusters: u64,
    pub wide_clusters: u64,
}

impl Statistics {
    /// The statistics of `file`, decoding the sections they need.
    pub fn of(file: &CacheFile) -> Result<Statistics> {
        let h = file.header();
        let counts = file.neighbour_counts()?;
        let points: Vec<GpuPoint> = file.decode(names::POINTS)?;
        let balls = file.balls()?;
        let base: Vec<u32> = file.decode(names::CLUSTER_BASE)?;
        let wide = crate::candidates::WIDE_CLUSTER;
        let mut histogram = vec![0u64; 9];
        for &c in &counts {
            histogram[(c as usize / 16).min(8)] += 1;
        }
        let mut degrees = [0u64; 4];
        for b in &balls {
            if matches!(b.kind(), BallState::Full | BallState::Degraded) {
                degrees[usize::from(b.degree())] += 1;
            }
        }
        let bvh = file.bvh()?;
        Ok(Statistics {
            neighbours: Summary::of(counts.iter().map(|&c| f64::from(c))),
            neighbour_histogram: histogram,
            radii: Summary::of(
                points
                    .iter()
                    .map(|p| f64::from(p.radius()) * h.transform.scale),
            ),
            degrees,
            fit_full: h.stats.fit_full,
            fit_degraded: h.stats.fit_degraded,
            fit_none: h.stats.fit_none,
            droplets: h.stats.droplets,
            droplet_points: h.stats.droplet_points,
            bvh_leaves: bvh.nodes.iter().filter(|n| n.count > 0).count() as u64,
            bvh_nodes: bvh.nodes.len() as u64,
            bvh_depth: bvh.depth().unwrap_or(0) as u64,
            clusters: base.len() as u64,
            wide_clusters: base.iter().filter(|&&b| b & wide != 0).count() as u64,
        })
    }
}
