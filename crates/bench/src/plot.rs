//! The accuracy report's plot: error against cost on log axes, one line per scene, as a PNG.

use std::path::Path;

use anyhow::{Context, Result};

/// round(log10(v)) with `round` = floor or ceil.
fn decade(v: f64, round: fn(f64) -> f64) -> f64 {
    round(v.log10())
}

const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

pub(crate) fn plot_png(path: &Path, series: &[(String, Vec<(f64, f64)>)]) -> Result<()> {
    use plotters::prelude::*;
    let font = std::fs::read(FONT).with_context(|| {
        format!("{FONT}: the plot needs DejaVu Sans (Debian: fonts-dejavu-core)")
    })?;
    let font: &'static [u8] = Box::leak(font.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, font)
        .map_err(|_| anyhow::anyhow!("{FONT}: not a usable font"))?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = path.with_extension("tmp.png");
    {
        let root = BitMapBackend::new(&tmp, (1000, 650)).into_drawing_area();
        root.fill(&WHITE)?;
        let xs = series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
        let ys = series
            .iter()
            .flat_map(|s| s.1.iter().map(|p| p.1))
            .filter(|y| *y > 0.0);
        let x_max = xs.fold(0.0f64, f64::max) * 1.1;
        let (y_min, y_max) = ys.fold((f64::INFINITY, 0.0f64), |(a, b), y| (a.min(y), b.max(y)));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "MLS error against cost (clean scenes, iterations 1..)",
                ("sans-serif", 24),
            )
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            // log10 of the error on a linear axis over whole decades: labelled ticks always.
            .build_cartesian_2d(
                0.0..x_max.max(1e-3),
                decade(y_min.max(1e-9), f64::floor)..decade(y_max.max(1e-8), f64::ceil),
            )?;
        chart
            .configure_mesh()
            .x_desc("CPU µs per ray (one thread)")
            .y_desc("RMS distance to the true surface (spacings)")
            .y_labels(12)
            .y_label_formatter(&|v| format!("{:.1e}", 10f64.powf(*v)))
            .label_style(("sans-serif", 15))
            .draw()?;
        for (k, (name, pts)) in series.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            let pts: Vec<(f64, f64)> = pts
                .iter()
                .filter(|p| p.1 > 0.0)
                .map(|&(x, y)| (x, y.log10()))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))?
                .label(name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        root.present()?;
    }
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
