//! Starting the player: the window opened over a device the player made and shares with
//! egui.

use std::sync::Arc;

use eframe::egui;
use slosh_render::Gpu;

use super::options::{AppError, PlayOptions};
use super::player::Player;
use crate::engine::Engine;

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
    let engine = match &options.bake {
        Some(bake) => Engine::open_baking(gpu.clone(), bake.clone(), options.engine.clone())?,
        None => Engine::open(gpu.clone(), &options.dir, options.engine.clone())?,
    };
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
