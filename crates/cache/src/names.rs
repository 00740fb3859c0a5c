//! Section names.

pub const POINTS: &str = "points";
pub const NORMALS: &str = "normals";
pub const BALLS: &str = "balls";
/// A cubic's coefficients 6–9, two words per point (format 5; only where the bake fits
/// cubics).
pub const BALL_CUBIC: &str = "ball_cubic";
/// Each ball's kind and degree, four bits, eight to a word (format 9).
pub const BALL_STATES: &str = "ball_states";
/// Each ball's h as a half float, two to a word, where h is per point (format 9).
pub const BALL_H: &str = "ball_h";
pub const CLUSTER_START: &str = "cluster_start";
pub const CLUSTER_NEIGHBOURS: &str = "cluster_neighbours";
/// Each cluster's first word of `cluster_neighbours` and whether it is wide (format 4; its
/// runs, format 5).
pub const CLUSTER_BASE: &str = "cluster_base";
pub const SPHERES: &str = "spheres";
pub const BVH_NODES: &str = "bvh_nodes";
/// Per-point field sections are named `field.<variable>`.
pub const FIELD_PREFIX: &str = "field.";
