//! Progressive refinement: while time or the camera moves, frames use the baked polynomial
//! (one iteration); when both are still, the same view is traced again with one more
//! iteration per frame until the requested count. The last frame of a finished refinement
//! is a direct render at that count.

use slosh_mls::Camera;
use slosh_render::TraceParams;

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
    /// Iterations of the frame last drawn.
    pub done: u32,
    /// Iterations asked for once still.
    pub target: u32,
}

impl Progress {
    pub fn finished(&self) -> bool {
        self.done >= self.target
    }
}

#[derive(Debug, Clone, Default)]
pub struct Refinement {
    key: Option<ViewKey>,
    done: u32,
}

impl Refinement {
    /// The iterations to draw this frame with, or `None` when the view is already drawn at
    /// `target` and nothing changed. `moving`: time or the camera is in motion.
    pub fn next(&mut self, key: ViewKey, moving: bool, target: u32) -> Option<u32> {
        let target = target.max(1);
        if moving || self.key.as_ref() != Some(&key) {
            self.key = Some(key);
            self.done = 1;
            return Some(1);
        }
        if self.done < target {
            self.done += 1;
            return Some(self.done);
        }
        if self.done > target {
            // The target was lowered: draw it once at the new count.
            self.done = target;
            return Some(target);
        }
        None
    }

    /// Forgets the view: the next frame is drawn whatever it is.
    pub fn invalidate(&mut self) {
        self.key = None;
        self.done = 0;
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

    #[test]
    fn still_views_refine_one_iteration_per_frame_then_stop() {
        let mut r = Refinement::default();
        let drawn: Vec<Option<u32>> = (0..5).map(|_| r.next(key(3, 0.0), false, 3)).collect();
        assert_eq!(drawn, vec![Some(1), Some(2), Some(3), None, None]);
        assert!(r.progress(3).finished());
        // The camera moves: back to one iteration, and while moving it stays there.
        assert_eq!(r.next(key(3, 0.1), true, 3), Some(1));
        assert_eq!(r.next(key(3, 0.2), true, 3), Some(1));
        assert_eq!(r.next(key(3, 0.2), false, 3), Some(2));
        // Another step is another view.
        assert_eq!(r.next(key(4, 0.2), false, 3), Some(1));
        // Lowering the target draws the lower count once.
        r.next(key(4, 0.2), false, 3);
        r.next(key(4, 0.2), false, 3);
        assert_eq!(r.next(key(4, 0.2), false, 2), Some(2));
        assert_eq!(r.next(key(4, 0.2), false, 2), None);
        r.invalidate();
        assert_eq!(r.next(key(4, 0.2), false, 2), Some(1));
    }
}
