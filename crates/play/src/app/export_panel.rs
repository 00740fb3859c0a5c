//! The Output section's export: a range of steps (by bake index) that follows a growing
//! series, the frame size and iterations, PNG frames or an MP4 movie (timed by a rate or by
//! the series' times), and the running [`ExportJob`].

use std::path::Path;
use std::sync::Arc;

use eframe::egui;
use slosh_mls::Camera;
use slosh_render::{Gpu, TraceParams};

use crate::engine::Engine;
use crate::export::{ExportJob, ExportRequest, ExportState, MovieRequest};

/// The export's settings and its job while one runs.
#[derive(Debug)]
pub struct ExportPanel {
    /// The export's steps, by bake index.
    pub first: usize,
    pub last: usize,
    /// The series' last bake index when the range was last looked at: a range that ended
    /// there grows with the series.
    seen_last: usize,
    pub size: (u32, u32),
    pub iterations: u32,
    /// One MP4 instead of a PNG per step.
    pub movie: bool,
    /// The movie's frame rate; 0: the series' times, slowed down by `slowdown`.
    pub fps: f64,
    pub slowdown: f64,
    /// Frames carry the time label and the colour legend.
    pub labels: bool,
    job: Option<ExportJob>,
}

/// An export range (bake indices) after the series came to span `series`: one that ended at
/// the last step seen (`seen_last`) ends at the new last step; every range stays within.
fn follow_series(
    range: (usize, usize),
    seen_last: usize,
    series: (usize, usize),
) -> (usize, usize) {
    let (first, mut last) = range;
    if last == seen_last {
        last = series.1;
    }
    (
        first.clamp(series.0, series.1),
        last.clamp(series.0, series.1),
    )
}

/// The first and last bake index of the series (0, 0 before any step).
fn series_span(engine: &Engine) -> (usize, usize) {
    let steps = engine.series().steps();
    (
        steps.first().map_or(0, |s| s.index),
        steps.last().map_or(0, |s| s.index),
    )
}

impl ExportPanel {
    /// The whole series at 1920×1080, three iterations.
    pub fn new(engine: &Engine) -> ExportPanel {
        let (first, last) = series_span(engine);
        ExportPanel {
            first,
            last,
            seen_last: last,
            size: (1920, 1080),
            iterations: 3,
            movie: false,
            fps: 0.0,
            slowdown: 1.0,
            labels: true,
            job: None,
        }
    }

    pub fn running(&self) -> bool {
        self.job.is_some()
    }

    /// A range that ended at the series' last step grows with the series (a bake adding
    /// steps), and every range stays within the series.
    fn follow_series(&mut self, engine: &Engine) {
        if engine.series().is_empty() {
            return;
        }
        let span = series_span(engine);
        (self.first, self.last) = follow_series((self.first, self.last), self.seen_last, span);
        self.seen_last = span.1;
    }

    /// The range, size and iterations, and the button or the progress: whether the button
    /// was pressed.
    pub fn ui(&mut self, ui: &mut egui::Ui, engine: &Engine) -> bool {
        self.follow_series(engine);
        let (first, last) = series_span(engine);
        ui.horizontal(|ui| {
            ui.label("steps");
            ui.add(egui::DragValue::new(&mut self.first).range(first..=last));
            ui.label("–");
            ui.add(egui::DragValue::new(&mut self.last).range(first..=last));
        });
        ui.horizontal(|ui| {
            ui.add(egui::DragValue::new(&mut self.size.0).range(16..=8192));
            ui.label("×");
            ui.add(egui::DragValue::new(&mut self.size.1).range(16..=8192));
            ui.add(
                egui::DragValue::new(&mut self.iterations)
                    .range(1..=8)
                    .suffix(" it"),
            );
        });
        ui.horizontal(|ui| {
            ui.checkbox(&mut self.labels, "labels");
            ui.checkbox(&mut self.movie, "MP4");
            if self.movie {
                ui.add(
                    egui::DragValue::new(&mut self.fps)
                        .range(0.0..=240.0)
                        .suffix(" fps")
                        .custom_formatter(|v, _| {
                            if v == 0.0 {
                                "series times".into()
                            } else {
                                format!("{v}")
                            }
                        }),
                );
                if self.fps == 0.0 {
                    ui.add(
                        egui::DragValue::new(&mut self.slowdown)
                            .range(0.01..=1e6)
                            .prefix("×")
                            .suffix(" slower"),
                    );
                }
            }
        });
        match &self.job {
            Some(job) => {
                let (done, total) = job.progress();
                ui.label(format!("exporting {done}/{total}…"));
                false
            }
            None => ui
                .button(if self.movie {
                    "export movie"
                } else {
                    "export frames"
                })
                .clicked(),
        }
    }

    /// Starts exporting the range's readable steps with `camera` (at the export's size) and
    /// `params` (at the export's iterations) into `output`/frames; an error message where
    /// it cannot start.
    pub fn start(
        &mut self,
        gpu: Arc<Gpu>,
        engine: &Engine,
        camera: Camera,
        mut params: TraceParams,
        output: &Path,
    ) -> Option<String> {
        let (first, last) = (self.first.min(self.last), self.first.max(self.last));
        let chosen: Vec<_> = engine
            .series()
            .steps()
            .iter()
            .filter(|s| (first..=last).contains(&s.index) && s.problem.is_none())
            .collect();
        let movie = if self.movie {
            let timing = if self.fps > 0.0 {
                slosh_movie::Timing::Fps(self.fps)
            } else {
                slosh_movie::Timing::SeriesTimes {
                    slowdown: self.slowdown,
                }
            };
            let times: Vec<f64> = chosen.iter().map(|s| s.time).collect();
            match slosh_movie::frame_seconds(timing, &times) {
                Ok(seconds) => Some(MovieRequest {
                    path: output.join(format!("movie-{first:05}-{last:05}.mp4")),
                    seconds,
                }),
                Err(why) => return Some(format!("export: {why}")),
            }
        } else {
            None
        };
        let steps = chosen.iter().map(|s| (s.index, s.path.clone())).collect();
        params.iterations = self.iterations;
        let request = ExportRequest {
            steps,
            camera,
            params,
            field: engine.field().map(str::to_string),
            dir: output.join("frames"),
            movie,
            labels: self.labels,
        };
        match ExportJob::spawn(gpu, request) {
            Ok(job) => {
                self.job = Some(job);
                None
            }
            Err(why) => Some(format!("export: {why} in {first}..={last}")),
        }
    }

    /// What the running export finished since the last pass: a message when it ended.
    pub fn poll(&mut self) -> Option<String> {
        let state = self.job.as_mut()?.poll();
        let message = match state {
            ExportState::Running { .. } => return None,
            ExportState::Finished { frames, dir } => {
                format!("exported {frames} frames to {}", dir.display())
            }
            ExportState::Failed(why) => format!("export: {why}"),
        };
        self.job = None;
        Some(message)
    }
}

#[cfg(test)]
mod tests {
    use super::follow_series;

    /// The export range grows with a series a bake is filling, unless the user set its end
    /// (issue 25, item 13).
    #[test]
    fn the_export_range_follows_a_growing_series() {
        // Opened with one step (0..=0), the bake adds steps up to 9.
        assert_eq!(follow_series((0, 0), 0, (0, 9)), (0, 9));
        // An end the user moved stays.
        assert_eq!(follow_series((2, 5), 9, (0, 20)), (2, 5));
        // Steps removed from the end: the range stays within the series.
        assert_eq!(follow_series((3, 12), 9, (0, 8)), (3, 8));
    }
}
