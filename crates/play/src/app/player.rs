//! The player window: the traced viewport, the timeline, the controls and the status bar,
//! over one [`Engine`]. Widgets read and change the engine's state; they hold none of their
//! own beyond what is being edited.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use eframe::egui;
use slosh_fileio::say;
use slosh_render::Gpu;

use super::camera::OrbitCamera;
use super::export_panel::ExportPanel;
use super::fit::fit_texture;
use super::frame_stats::FrameStats;
use super::options::PlayOptions;
use super::timeline_panel;
use super::view::{ViewSettings, axis_vector, default_light};
use crate::engine::{Engine, FrameReport, FrameRequest, Probe};
use crate::refine::Draw;
use slosh_mls::dominant_axis;

/// The controls panel's width and the height of the timeline and status bars, in points:
/// what the viewport leaves of the window.
const CONTROLS_WIDTH: f32 = 260.0;
const BARS_HEIGHT: f32 = 80.0;

/// Framed before the series has a step with particles.
const NO_BOUNDS: [[f64; 3]; 2] = [[-1.0; 3], [1.0; 3]];

pub(super) struct Player {
    engine: Engine,
    gpu: Arc<Gpu>,
    render_state: eframe::egui_wgpu::RenderState,
    camera: OrbitCamera,
    home: OrbitCamera,
    view: ViewSettings,
    /// The series' baked fields and its bounds, from the series.
    fields: Vec<String>,
    bounds: [[f64; 3]; 2],
    /// The registered texture and the size it was registered at.
    texture: Option<(egui::TextureId, (u32, u32))>,
    stats: FrameStats,
    last: FrameReport,
    message: Option<String>,
    last_refresh: Instant,
    output: PathBuf,
    export: ExportPanel,
    /// F12 was pressed: save the next drawn frame.
    screenshot_pending: bool,
    log_frames: bool,
    /// The viewport in physical pixels within the window.
    viewport_px: egui::Rect,
    /// The window title last set (set again only when it changes: setting it asks for
    /// another pass).
    title: String,
    /// What the surface holds under the pointer, and the pixel and frame count it was read
    /// at.
    probe: Option<(Probe, (u32, u32), u64)>,
    /// A click whose probe waits for the step's surface to be prepared: said once read.
    click_pending: bool,
}

impl Player {
    pub(super) fn new(
        engine: Engine,
        gpu: Arc<Gpu>,
        render_state: eframe::egui_wgpu::RenderState,
        options: PlayOptions,
    ) -> Player {
        // Up from the command line, else from the data, else z.
        let up = options
            .up
            .or_else(|| engine.series().up())
            .unwrap_or([0.0, 0.0, 1.0]);
        let up_axis = dominant_axis(up);
        let bounds = engine.series().bounds().unwrap_or(NO_BOUNDS);
        // The viewport: the window less the controls and the timeline and status bars.
        let viewport = (
            (options.window.0 - CONTROLS_WIDTH).max(1.0) as u32,
            (options.window.1 - BARS_HEIGHT).max(1.0) as u32,
        );
        let camera = OrbitCamera::framing(&bounds, 40.0, axis_vector(up_axis), viewport);
        let view = ViewSettings {
            mode: options.mode,
            iterations: options.iterations.max(1),
            render_scale: options.render_scale.clamp(0.25, 2.0),
            frame_budget_ms: options.frame_budget_ms,
            up_axis,
            light: default_light(),
            field: engine.field().map(str::to_string),
            range_mode: options.range_mode,
            colormap: options.colormap,
            series_range: None,
        };
        Player {
            gpu,
            render_state,
            camera,
            home: camera,
            view,
            fields: engine.series().fields(),
            bounds,
            texture: None,
            stats: if options.log_frames {
                FrameStats::with_queue_waits()
            } else {
                FrameStats::default()
            },
            last: FrameReport::default(),
            message: None,
            last_refresh: Instant::now(),
            output: options.output,
            export: ExportPanel::new(&engine),
            engine,
            screenshot_pending: false,
            viewport_px: egui::Rect::NOTHING,
            log_frames: options.log_frames,
            title: String::new(),
            probe: None,
            click_pending: false,
        }
    }

    /// Frames the data again about the chosen up axis.
    fn reframe(&mut self) {
        let r = self.viewport_px;
        let size = if r.is_positive() {
            (r.width() as u32, r.height() as u32)
        } else {
            (1, 1)
        };
        self.home = OrbitCamera::framing(&self.bounds, 40.0, axis_vector(self.view.up_axis), size);
        self.camera = self.home;
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
        let ppp = ui.ctx().pixels_per_point() * self.view.render_scale;
        let (width, height) = fit_texture(
            rect.width() * ppp,
            rect.height() * ppp,
            self.gpu.device.limits().max_texture_dimension_2d,
            self.engine.tracer().max_frame_pixels(&self.gpu),
        );
        let seconds = self.stats.begin_frame();
        let request = FrameRequest {
            seconds,
            camera: self.camera.camera(width, height),
            params: self.view.params(&self.engine),
            camera_moving: moving,
            frame_budget_ms: self.view.frame_budget_ms,
        };
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("player frame"),
            });
        match self.engine.frame(&request, &mut encoder) {
            Ok(report) => {
                self.gpu.queue.submit([encoder.finish()]);
                // Waits for the frame: what it cost paces the next ones.
                let trace_ms = match self.engine.finish_frame() {
                    Ok(ms) => ms.map(Some),
                    Err(e) => {
                        self.message = Some(e.to_string());
                        None
                    }
                };
                self.stats.record(&report, trace_ms);
                if let Some((_, why)) = report.failures.last() {
                    self.message = Some(why.clone());
                }
                if self.log_frames {
                    for (position, why) in &report.failures {
                        let step = self.engine.bake_index(*position).unwrap_or(*position);
                        say!("failed step {step}: {why}");
                    }
                }
                self.last = report;
            }
            Err(e) => {
                // The encoder is dropped unsubmitted: what the frame recorded before it
                // failed never runs, so the tracer must not take its tree or masks as held.
                self.engine.tracer().forget_held();
                if self.log_frames {
                    say!("frame error: {e}");
                }
                self.message = Some(e.to_string());
            }
        }
        self.view.track_field_range(&self.engine);
        self.show_texture(ui, rect);
        self.probe_pointer(ui, &response, rect, moving);
        if self.screenshot_pending && self.last.progress.is_some_and(|p| p.finished()) {
            self.screenshot_pending = false;
            self.screenshot();
        }
    }

    /// Reads the surface under the pointer back where it rests on a refined picture, or
    /// where it clicks, and labels it there.
    fn probe_pointer(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        rect: egui::Rect,
        moving: bool,
    ) {
        let (Some(pos), Some(size)) = (
            response.hover_pos(),
            self.engine.targets().map(|t| t.size()),
        ) else {
            self.probe = None;
            self.click_pending = false;
            return;
        };
        let clicked = response.clicked() || self.click_pending;
        let at_rest = !moving && self.last.progress.is_some_and(|p| p.finished());
        if !clicked && !at_rest {
            self.probe = None;
            return;
        }
        let u = ((pos.x - rect.min.x) / rect.width().max(1.0)).clamp(0.0, 1.0);
        let v = ((pos.y - rect.min.y) / rect.height().max(1.0)).clamp(0.0, 1.0);
        let pixel = (
            ((u * size.0 as f32) as u32).min(size.0 - 1),
            ((v * size.1 as f32) as u32).min(size.1 - 1),
        );
        let current = self
            .probe
            .as_ref()
            .is_some_and(|(_, at, frames)| *at == pixel && *frames == self.stats.frames);
        if clicked || !current {
            let h_factor = self.view.params(&self.engine).h_factor;
            let probed = self.engine.probe(pixel.0, pixel.1, h_factor);
            // Asked again in the next passes while the step's surface is prepared.
            self.click_pending =
                clicked && matches!(probed, Ok(None)) && self.engine.probe_preparing();
            match probed {
                Ok(Some(probe)) => {
                    if clicked {
                        let line = probe_line(&probe, pixel);
                        if self.log_frames {
                            say!("{line}");
                        }
                        self.message = Some(line);
                    }
                    self.probe = Some((probe, pixel, self.stats.frames));
                }
                Ok(None) => self.probe = None,
                Err(e) => {
                    self.probe = None;
                    self.message = Some(format!("reading the surface back failed: {e}"));
                }
            }
        }
        if let Some((probe, _, _)) = &self.probe {
            let text = probe_label(probe);
            let font = egui::FontId::monospace(12.0);
            let painter = ui.painter();
            let galley = painter.layout_no_wrap(text, font, egui::Color32::WHITE);
            let at = pos + egui::vec2(16.0, 16.0);
            let frame = egui::Rect::from_min_size(at, galley.size()).expand(4.0);
            painter.rect_filled(frame, 3.0, egui::Color32::from_black_alpha(190));
            painter.galley(at, galley, egui::Color32::WHITE);
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
        if self
            .view
            .controls(ui, &mut self.engine, &self.fields)
            .reframe
        {
            self.reframe();
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
        if self.export.ui(ui, &self.engine) {
            let (w, h) = self.export.size;
            let params = self.view.params(&self.engine);
            let camera = self.camera.camera(w, h);
            let gpu = self.gpu.clone();
            if let Some(why) = self
                .export
                .start(gpu, &self.engine, camera, params, &self.output)
            {
                self.message = Some(why);
            }
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
                say!(
                    "screenshot {} ({w}x{h}, viewport at {},{} in the window): step {step} --size {w}x{h} --eye {} --target {} --up {} --fov {} --iterations {}",
                    path.display(),
                    r.min.x.round(),
                    r.min.y.round(),
                    v(c.eye),
                    v(c.target),
                    v(c.up),
                    c.fov_y,
                    self.last.progress.map_or(1, |p| p.done)
                );
                format!("saved {}", path.display())
            }
            Err(e) => format!("screenshot failed: {e}"),
        });
    }

    fn status_bar(&self, ui: &mut egui::Ui) {
        let stats = self.stats.status_line(&self.engine, &self.last);
        ui.add(egui::Label::new(egui::RichText::new(stats).monospace()).truncate());
        let message = self.message.as_deref().unwrap_or(" ");
        ui.add(
            egui::Label::new(egui::RichText::new(message).color(ui.visuals().warn_fg_color))
                .truncate(),
        );
    }
}

impl eframe::App for Player {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let pass_start = Instant::now();
        self.stats.previous_cpu_ms = frame.info().cpu_usage.map(|s| f64::from(s) * 1e3);
        let ctx = ui.ctx().clone();
        self.keys(&ctx);
        if let Some(message) = self.export.poll() {
            self.message = Some(message);
        }
        // A bake may still be adding steps.
        if self.last_refresh.elapsed().as_secs_f64() > 1.0 {
            self.last_refresh = Instant::now();
            match self.engine.refresh_series() {
                Ok(true) => {
                    if self.fields.is_empty() {
                        self.fields = self.engine.series().fields();
                    }
                    if self.engine.series().len() == 1 || self.bounds == NO_BOUNDS {
                        self.bounds = self.engine.series().bounds().unwrap_or(NO_BOUNDS);
                        self.reframe();
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
            .default_size(CONTROLS_WIDTH)
            .show(ui, |ui| self.controls(ui));
        egui::CentralPanel::no_frame().show(ui, |ui| self.viewport(ui));
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
            || self.export.running()
            || self.engine.probe_preparing();
        self.stats.passes += 1;
        if self.log_frames {
            // The pass's interval since the last one (what delays an input event while the
            // player is busy), the time spent in this pass's own work, how much of the
            // interval the UI thread waited, runnable, for a core, and the CPU time of the
            // frame before (its pass and eframe's paint, without the waits for the surface and
            // the present).
            let band = match (&self.last.draw, self.last.masks) {
                (
                    Some(Draw::Rows {
                        rows, done, height, ..
                    }),
                    _,
                ) => format!(" rows {}+{}k ({done} of {height})", rows.first, rows.stride),
                (None, Some(m)) => format!(" masks {}/{}", m.derived, m.total),
                (Some(Draw::Preview), _) => self
                    .last
                    .quality
                    .map_or(String::new(), |q| format!(" preview {}", q.scale)),
                _ => String::new(),
            };
            say!(
                "pass {}: wanted {} shown {:?}{}{}{band} ms {:.1}/{:.1}/{}/{} {} export {}..={}",
                self.stats.passes,
                self.last.wanted,
                self.last.shown,
                if self.last.stand_in { " stand-in" } else { "" },
                self.last
                    .drawn
                    .map_or(String::new(), |n| format!(" drew {n}")),
                self.stats.frame_ms,
                pass_start.elapsed().as_secs_f64() * 1e3,
                self.stats
                    .queued_ms
                    .map_or("-".into(), |q| format!("{q:.1}")),
                self.stats
                    .previous_cpu_ms
                    .map_or("-".into(), |c| format!("{c:.1}")),
                if busy { "busy" } else { "idle" },
                self.export.first,
                self.export.last
            );
        }
        if busy {
            ctx.request_repaint();
        } else {
            ctx.request_repaint_after(std::time::Duration::from_millis(1000));
        }
    }
}

/// The label beside the pointer: position, the field's value, the nearest particle.
fn probe_label(probe: &Probe) -> String {
    let r = &probe.reading;
    let [x, y, z] = r.world;
    let mut text = format!("x {x:.5}  y {y:.5}  z {z:.5}");
    match (&probe.field, r.field) {
        (Some(name), Some(value)) => text += &format!("\n{name} {value:.5e}"),
        (Some(name), None) => text += &format!("\n{name}: no finite value here"),
        _ => {}
    }
    text += &match &probe.input {
        Ok((input, _)) => format!("\nparticle {input} at {:.3e}", r.nearest_distance),
        Err(why) => format!(
            "\nparticle {} of the cache at {:.3e}\n(its index in the case: {why})",
            r.nearest, r.nearest_distance
        ),
    };
    if probe.status == slosh_render::status::DROPLET {
        text += "\n(a droplet)";
    }
    text
}

/// The probe said in one line (the message line and the frame log).
fn probe_line(probe: &Probe, pixel: (u32, u32)) -> String {
    let r = &probe.reading;
    let [x, y, z] = r.world;
    let field = match (&probe.field, r.field) {
        (Some(name), Some(value)) => format!(" {name} {value:e}"),
        (Some(name), None) => format!(" {name} none"),
        _ => String::new(),
    };
    let input = match &probe.input {
        Ok((i, [a, b, c])) => format!("{i} ({a},{b},{c})"),
        Err(why) => format!("unknown ({why})"),
    };
    format!(
        "probe step {} pixel {},{}: position {x},{y},{z}{field} nearest cache {} at {:e} input {input} status {}",
        probe.step, pixel.0, pixel.1, r.nearest, r.nearest_distance, probe.status
    )
}
