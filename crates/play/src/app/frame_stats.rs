//! What the status bar reports of the frames: their interval, trace and upload times, and
//! how many were drawn.

use std::time::Instant;

use super::run_queue::waited_for_a_core;
use crate::engine::{Engine, FrameReport};
use crate::refine::Draw;

/// Timings of the UI's frames, as the status bar shows them.
#[derive(Debug, Clone)]
pub struct FrameStats {
    last_frame: Instant,
    /// Milliseconds between the last two UI frames: what a person sees as the frame time.
    pub frame_ms: f64,
    /// Milliseconds of `frame_ms` the UI thread waited, runnable, for a core (other processes
    /// or the software GPU's threads held them), where [`FrameStats::with_queue_waits`] asked
    /// for them and the kernel says.
    pub queued_ms: Option<f64>,
    queued_before: Option<std::time::Duration>,
    /// Milliseconds of CPU the window's previous frame took (this player's pass, then eframe's
    /// tessellation and paint recording), less its waits for the surface and the present:
    /// what eframe says, `None` before it says.
    pub previous_cpu_ms: Option<f64>,
    pub trace_ms: Option<f64>,
    pub upload_ms: f64,
    /// Frames drawn so far.
    pub frames: u64,
    /// UI passes so far.
    pub passes: u64,
}

impl Default for FrameStats {
    fn default() -> FrameStats {
        FrameStats {
            last_frame: Instant::now(),
            frame_ms: 0.0,
            queued_ms: None,
            queued_before: None,
            previous_cpu_ms: None,
            trace_ms: None,
            upload_ms: 0.0,
            frames: 0,
            passes: 0,
        }
    }
}

impl FrameStats {
    /// Timings that also say how long the UI thread waited for a core (a file read a frame:
    /// for the frame log only).
    pub fn with_queue_waits() -> FrameStats {
        FrameStats {
            queued_before: waited_for_a_core(),
            ..FrameStats::default()
        }
    }

    /// Seconds since the last frame began, and a new frame begun.
    pub fn begin_frame(&mut self) -> f64 {
        let seconds = self.last_frame.elapsed().as_secs_f64();
        self.last_frame = Instant::now();
        self.frame_ms = seconds * 1e3;
        if let Some(before) = self.queued_before {
            let queued = waited_for_a_core();
            self.queued_ms = queued.map(|now| now.saturating_sub(before).as_secs_f64() * 1e3);
            self.queued_before = queued;
        }
        seconds
    }

    /// Takes in a frame's report: a drawn frame and its trace time (`None` where the device
    /// has no timestamps), an upload's host time.
    pub fn record(&mut self, report: &FrameReport, trace_ms: Option<Option<f64>>) {
        if report.drawn.is_some() {
            self.frames += 1;
            if let Some(t) = trace_ms {
                self.trace_ms = t;
            }
        }
        if !report.uploaded.is_empty() {
            self.upload_ms = report
                .uploaded
                .iter()
                .map(|u| u.host_ms + u.record_ms)
                .sum();
        }
    }

    /// The status bar's first line: times, residency, refinement and the step on screen.
    pub fn status_line(&self, engine: &Engine, last: &FrameReport) -> String {
        let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
        let progress = last.progress.map_or(String::new(), |p| {
            format!(" · refined {}/{}", p.done, p.target)
        });
        // What is on screen, where the frame budget lowered it or a refinement is in bands.
        let percent = |part: u32, whole: u32| u64::from(part) * 100 / u64::from(whole.max(1));
        let quality = match (last.masks, last.quality, &last.draw) {
            (Some(m), _, _) => format!(" · neighbour masks {}%", percent(m.derived, m.total)),
            (
                _,
                _,
                Some(Draw::Rows {
                    iterations,
                    done,
                    height,
                    ..
                }),
            ) => format!(
                " · refining {iterations} it: {}% of rows",
                percent(*done, *height)
            ),
            (_, Some(q), _) if q.scale < 1.0 => format!(
                " · showing {:.0}% size, {} it",
                q.scale * 100.0,
                q.iterations
            ),
            _ => String::new(),
        };
        let index = |p: usize| engine.bake_index(p).unwrap_or(p);
        let shown = match (last.shown, last.stand_in) {
            (Some(s), true) => format!(" · showing step {} for {}", index(s), index(last.wanted)),
            (Some(s), false) => format!(" · step {}", index(s)),
            (None, _) => " · nothing resident yet".into(),
        };
        let dropped = engine.shown_step().map_or(String::new(), |(_, step)| {
            dropped_note(step.info.dropped_non_finite, step.info.dropped_far)
        });
        format!(
            "frame {:.1} ms · trace {} · upload {:.1} ms · {} / {} steps resident · {:.2} / {:.2} GiB{progress}{quality}{shown}{dropped} · {} frames",
            self.frame_ms,
            self.trace_ms.map_or("–".into(), |t| format!("{t:.2} ms")),
            self.upload_ms,
            engine.resident().len(),
            engine.timeline().len(),
            gib(engine.used_bytes()),
            gib(engine.budget()),
            self.frames,
        )
    }
}

/// What the bake dropped from the step on screen, where it dropped any: input damage is
/// seen where the step is looked at, not only by `slosh inspect`.
fn dropped_note(non_finite: u64, far: u64) -> String {
    slosh_bake::dropped_input(non_finite, far)
        .map_or(String::new(), |dropped| format!(" · dropped {dropped}"))
}

#[cfg(test)]
mod tests {
    use super::dropped_note;

    #[test]
    fn the_status_bar_names_what_the_bake_dropped_only_where_it_dropped_any() {
        assert_eq!(dropped_note(0, 0), "");
        assert_eq!(
            dropped_note(10, 0),
            " · dropped 10 with a non-finite coordinate"
        );
        assert_eq!(dropped_note(0, 2), " · dropped 2 far beyond the rest");
        assert_eq!(
            dropped_note(10, 2),
            " · dropped 10 with a non-finite coordinate and 2 far beyond the rest"
        );
    }
}
