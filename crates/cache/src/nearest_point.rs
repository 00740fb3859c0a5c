//! The nearest of a set of points to a query point, from a k-d tree built once: a probe asks
//! for one per pixel the pointer rests on, and a scan of every point (what this replaced) took
//! over 100 ms of the UI thread at 300k points in an unoptimised build.

use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// A set of points, searchable for the nearest. Points with a coordinate that is not finite
/// are never the nearest.
pub struct NearestPoints {
    tree: Option<ImmutableKdTree<f32, 3>>,
    /// The index in the given points of each point in the tree (the finite ones).
    index: Vec<u32>,
}

impl std::fmt::Debug for NearestPoints {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NearestPoints")
            .field("points", &self.index.len())
            .finish()
    }
}

impl NearestPoints {
    pub fn new(points: &[[f32; 3]]) -> NearestPoints {
        let (index, finite): (Vec<u32>, Vec<[f32; 3]>) = points
            .iter()
            .enumerate()
            .filter(|(_, p)| p.iter().all(|c| c.is_finite()))
            .map(|(i, p)| (i as u32, *p))
            .unzip();
        // A tree that cannot be built (more points than its items count) leaves none: the
        // search then finds nothing rather than a wrong point.
        let tree = (!finite.is_empty())
            .then(|| ImmutableKdTree::new_from_slice(&finite).ok())
            .flatten();
        NearestPoints { tree, index }
    }

    /// The index (in the points given to [`NearestPoints::new`]) of the point nearest to
    /// `at`; `None` where no point is finite or `at` is not.
    pub fn nearest(&self, at: [f32; 3]) -> Option<usize> {
        if !at.iter().all(|c| c.is_finite()) {
            return None;
        }
        let found = self
            .tree
            .as_ref()?
            .query(&at)
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute();
        self.index.get(found.item as usize).map(|&i| i as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nearest_is_the_scans_and_never_a_non_finite_point() {
        let points: Vec<[f32; 3]> = (0..2000)
            .map(|k| {
                let t = k as f32 * 0.37;
                [t.sin() * 3.0, (t * 1.3).cos() * 2.0, (k % 17) as f32 * 0.1]
            })
            .collect();
        let near = NearestPoints::new(&points);
        let scan = |q: [f32; 3]| {
            (0..points.len())
                .min_by(|&a, &b| {
                    let d = |i: usize| (0..3).map(|c| (points[i][c] - q[c]).powi(2)).sum::<f32>();
                    d(a).total_cmp(&d(b))
                })
                .unwrap()
        };
        for k in 0..200 {
            let q = [
                (k as f32 * 0.11).sin() * 3.5,
                (k as f32 * 0.07).cos() * 2.5,
                0.9,
            ];
            assert_eq!(near.nearest(q), Some(scan(q)), "query {q:?}");
        }
        // A NaN point is skipped, and its neighbours keep their own indices.
        let mut holed = points.clone();
        holed[5] = [f32::NAN, 0.0, 0.0];
        let near = NearestPoints::new(&holed);
        assert_ne!(near.nearest(points[5]), Some(5));
        assert_eq!(near.nearest(points[6]), Some(6));
        assert_eq!(near.nearest([f32::NAN, 0.0, 0.0]), None);
        assert_eq!(NearestPoints::new(&[]).nearest([0.0; 3]), None);
    }
}
