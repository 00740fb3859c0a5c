//! Driving the engine without a window: a frame submitted and waited for, and frames until a
//! step is on screen. What tests and `slosh bench scrub` use; the player submits its own.

use std::time::{Duration, Instant};

use super::{Engine, FrameReport, FrameRequest};
use crate::error::{Error, Result};

/// How [`Engine::show_and_wait`] paces its frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pace {
    /// Each frame's `seconds` is the real time since the last, as a person's frames are
    /// (playback and the rate of motion follow); else `seconds` stays as given, for runs that
    /// repeat exactly.
    pub real_time: bool,
    /// Slept between frames, leaving the loader threads the cores.
    pub pause: Duration,
    /// The most a step may take to be shown.
    pub timeout: Duration,
}

impl Engine {
    /// One frame recorded, submitted and waited for.
    pub fn frame_and_wait(&mut self, request: &FrameRequest) -> Result<FrameReport> {
        let gpu = self.gpu().clone();
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame and wait"),
            });
        let report = self.frame(request, &mut encoder)?;
        gpu.queue.submit([encoder.finish()]);
        self.finish_frame()?;
        gpu.wait()?;
        Ok(report)
    }

    /// Frames (each waited for) from a jump to `position` until it is drawn, not a stand-in,
    /// paced by `pace`, with `each` called on every report. An error where the step fails or
    /// is not shown within the pace's timeout.
    pub fn show_and_wait(
        &mut self,
        request: &mut FrameRequest,
        position: usize,
        pace: Pace,
        mut each: impl FnMut(&Engine, &FrameReport),
    ) -> Result<Vec<FrameReport>> {
        let start = Instant::now();
        self.timeline_mut().set_current(position);
        let mut last = Instant::now();
        let mut reports = Vec::new();
        loop {
            if pace.real_time {
                request.seconds = last.elapsed().as_secs_f64();
                last = Instant::now();
            }
            let report = self.frame_and_wait(request)?;
            each(self, &report);
            if let Some((p, why)) = report.failures.iter().find(|(p, _)| *p == position) {
                return Err(Error::NotShown {
                    position: *p,
                    why: format!("failed: {why}"),
                });
            }
            let done = report.shown == Some(position) && !report.stand_in;
            reports.push(report);
            if done {
                return Ok(reports);
            }
            if start.elapsed() > pace.timeout {
                return Err(Error::NotShown {
                    position,
                    why: format!("not shown within {} s", pace.timeout.as_secs_f64()),
                });
            }
            std::thread::sleep(pace.pause);
        }
    }
}
