//! The maths of slosh: moving least squares point set surfaces and their iterative ray
//! intersection (Adamson & Alexa 2003), generic over f32 and f64. The f64 build is the oracle
//! that the GPU port must match. No I/O.

// `!(x > 0)` is true for NaN; these negated comparisons are how NaN is refused, on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Index loops mirror the WGSL port line for line, which has no iterators.
#![allow(clippy::needless_range_loop)]

mod clusters;
mod error;
mod fit;
mod found;
mod frame;
mod geometry;
mod grid;
mod intersect;
mod lists;
mod neighbours;
mod order;
mod orient;
mod poly;
mod real;
mod roots;
mod runs;
mod search;
mod spray;
mod support;
mod surface;
mod timing;
mod tracer;
mod up;

pub use clusters::{
    ClusterCandidates, NEIGHBOUR_CLUSTER, cluster_lists, cluster_union, expand_one,
};
pub use fit::{Fit, FitStatus, PIVOT_TOLERANCE, fit};
pub use found::{InitialFit, KeptLists, NeighbourLists};
pub use frame::LocalFrame;
pub use geometry::{bounds, bounds_in_parallel, dominant_axis};
pub use grid::BallIndex;
pub use intersect::{
    Ball, BallHit, HitStatus, InitialHit, Params, Ray, initial_fit, initial_hit, intersect_ball,
    ray_ball, refine,
};
pub use lists::distance2;
pub use neighbours::{Neighbours, csr_pieces};
pub use order::{MortonGrid, morton_keys, morton_order};
pub use orient::{
    Around, NO_POINT, NearestIds, ORIENT_NEIGHBOURS, OrientationRepair, VOTE_SQUARINGS,
    repair_orientation, vote_word, vote_word_wgsl,
};
pub use poly::{Poly, coefficient_count, monomials};
pub use real::{Real, V3};
pub use roots::{eval as eval_cubic, first_root_in, quadratic_roots};
pub use runs::{LIST_BLOCK, LIST_RUN, RunUnions};
pub use search::{FitRequest, KdSearch, ListRequest, NeighbourSearch, PointIndex};
pub use spray::{Sphere, component_roots};
pub use support::{
    CANCELLATION, MIN_WEIGHT, NormalsMode, Support, SupportStatus, jacobi_eigen, support_normal,
    weight,
};
pub use surface::{
    BallFit, BesideFits, ORIENTATION_VOTES_CAST_BY_THE_SEARCH, Surface, SurfaceError,
    SurfaceParams, SurfaceParts, half_precision,
};
pub use timing::{StageClock, stage_part};
pub use tracer::{Camera, CameraBasis, MAX_CANDIDATES, TraceHit};
pub use up::guess_up;
