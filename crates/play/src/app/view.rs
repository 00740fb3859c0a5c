//! How the player shows the surface: shading, refinement, scale, up axis, light and the
//! colour field with its range, and the panel that edits them.

use eframe::egui;
use slosh_render::{Colormap, ShadeMode, TraceParams};

use crate::RangeMode;
use crate::engine::Engine;

/// The view's settings, as the controls edit them.
#[derive(Debug, Clone)]
pub struct ViewSettings {
    pub mode: ShadeMode,
    /// Iterations refined to once the view is still.
    pub iterations: u32,
    /// Viewport pixels traced per physical pixel, per axis.
    pub render_scale: f32,
    /// Milliseconds a frame may take on the GPU; `None`: every frame whole at full size.
    pub frame_budget_ms: Option<f64>,
    pub up_axis: usize,
    /// The key light's azimuth and elevation about the up axis, in degrees.
    pub light: (f32, f32),
    pub field: Option<String>,
    pub range_mode: RangeMode,
    pub colormap: Colormap,
    /// The widest field range of the steps shown since the field was chosen.
    pub series_range: Option<(f32, f32)>,
}

/// What the view panel asks of the player after a pass.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ViewChange {
    /// The up axis changed or "reset view" was pressed: frame the data again.
    pub reframe: bool,
}

/// Azimuth and elevation (degrees) of the default key light about z.
pub fn default_light() -> (f32, f32) {
    let [x, y, z] = slosh_render::DEFAULT_KEY_LIGHT;
    (
        y.atan2(x).to_degrees(),
        z.clamp(-1.0, 1.0).asin().to_degrees(),
    )
}

/// The unit vector along `axis`.
pub fn axis_vector(axis: usize) -> [f64; 3] {
    std::array::from_fn(|a| if a == axis { 1.0 } else { 0.0 })
}

impl ViewSettings {
    /// The key light's direction: azimuth and elevation about the chosen up axis (for z up,
    /// the default is `DEFAULT_KEY_LIGHT`).
    pub fn key_light(&self) -> [f32; 3] {
        // The default itself, not its round trip through degrees: f32 trigonometry moves it
        // by an ulp, enough to change a pixel against `slosh render`'s.
        if self.up_axis == 2 && self.light == default_light() {
            return slosh_render::DEFAULT_KEY_LIGHT;
        }
        let (az, el) = (self.light.0.to_radians(), self.light.1.to_radians());
        let mut d = [0.0f32; 3];
        d[(self.up_axis + 1) % 3] = el.cos() * az.cos();
        d[(self.up_axis + 2) % 3] = el.cos() * az.sin();
        d[self.up_axis] = el.sin();
        d
    }

    /// Trace settings for the step on screen (its baked degree and normals, or the defaults
    /// before any).
    pub fn params(&self, engine: &Engine) -> TraceParams {
        let (degree, covariance) = engine
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
            colormap: self.colormap,
            key_light: self.key_light(),
        }
    }

    /// The series range: the manifest's for the field, where it records one, widened by the
    /// shown step's field range (a bake still running, a cache of format 9.0).
    pub fn track_field_range(&mut self, engine: &Engine) {
        if self.series_range.is_none() {
            self.series_range = self
                .field
                .as_deref()
                .and_then(|f| engine.series().field_range(f));
        }
        // A step whose every value is missing leaves it as it was.
        if let Some((_, step)) = engine.shown_step()
            && let Some((lo, hi)) = step.field_range()
        {
            self.series_range = Some(match self.series_range {
                Some((a, b)) => (a.min(lo), b.max(hi)),
                None => (lo, hi),
            });
        }
    }

    /// The View and Colour sections of the controls; a new field is set on `engine`.
    pub fn controls(
        &mut self,
        ui: &mut egui::Ui,
        engine: &mut Engine,
        fields: &[String],
    ) -> ViewChange {
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
        let mut paced = self.frame_budget_ms.is_some();
        let mut ms = self.frame_budget_ms.unwrap_or(33.0);
        ui.horizontal(|ui| {
            ui.checkbox(&mut paced, "frame budget")
                .on_hover_text("while the view moves, draw it smaller; refine a still view in bands, so the window stays responsive on a slow GPU");
            ui.add_enabled(paced, egui::Slider::new(&mut ms, 8.0..=200.0).suffix(" ms"));
        });
        self.frame_budget_ms = paced.then_some(ms);
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
        let change = ViewChange {
            reframe: before != self.up_axis || ui.button("reset view").clicked(),
        };
        ui.separator();
        ui.heading("Colour");
        let mut choice = self.field.clone();
        egui::ComboBox::from_label("field")
            .selected_text(choice.as_deref().unwrap_or("none"))
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut choice, None, "none");
                for f in fields {
                    ui.selectable_value(&mut choice, Some(f.clone()), f);
                }
            });
        if choice != self.field {
            engine.set_field(choice.clone());
            self.field = choice;
            self.series_range = None;
        }
        if self.field.is_some() {
            egui::ComboBox::from_label("colour map")
                .selected_text(self.colormap.name())
                .show_ui(ui, |ui| {
                    for m in Colormap::ALL {
                        ui.selectable_value(&mut self.colormap, m, m.name());
                    }
                });
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
            self.legend(ui, engine);
        }
        change
    }

    /// The colour map with the range it spans.
    fn legend(&self, ui: &mut egui::Ui, engine: &Engine) {
        let (rect, _) =
            ui.allocate_exact_size(egui::vec2(ui.available_width(), 14.0), egui::Sense::hover());
        let steps = 64;
        for k in 0..steps {
            let t = k as f32 / (steps - 1) as f32;
            // The shade pass encodes the map's values to sRGB; so does egui's `Rgba`.
            let [r, g, b] = self.colormap.at(t);
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
            // A step whose every value is missing has none (the line below says so).
            RangeMode::Step => engine.shown_step().and_then(|(_, s)| s.field_range()),
        };
        if let Some((lo, hi)) = range {
            ui.horizontal(|ui| {
                ui.monospace(format!("{lo:.4e}"));
                ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                    ui.monospace(format!("{hi:.4e}"));
                });
            });
        }
        // Values that are not finite: left out of the colour; a hit that finds none is
        // drawn in the missing colour.
        if let Some((_, step)) = engine.shown_step().filter(|(_, s)| s.field_missing > 0) {
            let [r, g, b] = slosh_render::MISSING_FIELD_COLOUR;
            let colour: egui::Color32 = egui::Rgba::from_rgb(r, g, b).into();
            ui.colored_label(
                colour,
                format!(
                    "{} of {} points have no finite value",
                    step.field_missing, step.info.point_count
                ),
            );
        }
    }
}
