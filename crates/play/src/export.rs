//! Frames of a range of steps written as PNGs, or as one MP4 movie, by a job on a thread of
//! its own, with a tracer of its own, so that the window stays live while it runs: the player's export. The trace
//! of one step file ([`trace_file`]) is shared with `slosh render`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError, channel};

use slosh_cache::CacheFile;
use slosh_mls::Camera;
use slosh_render::{Frame, Gpu, GpuStep, TraceParams, Tracer};

use crate::overlay::{Overlay, frame_rgb};

/// One step file on the GPU and traced: uploaded (with `field`, if named), rendered and read
/// back, waiting for the device.
pub fn trace_file(
    gpu: &Gpu,
    tracer: &Tracer,
    file: &CacheFile,
    field: Option<&str>,
    camera: &Camera,
    params: &TraceParams,
) -> slosh_render::Result<(GpuStep, Frame)> {
    let step = GpuStep::upload(gpu, file, field)?;
    let frame = tracer.render(gpu, &step, camera, params)?;
    Ok((step, frame))
}

/// `{}` or `{:0N}` in `pattern` replaced by `step` (zero-padded to N digits).
pub fn step_pattern(pattern: &Path, step: usize) -> PathBuf {
    let text = pattern.to_string_lossy();
    let Some(open) = text.find('{') else {
        return pattern.to_path_buf();
    };
    let Some(close) = text[open..].find('}').map(|c| open + c) else {
        return pattern.to_path_buf();
    };
    let width: usize = text[open + 1..close]
        .trim_start_matches(':')
        .parse()
        .unwrap_or(0);
    PathBuf::from(format!(
        "{}{step:0width$}{}",
        &text[..open],
        &text[close + 1..]
    ))
}

/// A step rendered from a cache directory must belong to its series (`manifest`, read once
/// per run where the directory has one).
pub fn check_belongs(
    manifest: Option<&slosh_cache::Manifest>,
    dir: &Path,
    step: usize,
    path: &Path,
    file: &CacheFile,
) -> Result<(), String> {
    if let Some(manifest) = manifest {
        let problems = manifest.step_problems(step, file);
        if !problems.is_empty() {
            return Err(format!(
                "{}: not step {step} of the series in {}: {}",
                path.display(),
                dir.display(),
                problems.join("; ")
            ));
        }
    }
    Ok(())
}

/// A `width` × `height` movie at `out` of the step files `steps`, with each frame's seconds
/// under `timing` (the steps' times read from their headers where it asks for them).
pub fn open_movie(
    out: &Path,
    timing: slosh_movie::Timing,
    steps: &[PathBuf],
    (width, height): (u32, u32),
) -> Result<(slosh_movie::MovieWriter, Vec<f64>), String> {
    let mut times = vec![0.0; steps.len()];
    if matches!(timing, slosh_movie::Timing::SeriesTimes { .. }) {
        for (t, path) in times.iter_mut().zip(steps) {
            *t = CacheFile::open(path)
                .map_err(|e| e.to_string())?
                .header()
                .source
                .time;
        }
    }
    let seconds = slosh_movie::frame_seconds(timing, &times)
        .map_err(|e| format!("{}: {e}", out.display()))?;
    let fps = seconds.len() as f64 / seconds.iter().sum::<f64>();
    let writer =
        slosh_movie::MovieWriter::new(out, width, height, fps).map_err(|e| e.to_string())?;
    Ok((writer, seconds))
}

/// Writes the movie: what it holds, as a line for the terminal.
pub fn finish_movie(movie: slosh_movie::MovieWriter) -> Result<String, String> {
    let path = movie.path().display().to_string();
    let s = movie.finish().map_err(|e| e.to_string())?;
    Ok(format!(
        "wrote {path}: {} frames, {}x{}, {:.3} s, {:.1} MB (H.264 in MP4)",
        s.frames,
        s.width,
        s.height,
        s.seconds,
        s.bytes as f64 / 1e6
    ))
}

/// What to export: steps by bake index and file, one camera and trace settings for all.
#[derive(Debug, Clone)]
pub struct ExportRequest {
    pub steps: Vec<(usize, PathBuf)>,
    pub camera: Camera,
    pub params: TraceParams,
    pub field: Option<String>,
    /// Frames go here as `NNNNN.png`, by bake index; created as needed.
    pub dir: PathBuf,
    /// Instead of PNGs: one H.264 movie at this path, frame i shown for `seconds[i]`.
    pub movie: Option<MovieRequest>,
    /// Each frame carries its time label and, with a field, the colour legend.
    pub labels: bool,
}

/// Where an export's movie goes and how long each of its frames is shown.
#[derive(Debug, Clone)]
pub struct MovieRequest {
    pub path: PathBuf,
    pub seconds: Vec<f64>,
}

/// Where frame `index` of an export into `dir` goes.
pub fn frame_path(dir: &Path, index: usize) -> PathBuf {
    dir.join(format!("{index:05}.png"))
}

/// How an export stands.
#[derive(Debug, Clone, PartialEq)]
pub enum ExportState {
    Running {
        done: usize,
        total: usize,
    },
    Finished {
        frames: usize,
        dir: PathBuf,
    },
    /// The first frame that failed, and why; nothing more is written.
    Failed(String),
}

/// An export running on its own thread; dropping it stops the thread after its current frame.
#[derive(Debug)]
pub struct ExportJob {
    progress: Receiver<Result<PathBuf, String>>,
    done: usize,
    total: usize,
    dir: PathBuf,
}

impl ExportJob {
    /// Starts `request` on a new thread; an error where it names no step.
    pub fn spawn(gpu: Arc<Gpu>, request: ExportRequest) -> Result<ExportJob, String> {
        if request.steps.is_empty() {
            return Err("no readable step".into());
        }
        let (tx, rx) = channel();
        let total = request.steps.len();
        let dir = match &request.movie {
            Some(m) if m.seconds.len() != total => {
                return Err(format!(
                    "{} frame durations for {total} steps",
                    m.seconds.len()
                ));
            }
            Some(m) => m.path.clone(),
            None => request.dir.clone(),
        };
        // A thread the binary waits for before it exits (`slosh_render::wait_for_background`):
        // a dropped job stops after the frame in hand, which must not meet the driver's
        // exit-time teardown.
        slosh_render::spawn_background("export".into(), move || {
            let tracer = match Tracer::new(&gpu) {
                Ok(t) => t,
                Err(e) => {
                    let _ = tx.send(Err(e.to_string()));
                    return;
                }
            };
            let folder = match &request.movie {
                Some(m) => m.path.parent().map(Path::to_path_buf).unwrap_or_default(),
                None => request.dir.clone(),
            };
            if let Err(e) = std::fs::create_dir_all(&folder) {
                let _ = tx.send(Err(format!("{}: {e}", folder.display())));
                return;
            }
            let mut movie = match &request.movie {
                Some(m) => {
                    let fps = m.seconds.len() as f64 / m.seconds.iter().sum::<f64>();
                    let (w, h) = (request.camera.width, request.camera.height);
                    match slosh_movie::MovieWriter::new(&m.path, w, h, fps) {
                        Ok(writer) => Some((writer, &m.seconds)),
                        Err(e) => {
                            let _ = tx.send(Err(e.to_string()));
                            return;
                        }
                    }
                }
                None => None,
            };
            for (k, (index, path)) in request.steps.iter().enumerate() {
                let out = frame_path(&request.dir, *index);
                let written = CacheFile::open(path)
                    .map_err(slosh_render::Error::from)
                    .and_then(|file| {
                        let field = request.field.as_deref();
                        let time = file.header().source.time;
                        trace_file(
                            &gpu,
                            &tracer,
                            &file,
                            field,
                            &request.camera,
                            &request.params,
                        )
                        .map(|traced| (time, traced))
                    })
                    .map_err(|e| e.to_string())
                    .and_then(|(time, (step, frame))| {
                        let overlay = request
                            .labels
                            .then(|| Overlay::for_step(time, *index, &step, &request.params));
                        let rgb = frame_rgb(&frame, overlay.as_ref());
                        match movie.as_mut() {
                            Some((writer, seconds)) => {
                                writer.push_rgb(&rgb, seconds[k]).map_err(|e| e.to_string())
                            }
                            None => {
                                slosh_render::write_rgb_png(&out, frame.width, frame.height, &rgb)
                                    .map_err(|e| e.to_string())
                            }
                        }
                    });
                // A movie's last frame counts once the file is written.
                let written = match (written, k + 1 == total, movie.take()) {
                    (Ok(()), true, Some((writer, _))) => {
                        writer.finish().map(|_| ()).map_err(|e| e.to_string())
                    }
                    (written, _, held) => {
                        movie = held;
                        written
                    }
                };
                let failed = written.is_err();
                let sent = tx.send(written.map(|()| out));
                if sent.is_err() || failed {
                    return;
                }
            }
        })
        .map_err(|e| format!("no thread for the export: {e}"))?;
        Ok(ExportJob {
            progress: rx,
            done: 0,
            total,
            dir,
        })
    }

    /// Frames written so far, of the total.
    pub fn progress(&self) -> (usize, usize) {
        (self.done, self.total)
    }

    /// Takes in what the thread finished since the last call, without waiting.
    pub fn poll(&mut self) -> ExportState {
        let stopped = loop {
            match self.progress.try_recv() {
                Ok(Ok(_)) => self.done += 1,
                Ok(Err(why)) => return ExportState::Failed(why),
                Err(TryRecvError::Empty) => break false,
                Err(TryRecvError::Disconnected) => break true,
            }
        };
        if self.done == self.total {
            ExportState::Finished {
                frames: self.total,
                dir: self.dir.clone(),
            }
        } else if stopped {
            ExportState::Failed(format!(
                "the export stopped after {} of {} frames",
                self.done, self.total
            ))
        } else {
            ExportState::Running {
                done: self.done,
                total: self.total,
            }
        }
    }
}
