//! Progressive refinement: while time or the camera moves, frames use the baked polynomial
//! (one iteration); when both are still, the same view is traced again with one more
//! iteration per frame until the requested count. The last frame of a finished refinement
//! is a direct render at that count. Under a frame budget ([`Pacing`]) a moving view is drawn
//! smaller, and a refined frame too slow for one pass is traced as interleaved sets of rows,
//! one per pass; it shows once its last set is in.

use slosh_mls::Camera;
use slosh_render::{RowSet, TraceParams};

use crate::frame_budget::FrameBudget;

/// Everything but the iteration count that decides a frame's pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewKey {
    /// The series position shown.
    pub step: usize,
    pub camera: Camera,
    /// The trace parameters with `iterations` set to 0.
    pub params: TraceParams,
    pub field: Option<String>,
    /// Changes whenever the step's content on the GPU changes (a field switched).
    pub revision: u64,
}

impl ViewKey {
    pub fn new(
        step: usize,
        camera: Camera,
        params: &TraceParams,
        field: Option<String>,
        revision: u64,
    ) -> ViewKey {
        ViewKey {
            step,
            camera,
            params: TraceParams {
                iterations: 0,
                ..*params
            },
            field,
            revision,
        }
    }
}

/// How far the refinement of the current view has got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// Iterations of the last whole frame of this view at full size (0: none yet, a
    /// preview is on screen).
    pub done: u32,
    /// Iterations asked for once still.
    pub target: u32,
}

impl Progress {
    pub fn finished(&self) -> bool {
        self.done >= self.target
    }
}

/// What one UI pass draws of the view.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Draw {
    /// The whole frame at full size.
    Whole { iterations: u32 },
    /// The whole frame at the reduced size the frame budget allows, at one iteration: the
    /// view moves.
    Preview,
    /// A set of rows of a full-size frame; the last one completes it.
    Rows {
        iterations: u32,
        rows: RowSet,
        /// Rows of the frame traced once this set is.
        done: u32,
        height: u32,
    },
}

impl Draw {
    pub fn iterations(&self) -> u32 {
        match self {
            Draw::Whole { iterations } | Draw::Rows { iterations, .. } => *iterations,
            Draw::Preview => 1,
        }
    }

    /// Whether this draw completes a full-size frame.
    pub fn completes_frame(&self) -> bool {
        match self {
            Draw::Whole { .. } => true,
            Draw::Preview => false,
            Draw::Rows { done, height, .. } => done >= height,
        }
    }
}

/// How a frame budget paces the refinement: whether a moving view is drawn as a preview,
/// and into how many row sets a refined frame is split.
#[derive(Debug, Clone, Copy)]
pub struct Pacing<'a> {
    pub budget: &'a FrameBudget,
    /// The budget asks for a preview smaller than the full size.
    pub preview: bool,
}

/// A full-size frame traced set of rows by set, one per pass.
#[derive(Debug, Clone, Default)]
struct InSets {
    iterations: u32,
    /// The row sets still to trace.
    pending: Vec<RowSet>,
    done: u32,
}

#[derive(Debug, Clone, Default)]
pub struct Refinement {
    key: Option<ViewKey>,
    done: u32,
    sets: Option<InSets>,
}

impl Refinement {
    /// What to draw of the view this pass, or `None` when it is already drawn at `target`
    /// and nothing changed. `moving`: time or the camera is in motion. Without `pacing`
    /// every draw is a whole frame at full size.
    pub fn next(
        &mut self,
        key: ViewKey,
        moving: bool,
        target: u32,
        pacing: Option<Pacing>,
    ) -> Option<Draw> {
        let target = target.max(1);
        let (width, height) = (key.camera.width.max(1), key.camera.height.max(1));
        if moving || self.key.as_ref() != Some(&key) {
            self.key = Some(key);
            self.sets = None;
            if pacing.is_some_and(|p| p.preview) {
                self.done = 0;
                return Some(Draw::Preview);
            }
            self.done = 1;
            return Some(Draw::Whole { iterations: 1 });
        }
        let mut sets = match self.sets.take() {
            Some(sets) => sets,
            None => {
                let level = match self.done.cmp(&target) {
                    // Once more per pass until the target.
                    std::cmp::Ordering::Less => self.done + 1,
                    // The target was lowered: draw it once at the new count.
                    std::cmp::Ordering::Greater => target,
                    std::cmp::Ordering::Equal => return None,
                };
                if pacing.is_none_or(|p| p.budget.fits(level, width, height)) {
                    self.done = level;
                    return Some(Draw::Whole { iterations: level });
                }
                InSets {
                    iterations: level,
                    pending: vec![RowSet::WHOLE],
                    done: 0,
                }
            }
        };
        let mut rows = sets.pending.pop()?;
        // A set predicted over the budget is halved, its second half kept for later, until
        // it fits: each pass takes as many rows as the latest measurements allow, and the
        // rows come in bit-reversed order, each set an even sample of the frame.
        while let Some(p) = pacing
            && rows.count(height) > 1
            && !p.budget.fits(sets.iterations, width, rows.count(height))
        {
            let [first, second] = rows.halves();
            sets.pending.push(second);
            rows = first;
        }
        sets.done += rows.count(height);
        let draw = Draw::Rows {
            iterations: sets.iterations,
            rows,
            done: sets.done,
            height,
        };
        if sets.pending.is_empty() {
            self.done = sets.iterations;
        } else {
            self.sets = Some(sets);
        }
        Some(draw)
    }

    /// Forgets the view: the next frame is drawn whatever it is.
    pub fn invalidate(&mut self) {
        self.key = None;
        self.done = 0;
        self.sets = None;
    }

    pub fn progress(&self, target: u32) -> Progress {
        Progress {
            done: self.done,
            target: target.max(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(step: usize, x: f64) -> ViewKey {
        let camera = Camera {
            eye: [x, 0.0, 5.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_y: 40.0,
            width: 64,
            height: 48,
        };
        let params = TraceParams {
            iterations: 7,
            ..TraceParams::default()
        };
        ViewKey::new(step, camera, &params, None, 0)
    }

    fn whole(iterations: u32) -> Option<Draw> {
        Some(Draw::Whole { iterations })
    }

    #[test]
    fn still_views_refine_one_iteration_per_frame_then_stop() {
        let mut r = Refinement::default();
        let drawn: Vec<Option<Draw>> = (0..5)
            .map(|_| r.next(key(3, 0.0), false, 3, None))
            .collect();
        assert_eq!(drawn, vec![whole(1), whole(2), whole(3), None, None]);
        assert!(r.progress(3).finished());
        // The camera moves: back to one iteration, and while moving it stays there.
        assert_eq!(r.next(key(3, 0.1), true, 3, None), whole(1));
        assert_eq!(r.next(key(3, 0.2), true, 3, None), whole(1));
        assert_eq!(r.next(key(3, 0.2), false, 3, None), whole(2));
        // Another step is another view.
        assert_eq!(r.next(key(4, 0.2), false, 3, None), whole(1));
        // Lowering the target draws the lower count once.
        r.next(key(4, 0.2), false, 3, None);
        r.next(key(4, 0.2), false, 3, None);
        assert_eq!(r.next(key(4, 0.2), false, 2, None), whole(2));
        assert_eq!(r.next(key(4, 0.2), false, 2, None), None);
        r.invalidate();
        assert_eq!(r.next(key(4, 0.2), false, 2, None), whole(1));
    }

    /// The rows of `draws` with `iterations`, sorted; and the sets.
    fn rows_of(draws: &[Draw], iterations: u32, height: u32) -> (Vec<u32>, Vec<RowSet>) {
        let sets: Vec<RowSet> = draws
            .iter()
            .filter_map(|d| match d {
                Draw::Rows {
                    iterations: it,
                    rows,
                    ..
                } if *it == iterations => Some(*rows),
                _ => None,
            })
            .collect();
        let mut rows: Vec<u32> = sets
            .iter()
            .flat_map(|s| (s.first..height).step_by(s.stride as usize))
            .collect();
        rows.sort_unstable();
        (rows, sets)
    }

    #[test]
    fn a_budget_previews_while_moving_and_refines_in_row_sets() {
        // 64×48 frames; 1 ms a pixel at one iteration, 2 at two: a budget of 1000 ms holds
        // 15 rows at one iteration (sets of every 4th row: 12), 7 at two (every 8th: 6).
        let mut budget = FrameBudget::new(1000.0);
        budget.record(1, 1, 1.0);
        budget.record(2, 1, 2.0);
        let pacing = Some(Pacing {
            budget: &budget,
            preview: true,
        });
        let mut r = Refinement::default();
        assert_eq!(r.next(key(3, 0.0), true, 2, pacing), Some(Draw::Preview));
        assert_eq!(r.progress(2).done, 0);
        // Still: level 1 in 4 sets, then level 2 in 8, every row once a level, then nothing.
        let mut draws = Vec::new();
        while let Some(d) = r.next(key(3, 0.0), false, 2, pacing) {
            draws.push(d);
        }
        assert_eq!(draws.len(), 12);
        for (it, stride) in [(1, 4), (2, 8)] {
            let (rows, sets) = rows_of(&draws, it, 48);
            assert_eq!(rows, (0..48).collect::<Vec<u32>>());
            assert!(sets.iter().all(|s| s.stride == stride), "{sets:?}");
        }
        // Bit-reversed: the second set of a level starts half-way between the first's rows.
        assert!(matches!(
            draws[1],
            Draw::Rows {
                rows: RowSet {
                    first: 2,
                    stride: 4
                },
                ..
            }
        ));
        assert!(draws[3].completes_frame() && draws[11].completes_frame());
        assert!(draws.iter().filter(|d| d.completes_frame()).count() == 2);
        assert!(r.progress(2).finished());
        // Half-way through a level the view moves: a preview, and the sets start over.
        r.next(key(3, 0.1), true, 2, pacing);
        r.next(key(3, 0.1), false, 2, pacing);
        assert_eq!(r.progress(2).done, 0);
        assert_eq!(r.next(key(3, 0.2), true, 2, pacing), Some(Draw::Preview));
        assert!(matches!(
            r.next(key(3, 0.2), false, 2, pacing),
            Some(Draw::Rows {
                iterations: 1,
                rows: RowSet {
                    first: 0,
                    stride: 4
                },
                done: 12,
                height: 48
            })
        ));
    }

    #[test]
    fn sets_follow_the_latest_measurements() {
        // Two iterations planned at 0.5 ms a pixel: sets of every 2nd row (24 rows, 768 ms)
        // within a budget of 1000 ms.
        let paced = |per_pixel: f64| {
            let mut b = FrameBudget::new(1000.0);
            b.record(1, 1, 0.1);
            b.record(2, 1, per_pixel);
            b
        };
        let (fast, slow) = (paced(0.5), paced(1.0));
        let pacing = |b| {
            Some(Pacing {
                budget: b,
                preview: false,
            })
        };
        let mut r = Refinement::default();
        assert_eq!(
            r.next(key(1, 0.0), false, 2, pacing(&fast)),
            Some(Draw::Whole { iterations: 1 })
        );
        let rows = |d: Option<Draw>| match d {
            Some(Draw::Rows { rows, done, .. }) => (rows, done),
            other => panic!("{other:?}"),
        };
        let set = |first, stride| RowSet { first, stride };
        assert_eq!(
            rows(r.next(key(1, 0.0), false, 2, pacing(&fast))),
            (set(0, 2), 24)
        );
        // The cost turns out 1 ms a pixel: the other half (1536 ms) is traced in two.
        assert_eq!(
            rows(r.next(key(1, 0.0), false, 2, pacing(&slow))),
            (set(1, 4), 36)
        );
        assert!(!r.progress(2).finished());
        assert_eq!(
            rows(r.next(key(1, 0.0), false, 2, pacing(&slow))),
            (set(3, 4), 48)
        );
        assert!(r.progress(2).finished());
        assert_eq!(r.next(key(1, 0.0), false, 2, pacing(&slow)), None);
        // Cheaper than planned: the sets left are taken whole, the larger one unsplit.
        let mut r = Refinement::default();
        r.next(key(1, 0.0), false, 2, pacing(&slow));
        assert_eq!(
            rows(r.next(key(1, 0.0), false, 2, pacing(&slow))),
            (set(0, 4), 12)
        );
        let cheap = paced(0.001);
        assert_eq!(
            rows(r.next(key(1, 0.0), false, 2, pacing(&cheap))),
            (set(2, 4), 24)
        );
        assert_eq!(
            rows(r.next(key(1, 0.0), false, 2, pacing(&cheap))),
            (set(1, 2), 48)
        );
    }
}
