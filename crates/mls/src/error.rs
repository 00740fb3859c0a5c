//! Why a surface cannot be built from the points given.

#[derive(Debug, thiserror::Error)]
pub enum SurfaceError {
    #[error("point {index} has a non-finite coordinate {value:?}")]
    NonFinite { index: usize, value: [f64; 3] },
    #[error("a surface needs at least 2 points, got {0}")]
    TooFew(usize),
    /// Most points' `nearest` nearest lie at their own position (piles of coincident points
    /// deeper than that): their radii, whose median sizes h, are 0, and nothing gives a
    /// spacing to size a surface's balls or a droplet's sphere by.
    #[error(
        "{} lie in piles of coincident points ({positions} distinct positions), each one's \
         {nearest} nearest at its own position: piles define no spacing to size a surface \
         or a droplet by",
        of_points(*.piled, *.points)
    )]
    Piles {
        piled: usize,
        points: usize,
        positions: usize,
        nearest: usize,
    },
    #[error("k must be at least 1")]
    BadK,
    #[error("spatial index: {0}")]
    Index(String),
    #[error("inconsistent surface parts: {0}")]
    Parts(String),
    /// The caller withdrew the work (a viewer's bake of a step it no longer wants).
    #[error("withdrawn by its caller")]
    Withdrawn,
}

/// "all 70 points", or "60 of 70 points".
fn of_points(some: usize, points: usize) -> String {
    if some == points {
        format!("all {points} points")
    } else {
        format!("{some} of {points} points")
    }
}
