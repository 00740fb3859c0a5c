//! Frames of a range of steps written as PNGs, or as one MP4 movie, by a job on a thread of
//! its own, with a tracer of its own, so that the window stays live while it runs: the player's export. The trace
//! of one step file ([`trace_file`]) is shared with `slosh render`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError, channel};

use slosh_cache::CacheFile;
use slosh_mls::Camera;
use slosh_render::{Frame, Gpu, GpuStep, TraceParams, Tracer};

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
        std::thread::spawn(move || {
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
                        trace_file(
                            &gpu,
                            &tracer,
                            &file,
                            field,
                            &request.camera,
                            &request.params,
                        )
                    })
                    .map_err(|e| e.to_string())
                    .and_then(|(_, frame)| match movie.as_mut() {
                        Some((writer, seconds)) => {
                            let rgba: Vec<u8> =
                                frame.rgba.iter().flat_map(|p| p.to_le_bytes()).collect();
                            writer
                                .push_rgba(&rgba, seconds[k])
                                .map_err(|e| e.to_string())
                        }
                        None => {
                            slosh_render::write_frame_png(&out, &frame).map_err(|e| e.to_string())
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
        });
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
