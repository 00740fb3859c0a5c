//! The player window: the traced viewport, the timeline, the controls and the status bar,
//! over one [`Engine`]. Widgets read and change the engine's state; they hold none of their
//! own beyond what is being edited.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, channel};
use std::time::Instant;

use eframe::egui;
use slosh_cache::{CacheFile, names};
use slosh_render::{Gpu, GpuStep, ShadeMode, TraceParams, Tracer, colormap};

use super::camera::OrbitCamera;
use super::timeline_panel;
use crate::engine::{Engine, EngineOptions, FrameReport, FrameRequest};

/// How `slosh play` was asked to run.
#[derive(Debug, Clone)]
pub struct PlayOptions {
    pub dir: PathBuf,
    pub adapter: Option<String>,
    pub engine: EngineOptions,
    /// Viewport pixels traced per physical pixel, per axis (0.25–2).
    pub render_scale: f32,
    /// The up axis; `None`: z.
    pub up: Option<[f64; 3]>,
    /// Iterations refined to once the view is still.
    pub iterations: u32,
    /// Window inner size in logical points.
    pub window: (f32, f32),
    /// Where screenshots and exported frames go.
    pub output: PathBuf,
    /// Print a line per UI frame and per failure (for tests driving the window).
    pub log_frames: bool,
    /// Map each step's own field range to the colour map, instead of the range seen over
    /// the series.
    pub step_range: bool,
}

/// Why the player could not start.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error(
        "no Vulkan adapter for the player: {0}\n  install a Vulkan driver: your GPU vendor's, or Mesa's software one (Debian/Ubuntu: apt install mesa-vulkan-drivers libvulkan1)"
    )]
    NoGpu(slosh_render::Error),
    #[error(transparent)]
    Engine(#[from] crate::Error),
    #[error("the window could not open: {0}")]
    Window(String),
}

/// Field range on the colour map.
#[derive(Debug, Clone, Copy, PartialEq)]
enum RangeMode {
    /// Each step's own range.
    Step,
    /// The widest range seen over the steps shown so far.
    Series,
    Fixed(f32, f32),
}

/// An export of frames running on its own thread.
struct Export {
    progress: Receiver<Result<(usize, PathBuf), String>>,
    done: usize,
    total: usize,
}

struct Player {
    engine: Engine,
    gpu: Arc<Gpu>,
    render_state: eframe::egui_wgpu::RenderState,
    camera: OrbitCamera,
    home: OrbitCamera,
    mode: ShadeMode,
    iterations: u32,
    render_scale: f32,
    up_axis: usize,
    field_choice: Option<String>,
    fields: Vec<String>,
    range_mode: RangeMode,
    series_range: Option<(f32, f32)>,
    /// The registered texture and the size it was registered at.
    texture: Option<(egui::TextureId, (u32, u32))>,
    last_frame: Instant,
    /// Milliseconds between the last two UI frames.
    frame_ms: f64,
    trace_ms: Option<f64>,
    upload_ms: f64,
    frames: u64,
    last: FrameReport,
    message: Option<String>,
    last_refresh: Instant,
    output: PathBuf,
    export: Option<Export>,
    /// The export's steps, by bake index.
    export_first: usize,
    export_last: usize,
    /// The series' last bake index when the range was last looked at: a range that ended
    /// there grows with the series.
    export_seen_last: usize,
    export_size: (u32, u32),
    export_iterations: u32,
    bounds: [[f64; 3]; 2],
    /// F12 was pressed: save the next drawn frame.
    screenshot_pending: bool,
    log_frames: bool,
    /// The key light's azimuth and elevation about the up axis, in degrees.
    light: (f32, f32),
    /// UI passes so far.
    passes: u64,
    /// The viewport in physical pixels within the window.
    viewport_px: egui::Rect,
    /// The window title last set (set again only when it changes: setting it asks for
    /// another pass).
    title: String,
}

/// Runs the player until its window closes.
pub fn run(options: PlayOptions) -> Result<(), AppError> {
    let gpu = Gpu::new(options.adapter.as_deref()).map_err(AppError::NoGpu)?;
    let instance = gpu
        .instance
        .clone()
        .ok_or_else(|| AppError::Window("the GPU came without its instance".into()))?;
    let setup = eframe::egui_wgpu::WgpuSetupExisting {
        instance,
        adapter: gpu.adapter.clone(),
        device: gpu.device.clone(),
        queue: gpu.queue.clone(),
    };
    let gpu = Arc::new(gpu);
    let engine = Engine::open(gpu.clone(), &options.dir, options.engine.clone())?;
    // The window's surface is a texture: a window manager that honours the hint never makes
    // it larger than the device holds (the device asks for the adapter's largest).
    let max_side = gpu.device.limits().max_texture_dimension_2d as f32;
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([options.window.0, options.window.1])
            .with_max_inner_size([max_side, max_side])
            .with_title("slosh"),
        renderer: eframe::Renderer::Wgpu,
        wgpu_options: eframe::egui_wgpu::WgpuConfiguration {
            wgpu_setup: eframe::egui_wgpu::WgpuSetup::Existing(setup),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut slot = Some((engine, gpu, options));
    eframe::run_native(
        "slosh",
        native,
        Box::new(move |cc| {
            let (engine, gpu, options) = slot.take().ok_or("the player was created twice")?;
            let render_state = cc
                .wgpu_render_state
                .clone()
                .ok_or("eframe gave no wgpu render state")?;
            Ok(Box::new(Player::new(engine, gpu, render_state, options)))
        }),
    )
    .map_err(|e| AppError::Window(e.to_string()))
}

/// A line on stdout, flushed at once (a test reading it through a pipe or file must not wait
/// for a buffer to fill).
fn say(line: &str) {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

/// Field names baked into a step file.
fn baked_fields(engine: &Engine) -> Vec<String> {
    let Some(first) = engine.series().steps().first() else {
        return Vec::new();
    };
    CacheFile::open(&first.path)
        .map(|f| {
            f.header()
                .sections
                .iter()
                .filter_map(|s| s.name.strip_prefix(names::FIELD_PREFIX))
                .map(str::to_string)
                .collect()
        })
        .unwrap_or_default()
}

/// The series' world bounds: the manifest's, or the first step's while a bake runs.
fn series_bounds(engine: &Engine) -> [[f64; 3]; 2] {
    if let Ok(m) = slosh_cache::Manifest::read(engine.series().dir()) {
        return m.bounds;
    }
    // The first step with particles (a Lagrangian run's first steps may have none).
    engine
        .series()
        .steps()
        .iter()
        .filter_map(|s| CacheFile::open(&s.path).ok())
        .find(|f| f.header().points > 0)
        .map_or([[-1.0; 3], [1.0; 3]], |f| f.header().bounds)
}

/// Azimuth and elevation (degrees) of the default key light about z.
fn default_light() -> (f32, f32) {
    let [x, y, z] = slosh_render::DEFAULT_KEY_LIGHT;
    (
        y.atan2(x).to_degrees(),
        z.clamp(-1.0, 1.0).asin().to_degrees(),
    )
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

/// The most pixels a frame is traced at (8K: 7680 × 4320).
const MAX_FRAME_PIXELS: u64 = 7680 * 4320;

/// The frame size for a viewport of `width` × `height` physical pixels (render scale
/// applied): as it is where the device can hold it, else scaled down, keeping its aspect, to
/// the device's largest texture (the texture is stretched over the viewport).
fn fit_texture(width: f32, height: f32, max_side: u32, max_pixels: u64) -> (u32, u32) {
    let (width, height) = (f64::from(width).max(1.0), f64::from(height).max(1.0));
    // And at most an 8K display's pixels, or what the device can bind for a frame's hits if
    // less: the hit buffers grow with the pixels (a window an X client sizes to 16000² would
    // ask for gigabytes), and past 8K a person cannot tell.
    let most = (MAX_FRAME_PIXELS as f64).min(max_pixels as f64);
    let shrink = (f64::from(max_side) / width.max(height))
        .min((most / (width * height)).sqrt())
        .min(1.0);
    // Rounded down when shrunk, so that the sides' product stays within the pixels allowed.
    let side = |v: f64| {
        let scaled = if shrink < 1.0 {
            (v * shrink).floor()
        } else {
            v.round()
        };
        (scaled as u32).clamp(1, max_side.max(1))
    };
    (side(width), side(height))
}

fn axis_vector(axis: usize) -> [f64; 3] {
    std::array::from_fn(|a| if a == axis { 1.0 } else { 0.0 })
}

impl Player {
    fn new(
        engine: Engine,
        gpu: Arc<Gpu>,
        render_state: eframe::egui_wgpu::RenderState,
        options: PlayOptions,
    ) -> Player {
        // Up from the command line, else from the data (the first step's header), else z.
        let up = options
            .up
            .or_else(|| {
                engine
                    .series()
                    .steps()
                    .first()
                    .and_then(|s| CacheFile::open(&s.path).ok())
                    .and_then(|f| f.header().up)
            })
            .unwrap_or([0.0, 0.0, 1.0]);
        let up_axis = (0..3)
            .max_by(|&a, &b| up[a].abs().total_cmp(&up[b].abs()))
            .unwrap_or(2);
        let bounds = series_bounds(&engine);
        let camera = OrbitCamera::framing(&bounds, 40.0, axis_vector(up_axis));
        let fields = baked_fields(&engine);
        let field_choice = engine.field().map(str::to_string);
        let first_step = engine.series().steps().first().map_or(0, |s| s.index);
        let last_step = engine.series().steps().last().map_or(0, |s| s.index);
        Player {
            gpu,
            render_state,
            camera,
            home: camera,
            mode: ShadeMode::Shade,
            iterations: options.iterations.max(1),
            render_scale: options.render_scale.clamp(0.25, 2.0),
            up_axis,
            field_choice,
            fields,
            range_mode: if options.step_range {
                RangeMode::Step
            } else {
                RangeMode::Series
            },
            series_range: None,
            texture: None,
            last_frame: Instant::now(),
            frame_ms: 0.0,
            trace_ms: None,
            upload_ms: 0.0,
            frames: 0,
            last: FrameReport::default(),
            message: None,
            last_refresh: Instant::now(),
            output: options.output,
            export: None,
            export_first: first_step,
            export_last: last_step,
            export_seen_last: last_step,
            export_size: (1920, 1080),
            export_iterations: 3,
            bounds,
            engine,
            screenshot_pending: false,
            viewport_px: egui::Rect::NOTHING,
            log_frames: options.log_frames,
            light: default_light(),
            passes: 0,
            title: String::new(),
        }
    }

    /// Every key press of the pass, in order: presses faster than the passes (a slow frame)
    /// each count.
    fn keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let presses: Vec<(egui::Key, bool)> = ctx.input(|i| {
            i.events
                .iter()
                .filter_map(|e| match e {
                    egui::Event::Key {
                        key,
                        pressed: true,
                        modifiers,
                        ..
                    } => Some((*key, modifiers.shift)),
                    _ => None,
                })
                .collect()
        });
        let t = self.engine.timeline_mut();
        for (key, shift) in presses {
            let by = if shift { 10 } else { 1 };
            match key {
                egui::Key::Space => t.toggle_play(),
                egui::Key::ArrowRight => t.step_by(by),
                egui::Key::ArrowLeft => t.step_by(-by),
                egui::Key::Home => t.home(),
                egui::Key::End => t.end(),
                egui::Key::F12 => self.screenshot_pending = true,
                _ => {}
            }
        }
    }

    /// The key light's direction: azimuth and elevation about the chosen up axis (for z up,
    /// the default is `DEFAULT_KEY_LIGHT`).
    fn key_light(&self) -> [f32; 3] {
        let (az, el) = (self.light.0.to_radians(), self.light.1.to_radians());
        let mut d = [0.0f32; 3];
        d[(self.up_axis + 1) % 3] = el.cos() * az.cos();
        d[(self.up_axis + 2) % 3] = el.cos() * az.sin();
        d[self.up_axis] = el.sin();
        d
    }

    fn params(&self) -> TraceParams {
        let (degree, covariance) = self
            .engine
            .shown_step()
            .map_or((2, false), |(_, s)| (s.info.degree, s.info.covariance));
        let field_range = match self.range_mode {
            RangeMode::Step => None,
            RangeMode::Series => self.series_range,
            RangeMode::Fixed(lo, hi) => Some((lo, hi)),
        };
        TraceParams {
            iterations: self.iterations,
            degree,
            h_factor: 1.0,
            covariance,
            epsilon: 1e-4,
            mode: self.mode,
            field_range,
            key_light: self.key_light(),
        }
    }

    /// Traces the viewport into the engine's targets and shows them in `rect`.
    fn viewport(&mut self, ui: &mut egui::Ui) {
        let rect = ui.available_rect_before_wrap();
        let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
        let mut moving = false;
        let delta = response.drag_delta();
        if response.dragged_by(egui::PointerButton::Primary) && delta != egui::Vec2::ZERO {
            self.camera.orbit(f64::from(delta.x), f64::from(delta.y));
            moving = true;
        }
        if (response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle))
            && delta != egui::Vec2::ZERO
        {
            self.camera.pan(
                f64::from(delta.x),
                f64::from(delta.y),
                f64::from(rect.height()),
            );
            moving = true;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.camera.zoom((-f64::from(scroll) * 0.002).exp());
                moving = true;
            }
        }
        self.viewport_px = egui::Rect::from_min_max(
            (rect.min.to_vec2() * ui.ctx().pixels_per_point()).to_pos2(),
            (rect.max.to_vec2() * ui.ctx().pixels_per_point()).to_pos2(),
        );
        let ppp = ui.ctx().pixels_per_point() * self.render_scale;
        let (width, height) = fit_texture(
            rect.width() * ppp,
            rect.height() * ppp,
            self.gpu.device.limits().max_texture_dimension_2d,
            self.engine.tracer().max_frame_pixels(&self.gpu),
        );
        let seconds = self.last_frame.elapsed().as_secs_f64();
        self.last_frame = Instant::now();
        let request = FrameRequest {
            seconds,
            camera: self.camera.camera(width, height),
            params: self.params(),
            camera_moving: moving,
        };
        // The interval between UI frames: what a person sees as the frame time.
        self.frame_ms = seconds * 1e3;
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("player frame"),
            });
        match self.engine.frame(&request, &mut encoder) {
            Ok(report) => {
                self.gpu.queue.submit([encoder.finish()]);
                if report.drawn.is_some() {
                    self.frames += 1;
                    if let Some(targets) = self.engine.targets()
                        && let Ok(times) = self.engine.tracer().pass_times(&self.gpu, targets)
                    {
                        self.trace_ms = times.map(|t| t.trace_ms);
                    }
                }
                if !report.uploaded.is_empty() {
                    self.upload_ms = report.upload_host_ms + report.upload_record_ms;
                }
                if let Some((_, why)) = report.failures.last() {
                    self.message = Some(why.clone());
                }
                if self.log_frames {
                    for (position, why) in &report.failures {
                        let step = self.engine.bake_index(*position).unwrap_or(*position);
                        say(&format!("failed step {step}: {why}"));
                    }
                }
                self.last = report;
            }
            Err(e) => {
                if self.log_frames {
                    say(&format!("frame error: {e}"));
                }
                self.message = Some(e.to_string());
            }
        }
        self.track_field_range();
        self.show_texture(ui, rect);
        if self.screenshot_pending && self.last.progress.is_some_and(|p| p.finished()) {
            self.screenshot_pending = false;
            self.screenshot();
        }
    }

    /// Widens the series range by the shown step's field range.
    fn track_field_range(&mut self) {
        if let Some((_, step)) = self.engine.shown_step()
            && let Some((_, lo, hi)) = &step.field
        {
            self.series_range = Some(match self.series_range {
                Some((a, b)) => (a.min(*lo), b.max(*hi)),
                None => (*lo, *hi),
            });
        }
    }

    /// Why the step asked for failed, where it did.
    fn wanted_failure(&self) -> Option<String> {
        self.engine
            .failures()
            .into_iter()
            .find(|(p, _)| *p == self.last.wanted)
            .map(|(_, why)| why)
    }

    fn show_texture(&mut self, ui: &mut egui::Ui, rect: egui::Rect) {
        let Some(targets) = self.engine.targets() else {
            let failures = self.engine.failures();
            let text = if self.engine.timeline().is_empty() {
                "waiting for the first step file…".to_string()
            } else if failures.len() == self.engine.timeline().len() {
                format!(
                    "none of the {} step files can be shown; the first: {}",
                    failures.len(),
                    failures.first().map_or("", |(_, why)| why.as_str())
                )
            } else if let Some(why) = self.wanted_failure() {
                format!("this step failed: {why}")
            } else {
                "loading…".to_string()
            };
            ui.painter().text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                text,
                egui::FontId::proportional(18.0),
                ui.visuals().text_color(),
            );
            return;
        };
        let size = targets.size();
        let view = targets
            .texture()
            .create_view(&wgpu::TextureViewDescriptor::default());
        let mut renderer = self.render_state.renderer.write();
        let id = match self.texture {
            Some((id, registered)) if registered == size => id,
            Some((id, _)) => {
                renderer.update_egui_texture_from_wgpu_texture(
                    &self.render_state.device,
                    &view,
                    wgpu::FilterMode::Linear,
                    id,
                );
                id
            }
            None => renderer.register_native_texture(
                &self.render_state.device,
                &view,
                wgpu::FilterMode::Linear,
            ),
        };
        drop(renderer);
        self.texture = Some((id, size));
        ui.painter().image(
            id,
            rect,
            egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
            egui::Color32::WHITE,
        );
        if self.last.stand_in
            && let Some(shown) = self.last.shown
        {
            let index = |p: usize| self.engine.bake_index(p).unwrap_or(p);
            let wanted = index(self.last.wanted);
            let text = match self.wanted_failure() {
                Some(why) => format!("step {wanted} failed: {why}; showing step {}", index(shown)),
                None => format!("showing step {} while step {wanted} loads", index(shown)),
            };
            ui.painter().text(
                rect.left_top() + egui::vec2(10.0, 10.0),
                egui::Align2::LEFT_TOP,
                text,
                egui::FontId::proportional(14.0),
                egui::Color32::from_rgb(240, 200, 80),
            );
        }
    }

    fn controls(&mut self, ui: &mut egui::Ui) {
        ui.heading("View");
        ui.horizontal(|ui| {
            for (mode, name) in [
                (ShadeMode::Shade, "shade"),
                (ShadeMode::Normals, "normals"),
                (ShadeMode::Status, "status"),
                (ShadeMode::Water, "water"),
            ] {
                ui.selectable_value(&mut self.mode, mode, name);
            }
        });
        ui.add(egui::Slider::new(&mut self.iterations, 1..=8).text("iterations when still"));
        ui.add(egui::Slider::new(&mut self.render_scale, 0.25..=2.0).text("render scale"));
        let before = self.up_axis;
        ui.horizontal(|ui| {
            ui.label("up");
            for (axis, name) in ["x", "y", "z"].iter().enumerate() {
                ui.selectable_value(&mut self.up_axis, axis, *name);
            }
        });
        ui.add(egui::Slider::new(&mut self.light.0, -180.0..=180.0).text("light azimuth °"));
        ui.add(egui::Slider::new(&mut self.light.1, -10.0..=90.0).text("light elevation °"));
        if ui.small_button("default light").clicked() {
            self.light = default_light();
        }
        if before != self.up_axis || ui.button("reset view").clicked() {
            self.home = OrbitCamera::framing(&self.bounds, 40.0, axis_vector(self.up_axis));
            self.camera = self.home;
        }
        ui.separator();
        ui.heading("Colour");
        let mut choice = self.field_choice.clone();
        egui::ComboBox::from_label("field")
            .selected_text(choice.as_deref().unwrap_or("none"))
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut choice, None, "none");
                for f in &self.fields {
                    ui.selectable_value(&mut choice, Some(f.clone()), f);
                }
            });
        if choice != self.field_choice {
            self.engine.set_field(choice.clone());
            self.field_choice = choice;
            self.series_range = None;
        }
        if self.field_choice.is_some() {
            ui.horizontal(|ui| {
                let mut mode = self.range_mode;
                ui.selectable_value(&mut mode, RangeMode::Series, "series");
                ui.selectable_value(&mut mode, RangeMode::Step, "step");
                let fixed = match mode {
                    RangeMode::Fixed(..) => mode,
                    _ => {
                        let (lo, hi) = self.series_range.unwrap_or((0.0, 1.0));
                        RangeMode::Fixed(lo, hi)
                    }
                };
                ui.selectable_value(&mut mode, fixed, "fixed");
                self.range_mode = mode;
            });
            if let RangeMode::Fixed(mut lo, mut hi) = self.range_mode {
                ui.horizontal(|ui| {
                    ui.add(egui::DragValue::new(&mut lo).speed(0.01).prefix("min "));
                    ui.add(egui::DragValue::new(&mut hi).speed(0.01).prefix("max "));
                });
                self.range_mode = RangeMode::Fixed(lo, hi);
            }
            self.legend(ui);
        }
        ui.separator();
        ui.heading("Output");
        if ui
            .button("screenshot (F12)")
            .on_hover_text("PNG of the viewport at full resolution")
            .clicked()
        {
            self.screenshot();
        }
        self.follow_series_in_export_range();
        let steps = self.engine.series().steps();
        let (first, last) = (
            steps.first().map_or(0, |s| s.index),
            steps.last().map_or(0, |s| s.index),
        );
        ui.horizontal(|ui| {
            ui.label("steps");
            ui.add(egui::DragValue::new(&mut self.export_first).range(first..=last));
            ui.label("–");
            ui.add(egui::DragValue::new(&mut self.export_last).range(first..=last));
        });
        ui.horizontal(|ui| {
            ui.add(egui::DragValue::new(&mut self.export_size.0).range(16..=8192));
            ui.label("×");
            ui.add(egui::DragValue::new(&mut self.export_size.1).range(16..=8192));
            ui.add(
                egui::DragValue::new(&mut self.export_iterations)
                    .range(1..=8)
                    .suffix(" it"),
            );
        });
        match &self.export {
            Some(e) => {
                ui.label(format!("exporting {}/{}…", e.done, e.total));
            }
            None => {
                if ui.button("export frames").clicked() {
                    self.start_export();
                }
            }
        }
    }

    /// The colour map with the range it spans.
    fn legend(&self, ui: &mut egui::Ui) {
        let (rect, _) =
            ui.allocate_exact_size(egui::vec2(ui.available_width(), 14.0), egui::Sense::hover());
        let steps = 64;
        for k in 0..steps {
            let t = k as f32 / (steps - 1) as f32;
            // The shade pass encodes the map's values to sRGB; so does egui's `Rgba`.
            let [r, g, b] = colormap::viridis(t);
            let colour: egui::Color32 = egui::Rgba::from_rgb(r, g, b).into();
            let x0 = rect.left() + rect.width() * k as f32 / steps as f32;
            let x1 = rect.left() + rect.width() * (k + 1) as f32 / steps as f32;
            ui.painter().rect_filled(
                egui::Rect::from_min_max(egui::pos2(x0, rect.top()), egui::pos2(x1, rect.bottom())),
                0.0,
                colour,
            );
        }
        let range = match self.range_mode {
            RangeMode::Fixed(lo, hi) => Some((lo, hi)),
            RangeMode::Series => self.series_range,
            RangeMode::Step => self
                .engine
                .shown_step()
                .and_then(|(_, s)| s.field.as_ref().map(|f| (f.1, f.2))),
        };
        if let Some((lo, hi)) = range {
            ui.horizontal(|ui| {
                ui.monospace(format!("{lo:.4e}"));
                ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                    ui.monospace(format!("{hi:.4e}"));
                });
            });
        }
    }

    fn screenshot(&mut self) {
        let Some(targets) = self.engine.targets() else {
            self.message = Some("nothing to save yet".into());
            return;
        };
        let position = self.last.shown.unwrap_or(self.last.wanted);
        let step = self.engine.bake_index(position).unwrap_or(position);
        let path = self.output.join(format!("slosh-step-{step:05}.png"));
        let saved = self
            .engine
            .tracer()
            .read_frame(&self.gpu, targets)
            .and_then(|frame| slosh_render::write_frame_png(&path, &frame));
        let (w, h) = targets.size();
        let c = self.camera.camera(w, h);
        let v = |a: [f64; 3]| format!("{},{},{}", a[0], a[1], a[2]);
        self.message = Some(match saved {
            Ok(()) => {
                // The camera, as `slosh render` takes it, so the frame can be made again.
                let r = self.viewport_px;
                say(&format!(
                    "screenshot {} ({w}x{h}, viewport at {},{} in the window): step {step} --size {w}x{h} --eye {} --target {} --up {} --fov {} --iterations {}",
                    path.display(),
                    r.min.x.round(),
                    r.min.y.round(),
                    v(c.eye),
                    v(c.target),
                    v(c.up),
                    c.fov_y,
                    self.last.progress.map_or(1, |p| p.done)
                ));
                format!("saved {}", path.display())
            }
            Err(e) => format!("screenshot failed: {e}"),
        });
    }

    /// A range that ended at the series' last step grows with the series (a bake adding
    /// steps), and every range stays within the series.
    fn follow_series_in_export_range(&mut self) {
        let steps = self.engine.series().steps();
        let (Some(first), Some(last)) = (steps.first(), steps.last()) else {
            return;
        };
        (self.export_first, self.export_last) = follow_series(
            (self.export_first, self.export_last),
            self.export_seen_last,
            (first.index, last.index),
        );
        self.export_seen_last = last.index;
    }

    fn start_export(&mut self) {
        let (first, last) = (
            self.export_first.min(self.export_last),
            self.export_first.max(self.export_last),
        );
        let steps: Vec<(usize, PathBuf)> = self
            .engine
            .series()
            .steps()
            .iter()
            .filter(|s| (first..=last).contains(&s.index) && s.problem.is_none())
            .map(|s| (s.index, s.path.clone()))
            .collect();
        let (tx, rx) = channel();
        let gpu = self.gpu.clone();
        let camera = self.camera.camera(self.export_size.0, self.export_size.1);
        let mut params = self.params();
        params.iterations = self.export_iterations;
        let field = self.field_choice.clone();
        let dir = self.output.join("frames");
        let total = steps.len();
        if total == 0 {
            self.message = Some(format!("export: no readable step in {first}..={last}"));
            return;
        }
        std::thread::spawn(move || {
            let tracer = match Tracer::new(&gpu) {
                Ok(t) => t,
                Err(e) => {
                    let _ = tx.send(Err(e.to_string()));
                    return;
                }
            };
            if let Err(e) = std::fs::create_dir_all(&dir) {
                let _ = tx.send(Err(format!("{}: {e}", dir.display())));
                return;
            }
            for (i, path) in steps {
                let out = dir.join(format!("{i:05}.png"));
                let frame = CacheFile::open(&path)
                    .map_err(slosh_render::Error::from)
                    .and_then(|f| GpuStep::upload(&gpu, &f, field.as_deref()))
                    .and_then(|step| tracer.render(&gpu, &step, &camera, &params))
                    .and_then(|frame| slosh_render::write_frame_png(&out, &frame));
                let sent = tx.send(frame.map(|()| (i, out)).map_err(|e| e.to_string()));
                if sent.is_err() {
                    return;
                }
            }
        });
        self.export = Some(Export {
            progress: rx,
            done: 0,
            total,
        });
    }

    fn poll_export(&mut self) {
        let Some(export) = &mut self.export else {
            return;
        };
        let mut finished = false;
        loop {
            match export.progress.try_recv() {
                Ok(Ok((_, path))) => {
                    export.done += 1;
                    if export.done == export.total {
                        self.message = Some(format!(
                            "exported {} frames to {}",
                            export.total,
                            path.parent()
                                .map_or(path.clone(), |p| p.to_path_buf())
                                .display()
                        ));
                        finished = true;
                    }
                }
                Ok(Err(why)) => {
                    self.message = Some(format!("export: {why}"));
                    finished = true;
                    break;
                }
                Err(std::sync::mpsc::TryRecvError::Empty) => break,
                Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                    finished = true;
                    break;
                }
            }
        }
        if finished {
            self.export = None;
        }
    }

    fn status_bar(&self, ui: &mut egui::Ui) {
        let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
        let progress = self.last.progress.map_or(String::new(), |p| {
            format!(" · refined {}/{}", p.done, p.target)
        });
        let index = |p: usize| self.engine.bake_index(p).unwrap_or(p);
        let shown = match (self.last.shown, self.last.stand_in) {
            (Some(s), true) => format!(
                " · showing step {} for {}",
                index(s),
                index(self.last.wanted)
            ),
            (Some(s), false) => format!(" · step {}", index(s)),
            (None, _) => " · nothing resident yet".into(),
        };
        // Two lines of fixed height, truncated: the viewport's size never depends on what
        // the status says.
        let stats = format!(
            "frame {:.1} ms · trace {} · upload {:.1} ms · {} / {} steps resident · {:.2} / {:.2} GiB{progress}{shown} · {} frames",
            self.frame_ms,
            self.trace_ms.map_or("–".into(), |t| format!("{t:.2} ms")),
            self.upload_ms,
            self.engine.resident().len(),
            self.engine.timeline().len(),
            gib(self.engine.used_bytes()),
            gib(self.engine.budget()),
            self.frames,
        );
        ui.add(egui::Label::new(egui::RichText::new(stats).monospace()).truncate());
        let message = self.message.as_deref().unwrap_or(" ");
        ui.add(
            egui::Label::new(egui::RichText::new(message).color(ui.visuals().warn_fg_color))
                .truncate(),
        );
    }
}

impl eframe::App for Player {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.keys(&ctx);
        self.poll_export();
        // A bake may still be adding steps.
        if self.last_refresh.elapsed().as_secs_f64() > 1.0 {
            self.last_refresh = Instant::now();
            match self.engine.refresh_series() {
                Ok(true) => {
                    if self.fields.is_empty() {
                        self.fields = baked_fields(&self.engine);
                    }
                    if self.engine.series().len() == 1 || self.bounds == [[-1.0; 3], [1.0; 3]] {
                        self.bounds = series_bounds(&self.engine);
                        self.home =
                            OrbitCamera::framing(&self.bounds, 40.0, axis_vector(self.up_axis));
                        self.camera = self.home;
                    }
                }
                Ok(false) => {}
                Err(e) => self.message = Some(e.to_string()),
            }
        }
        egui::Panel::bottom("status").show(ui, |ui| self.status_bar(ui));
        egui::Panel::bottom("timeline").show(ui, |ui| {
            timeline_panel::show(ui, &mut self.engine);
        });
        egui::Panel::right("controls")
            .default_size(260.0)
            .show(ui, |ui| self.controls(ui));
        egui::CentralPanel::no_frame().show(ui, |ui| self.viewport(ui));
        self.passes += 1;
        if self.log_frames {
            say(&format!(
                "pass {}: wanted {} shown {:?}{}{} export {}..={}",
                self.passes,
                self.last.wanted,
                self.last.shown,
                if self.last.stand_in { " stand-in" } else { "" },
                self.last
                    .drawn
                    .map_or(String::new(), |n| format!(" drew {n}")),
                self.export_first,
                self.export_last
            ));
        }
        // The title names the step on screen (a stand-in's own number while another loads),
        // by its bake index, as `slosh render --step` does.
        let title = match self.last.shown {
            Some(shown) => {
                let time = self
                    .engine
                    .timeline()
                    .times()
                    .get(shown)
                    .copied()
                    .unwrap_or(0.0);
                let index = |p: usize| self.engine.bake_index(p).unwrap_or(p);
                format!(
                    "slosh — step {}/{}, t = {time:.3}",
                    index(shown),
                    index(self.engine.timeline().len().saturating_sub(1))
                )
            }
            None => format!("slosh — loading {}", self.engine.series().dir().display()),
        };
        if title != self.title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.title = title;
        }
        // Keep drawing while something changes: playback, loads, refinement, exports. At
        // rest, one pass a second looks for steps a bake adds.
        let waiting_for_load = (self.last.stand_in || self.last.shown.is_none())
            && self.wanted_failure().is_none()
            && !self.engine.prefetching().is_empty();
        let busy = self.engine.timeline().is_playing()
            || waiting_for_load
            || self.last.progress.is_some_and(|p| !p.finished())
            || self.screenshot_pending
            || self.export.is_some();
        if busy {
            ctx.request_repaint();
        } else {
            ctx.request_repaint_after(std::time::Duration::from_millis(1000));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{fit_texture, follow_series};

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

    /// A viewport larger than the device's largest texture renders at the largest size that
    /// fits, keeping its aspect, instead of failing validation (issue 25, item 6).
    #[test]
    fn frames_fit_the_largest_texture_keeping_their_aspect() {
        let any = u64::MAX;
        assert_eq!(fit_texture(1600.0, 1000.0, 8192, any), (1600, 1000));
        assert_eq!(fit_texture(9000.0, 1000.0, 8192, any), (8192, 910));
        // Within the pixels allowed, however the sides round.
        let (w, h) = fit_texture(5730.0, 5856.0, 16384, 8_388_608);
        assert!(u64::from(w) * u64::from(h) <= 8_388_608, "{w}x{h}");
        assert_eq!(fit_texture(5000.0, 5000.0, 16384, any), (5000, 5000));
        // 16000² is past an 8K display's pixels: traced at 5760² and stretched.
        assert_eq!(fit_texture(16000.0, 16000.0, 16384, any), (5760, 5760));
        // A device that binds fewer pixels for a frame (lavapipe: 8M): fewer.
        assert_eq!(
            fit_texture(16000.0, 16000.0, 16384, 4_000_000),
            (2000, 2000)
        );
        assert_eq!(fit_texture(0.0, 0.0, 8192, any), (1, 1));
    }
}
