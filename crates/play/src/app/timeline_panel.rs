//! The timeline widget: transport buttons, loop and speed, and a scrub bar that shows which
//! steps are resident on the GPU, which are being loaded and which failed, and of a raw
//! case which are baked. It holds no state:
//! everything it shows and changes lives in the engine's `Timeline`.

use eframe::egui;

use crate::engine::Engine;
use crate::timeline::Looping;

const RESIDENT: egui::Color32 = egui::Color32::from_rgb(70, 170, 90);
const LOADING: egui::Color32 = egui::Color32::from_rgb(220, 170, 40);
const FAILED: egui::Color32 = egui::Color32::from_rgb(220, 60, 50);
const BAKED: egui::Color32 = egui::Color32::from_rgb(90, 120, 170);

/// Draws the timeline for `engine`.
pub fn show(ui: &mut egui::Ui, engine: &mut Engine) {
    let len = engine.timeline().len();
    ui.horizontal(|ui| {
        let t = engine.timeline_mut();
        if ui.button("|<").on_hover_text("first step (Home)").clicked() {
            t.home();
        }
        if ui.button("-10").on_hover_text("Shift+←").clicked() {
            t.step_by(-10);
        }
        if ui.button("<").on_hover_text("previous step (←)").clicked() {
            t.step_by(-1);
        }
        let play = if t.is_playing() { "pause" } else { "play" };
        if ui
            .button(play)
            .on_hover_text("play or pause (Space)")
            .clicked()
        {
            t.toggle_play();
        }
        if ui.button(">").on_hover_text("next step (→)").clicked() {
            t.step_by(1);
        }
        if ui.button("+10").on_hover_text("Shift+→").clicked() {
            t.step_by(10);
        }
        if ui.button(">|").on_hover_text("last step (End)").clicked() {
            t.end();
        }
        ui.separator();
        let mut looping = t.looping();
        let name = |l: &Looping| match l {
            Looping::Off => "loop off",
            Looping::All => "loop all",
            Looping::Range { .. } => "loop range",
        };
        egui::ComboBox::from_id_salt("loop")
            .selected_text(name(&looping))
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut looping, Looping::Off, "loop off");
                ui.selectable_value(&mut looping, Looping::All, "loop all");
                let range = match looping {
                    Looping::Range { .. } => looping,
                    _ => Looping::Range {
                        first: t.current(),
                        last: (t.current() + 50).min(len.saturating_sub(1)),
                    },
                };
                ui.selectable_value(&mut looping, range, "loop range");
            });
        if let Looping::Range {
            mut first,
            mut last,
        } = looping
        {
            ui.add(egui::DragValue::new(&mut first).range(0..=len.saturating_sub(1)));
            ui.label("–");
            ui.add(egui::DragValue::new(&mut last).range(0..=len.saturating_sub(1)));
            looping = Looping::Range { first, last };
        }
        if looping != t.looping() {
            t.set_looping(looping);
        }
        ui.separator();
        let mut speed = t.speed();
        ui.add(
            egui::DragValue::new(&mut speed)
                .range(0.1..=crate::timeline::MAX_SPEED)
                .speed(0.5)
                .suffix(" steps/s"),
        );
        if speed != t.speed() {
            t.set_speed(speed);
        }
        ui.separator();
        let (current, time) = (t.current(), t.time());
        let index = |p: usize| engine.bake_index(p).unwrap_or(p);
        ui.monospace(format!(
            "step {}/{}   t = {time:.4}",
            index(current),
            index(len.saturating_sub(1)),
        ));
    });
    scrub_bar(ui, engine);
}

/// The scrub bar: a click or drag sets the current step.
fn scrub_bar(ui: &mut egui::Ui, engine: &mut Engine) {
    let len = engine.timeline().len();
    let width = ui.available_width();
    let (rect, response) =
        ui.allocate_exact_size(egui::vec2(width, 26.0), egui::Sense::click_and_drag());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 3.0, ui.visuals().extreme_bg_color);
    if len == 0 {
        painter.text(
            rect.center(),
            egui::Align2::CENTER_CENTER,
            "no steps yet",
            egui::FontId::proportional(13.0),
            ui.visuals().weak_text_color(),
        );
        return;
    }
    let x_of = |i: usize| rect.left() + (i as f32 + 0.5) / len as f32 * rect.width();
    let tick = (rect.width() / len as f32).max(1.0);
    let band = |painter: &egui::Painter, i: usize, top: f32, bottom: f32, colour| {
        let x = x_of(i);
        painter.rect_filled(
            egui::Rect::from_min_max(
                egui::pos2(x - tick * 0.5, rect.top() + top),
                egui::pos2(x + tick * 0.5, rect.top() + bottom),
            ),
            0.0,
            colour,
        );
    };
    if engine.series().is_planned() {
        for i in engine.baked() {
            band(&painter, i, 10.0, 16.0, BAKED);
        }
    }
    for i in engine.resident() {
        band(&painter, i, 16.0, 26.0, RESIDENT);
    }
    for i in engine.prefetching() {
        band(&painter, i, 16.0, 26.0, LOADING);
    }
    for (i, _) in engine.failures() {
        band(&painter, i, 0.0, 26.0, FAILED);
    }
    if let Looping::Range { first, last } = engine.timeline().looping() {
        let span = egui::Rect::from_min_max(
            egui::pos2(x_of(first) - tick * 0.5, rect.top()),
            egui::pos2(x_of(last) + tick * 0.5, rect.top() + 4.0),
        );
        painter.rect_filled(span, 0.0, ui.visuals().selection.bg_fill);
    }
    let x = x_of(engine.timeline().current());
    painter.line_segment(
        [egui::pos2(x, rect.top()), egui::pos2(x, rect.bottom())],
        egui::Stroke::new(2.0, ui.visuals().strong_text_color()),
    );
    if let Some(pos) = response.interact_pointer_pos()
        && (response.clicked() || response.dragged())
    {
        let f = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 1.0);
        let step = ((f * len as f32) as usize).min(len - 1);
        engine.timeline_mut().set_current(step);
    }
    if let Some(pos) = response.hover_pos() {
        let f = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 1.0);
        let step = ((f * len as f32) as usize).min(len - 1);
        let failure = engine
            .failures()
            .into_iter()
            .find(|(i, _)| *i == step)
            .map(|(_, why)| why);
        let time = engine.timeline().times().get(step).copied().unwrap_or(0.0);
        let step = engine.bake_index(step).unwrap_or(step);
        response.on_hover_text(match failure {
            Some(why) => format!("step {step}, t = {time:.4}: {why}"),
            None => format!("step {step}, t = {time:.4}"),
        });
    }
}
