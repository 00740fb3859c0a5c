//! A step file turned back into the MLS crate's surface and the baked BVH: what the CPU
//! reference tracer needs to trace straight from a cache.

use slosh_mls::{
    Ball, BallFit, Camera, ClusterCandidates, FitStatus, KeptLists, Neighbours, NormalsMode,
    Params, Poly, Sphere, Surface, SurfaceParams, SurfaceParts, TraceHit, V3,
};

use crate::ball_state::{BALLS_PER_STATE_WORD, BallBits, StoredBall, h_of};
use crate::bvh::Bvh;
use crate::error::{Error, Result};
use crate::format::{MlsSettings, Transform};
use crate::layout::{BallState, CubicWords, GpuBall, GpuPoint, GpuSphere};
use crate::names;
use crate::reader::CacheFile;
use crate::{candidates, octahedral};

impl MlsSettings {
    pub fn from_params(p: &SurfaceParams) -> MlsSettings {
        MlsSettings {
            k: p.k,
            h_scale: p.h_scale,
            support: p.support,
            neighbour_cap: p.neighbour_cap,
            degree: p.degree,
            normals: match p.normals {
                NormalsMode::Mean => "mean",
                NormalsMode::Covariance => "covariance",
            }
            .to_string(),
            per_point_h: p.per_point_h,
            droplet_below: p.droplet_below,
            offset: p.offset,
        }
    }

    pub fn to_params(&self) -> Option<SurfaceParams> {
        Some(SurfaceParams {
            k: self.k,
            h_scale: self.h_scale,
            support: self.support,
            neighbour_cap: self.neighbour_cap,
            degree: self.degree,
            normals: match self.normals.as_str() {
                "mean" => NormalsMode::Mean,
                "covariance" => NormalsMode::Covariance,
                _ => return None,
            },
            per_point_h: self.per_point_h,
            droplet_below: self.droplet_below,
            offset: self.offset,
        })
    }
}

/// What neighbour lists are recovered from: stored points (with radii), positions and data
/// normals as vectors, reaches (from the points' words).
pub(crate) struct Geometry {
    pub(crate) points: Vec<GpuPoint>,
    pub(crate) positions: Vec<V3<f32>>,
    pub(crate) normals: Option<Vec<V3<f32>>>,
    pub(crate) reach: Vec<f32>,
}

impl CacheFile {
    pub(crate) fn geometry(&self) -> Result<Geometry> {
        let points: Vec<GpuPoint> = self.decode(names::POINTS)?;
        let normals: Option<Vec<u32>> = self
            .section(names::NORMALS)
            .map(|_| self.decode(names::NORMALS))
            .transpose()?;
        if normals.as_ref().is_some_and(|n| n.len() != points.len()) {
            return Err(Error::Invalid {
                path: self.path().to_path_buf(),
                problem: format!(
                    "{} points, {:?} normals",
                    points.len(),
                    normals.as_ref().map(Vec::len)
                ),
            });
        }
        Ok(Geometry {
            positions: points.iter().map(|p| v3(p.position)).collect(),
            // As the shaders decode them: on the octahedron, not normalised (the neighbour rule
            // tests signs; the fits normalise).
            normals: normals.map(|ns| ns.iter().map(|&n| v3(octahedral::decode(n))).collect()),
            reach: points.iter().map(GpuPoint::reach).collect(),
            points,
        })
    }

    /// The clusters' candidates as CSR: offsets per cluster, 32-bit indices.
    fn cluster_csr(&self) -> Result<(Vec<u32>, Vec<u32>)> {
        let cluster_start: Vec<u32> = self.decode(names::CLUSTER_START)?;
        let cluster_ids = self.cluster_candidates(&cluster_start)?;
        Ok((cluster_start, cluster_ids))
    }

    fn expand(&self, g: &Geometry) -> Result<(Vec<u32>, Vec<u32>)> {
        let (start, ids) = self.cluster_csr()?;
        Ok(self.clusters_of(g, &start, &ids).expand())
    }

    /// `g`'s points and the clusters' candidates `start` and `ids` ([`Self::cluster_csr`]).
    fn clusters_of<'a>(
        &self,
        g: &'a Geometry,
        start: &'a [u32],
        ids: &'a [u32],
    ) -> ClusterCandidates<'a, f32> {
        ClusterCandidates {
            points: &g.positions,
            normals: g.normals.as_deref(),
            reach: &g.reach,
            size: self.header().neighbour_cluster as usize,
            cluster_start: start,
            cluster_ids: ids,
        }
    }

    /// Every cluster's candidates as 32-bit indices (CSR over `cluster_start`), unpacked from
    /// their narrow or wide words (`candidates.rs`).
    pub fn cluster_candidates(&self, cluster_start: &[u32]) -> Result<Vec<u32>> {
        let (base, words) = self.cluster_words()?;
        self.packed_lists(cluster_start, &base, &words)
            .unpack()
            .map_err(|problem| self.lists_error(problem))
    }

    /// The `cluster_base` and `cluster_neighbours` sections, decoded.
    pub(crate) fn cluster_words(&self) -> Result<(Vec<u32>, Vec<u32>)> {
        Ok((
            self.decode(names::CLUSTER_BASE)?,
            self.decode(names::CLUSTER_NEIGHBOURS)?,
        ))
    }

    /// The step's packed cluster lists, over its cluster offsets `start` and the sections of
    /// [`Self::cluster_words`].
    pub(crate) fn packed_lists<'a>(
        &self,
        start: &'a [u32],
        base: &'a [u32],
        words: &'a [u32],
    ) -> candidates::PackedLists<'a> {
        candidates::PackedLists {
            start,
            base,
            words,
            size: self.header().neighbour_cluster.max(1),
        }
    }

    /// What is wrong with the packed cluster lists, said of `cluster_base`.
    pub(crate) fn lists_error(&self, problem: String) -> Error {
        Error::Invalid {
            path: self.path().to_path_buf(),
            problem: format!("section '{}': {problem}", names::CLUSTER_BASE),
        }
    }

    /// Checks the `ball_cubic` section against the header: present where the bake fits
    /// cubics (`mls.degree` 3), two words per point where present.
    pub fn check_ball_cubic(&self) -> Result<()> {
        let header = self.header();
        let problem = match self.section(names::BALL_CUBIC) {
            None if header.mls.degree == 3 => "is missing from a step of cubic fits".to_string(),
            Some(e) if e.count != 2 * header.points => format!(
                "holds {} words for {} points (two each)",
                e.count, header.points
            ),
            _ => return Ok(()),
        };
        Err(Error::Invalid {
            path: self.path().to_path_buf(),
            problem: format!("section '{}' {problem}", names::BALL_CUBIC),
        })
    }

    /// Each ball's cubic words ([`CubicWords`]): the `ball_cubic` section, or zeros where
    /// the step has none (no cubics were fitted).
    pub fn cubic_words(&self) -> Result<Vec<CubicWords>> {
        self.check_ball_cubic()?;
        if self.section(names::BALL_CUBIC).is_none() {
            return Ok(vec![[0; 2]; self.header().points as usize]);
        }
        let words: Vec<u32> = self.decode(names::BALL_CUBIC)?;
        Ok(words.chunks_exact(2).map(|w| [w[0], w[1]]).collect())
    }

    /// Every point's neighbour list (CSR), recovered from the cluster lists by the rule in
    /// `slosh_mls::ClusterCandidates::expand`.
    pub fn neighbour_lists(&self) -> Result<(Vec<u32>, Vec<u32>)> {
        self.expand(&self.geometry()?)
    }

    /// Every point's neighbour count by the same rule, without keeping the lists.
    pub fn neighbour_counts(&self) -> Result<Vec<u32>> {
        let g = self.geometry()?;
        let (start, ids) = self.cluster_csr()?;
        Ok(self.clusters_of(&g, &start, &ids).neighbour_counts())
    }
}

/// A step ready for the CPU tracer, in the file's local coordinates.
#[derive(Debug)]
pub struct LoadedStep {
    pub surface: Surface<f32>,
    pub bvh: Bvh,
    pub transform: Transform,
}

fn v3(a: [f32; 3]) -> V3<f32> {
    V3::new(a[0], a[1], a[2])
}

impl LoadedStep {
    pub fn load(file: &CacheFile) -> Result<LoadedStep> {
        let header = file.header();
        let invalid = |problem: String| Error::Invalid {
            path: file.path().to_path_buf(),
            problem,
        };
        let params = header
            .mls
            .to_params()
            .ok_or_else(|| invalid(format!("unknown normals mode '{}'", header.mls.normals)))?;
        let geometry = file.geometry()?;
        let (neighbour_start, neighbours) = file.expand(&geometry)?;
        let Geometry {
            points,
            positions,
            normals,
            reach,
        } = geometry;
        let balls = file.balls()?;
        let cubic = file.cubic_words()?;
        let spheres: Vec<GpuSphere> = file.decode(names::SPHERES)?;
        if balls.len() != points.len() {
            return Err(invalid(format!(
                "{} balls for {} points",
                balls.len(),
                points.len()
            )));
        }
        let requested = header.mls.degree;
        let ball_fits = balls
            .iter()
            .map(|b| match b.kind() {
                BallState::Full => BallFit::Fitted(FitStatus::Full),
                BallState::Degraded => BallFit::Fitted(FitStatus::Degraded {
                    requested,
                    used: b.degree(),
                }),
                BallState::Unfitted => BallFit::None,
                BallState::Droplet => BallFit::Droplet(b.ball.coeffs[0]),
            })
            .collect();
        let surface = Surface::from_parts(SurfaceParts {
            origin: [0.0; 3],
            points: positions,
            normals,
            radii: points.iter().map(|p| p.radius()).collect(),
            h: header.smoothing_length as f32,
            spacing: header.spacing as f32,
            offset: header.surface_offset as f32,
            neighbours: KeptLists::Whole(
                Neighbours::from_csr(neighbour_start, neighbours).ok_or_else(|| {
                    invalid("the expanded neighbour lists are not a CSR index".into())
                })?,
            ),
            reach,
            capped: header.stats.capped as usize,
            run_unions: None,
            orientation: slosh_mls::OrientationRepair {
                flipped_points: header.stats.orientation_flipped as usize,
                flipped_patches: header.stats.orientation_patches as usize,
                patch_points: header.stats.orientation_patch_points as usize,
            },
            balls: points
                .iter()
                .zip(&balls)
                .zip(&cubic)
                .map(|((p, b), cubic)| Ball {
                    centre: v3(p.position),
                    radius: p.radius(),
                    h: b.h,
                    normal: v3(b.normal()),
                    poly: Poly {
                        degree: b.degree(),
                        c: b.coeffs(*cubic),
                    },
                })
                .collect(),
            ball_fits,
            spheres: spheres
                .iter()
                .map(|s| Sphere {
                    centre: v3(s.centre),
                    radius: s.radius,
                })
                .collect(),
            params,
        })
        .map_err(|e| invalid(e.to_string()))?;
        let bvh = file.bvh()?;
        Ok(LoadedStep {
            surface,
            bvh,
            transform: header.transform,
        })
    }

    /// The camera in the file's local coordinates (same rays, uniformly scaled).
    pub fn local_camera(&self, camera: &Camera) -> Camera {
        Camera {
            eye: self.transform.to_local(camera.eye),
            target: self.transform.to_local(camera.target),
            ..*camera
        }
    }

    /// A local hit in world coordinates.
    pub fn to_world(&self, hit: TraceHit) -> TraceHit {
        TraceHit {
            t: hit.t * self.transform.scale,
            position: self.transform.to_world(hit.position),
            ..hit
        }
    }

    /// Traces every pixel through the baked BVH; hits in world coordinates.
    pub fn render(&self, camera: &Camera, params: &Params<f32>) -> Vec<Option<TraceHit>> {
        self.surface
            .render_in(&self.bvh, &self.local_camera(camera), params)
            .into_iter()
            .map(|h| h.map(|h| self.to_world(h)))
            .collect()
    }
}

impl CacheFile {
    /// Checks that `ball_states` holds a place for every point, and `ball_h` too where h is
    /// per point (and is absent otherwise), from the section table alone.
    pub fn check_ball_words(&self) -> Result<()> {
        let header = self.header();
        let n = header.points;
        let check = |name: &str, per_word: u64, wanted: bool| -> std::result::Result<(), String> {
            match self.section(name) {
                None if wanted => Err(format!("section '{name}' is missing")),
                Some(_) if !wanted => Err(format!(
                    "section '{name}' is present where h is the step's one value"
                )),
                Some(e) if e.count != n.div_ceil(per_word) => Err(format!(
                    "section '{name}' holds {} words for {n} points ({per_word} to a word)",
                    e.count
                )),
                _ => Ok(()),
            }
        };
        check(names::BALL_STATES, BALLS_PER_STATE_WORD as u64, true)
            .and_then(|()| check(names::BALL_H, 2, header.mls.per_point_h))
            .map_err(|problem| Error::Invalid {
                path: self.path().to_path_buf(),
                problem,
            })
    }

    /// Every ball with its state bits and h, gathered from `balls`, `ball_states` and the
    /// header's h or `ball_h`; an error where a section is missing or of the wrong length.
    pub fn balls(&self) -> Result<Vec<StoredBall>> {
        self.check_ball_words()?;
        let header = self.header();
        let balls: Vec<GpuBall> = self.decode(names::BALLS)?;
        if balls.len() as u64 != header.points {
            return Err(Error::Invalid {
                path: self.path().to_path_buf(),
                problem: format!("{} balls for {} points", balls.len(), header.points),
            });
        }
        let states: Vec<u32> = self.decode(names::BALL_STATES)?;
        let per_point: Option<Vec<u32>> = header
            .mls
            .per_point_h
            .then(|| self.decode(names::BALL_H))
            .transpose()?;
        let global = header.smoothing_length as f32;
        Ok(balls
            .into_iter()
            .enumerate()
            .map(|(i, ball)| StoredBall {
                ball,
                bits: BallBits::of(&states, i),
                h: per_point.as_deref().map_or(global, |w| h_of(w, i)),
            })
            .collect())
    }
}
