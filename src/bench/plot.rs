//! Plots for the benchmark reports (plotters' bitmap backend, encoded with `png`). No
//! font is needed: tick labels are drawn with a built-in 3x5 pixel font of digits, and
//! titles and legends are in the markdown that embeds the pictures.

use plotters::prelude::*;

/// 3x5 glyphs, rows top to bottom, 3 bits each (4 = left column).
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        'e' => [0, 7, 7, 4, 7],
        _ => return None,
    })
}

/// Draws `text` with its top-left corner at pixel (x, y), `scale` pixels per font pixel.
fn tiny_text<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    text: &str,
    (x, y): (i32, i32),
    scale: i32,
) {
    // (x, y) are backend pixels; the area draws relative to its own corner
    let (bx, by) = area.get_base_pixel();
    let (x, y) = (x - bx, y - by);
    for (k, c) in text.chars().enumerate() {
        let Some(rows) = glyph(c) else { continue };
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) != 0 {
                    let x0 = x + (k as i32 * 4 + col) * scale;
                    let y0 = y + r as i32 * scale;
                    let _ = area.draw(&Rectangle::new(
                        [(x0, y0), (x0 + scale - 1, y0 + scale - 1)],
                        BLACK.filled(),
                    ));
                }
            }
        }
    }
}

fn label(v: f64) -> String {
    let a = v.abs();
    if v != 0.0 && (a >= 1e4 || a < 1e-2) {
        format!("{v:.0e}").replace('+', "")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// One line of a plot.
pub struct Series {
    pub color: RGBColor,
    pub points: Vec<(f64, f64)>,
}

/// A panel: series on linear or log10 axes, optional vertical marker (a threshold).
pub struct Panel {
    pub series: Vec<Series>,
    pub log_x: bool,
    pub log_y: bool,
    pub marker_x: Option<f64>,
    /// fixed y range (before the log), e.g. 0..1 for a CDF
    pub y_range: Option<(f64, f64)>,
}

pub const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Renders panels side by side into a PNG (each `size` pixels square).
pub fn panels_png(panels: &[Panel], size: u32) -> Result<Vec<u8>, String> {
    let (w, h) = (size * panels.len().max(1) as u32, size);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let areas = root.split_evenly((1, panels.len().max(1)));
        for (area, panel) in areas.iter().zip(panels) {
            draw_panel(area, panel)?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    crate::io::encode_rgb_png(w, h, &rgb)
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
) -> Result<(), String> {
    let tx = |v: f64| if panel.log_x { v.max(1e-12).log10() } else { v };
    let ty = |v: f64| if panel.log_y { v.max(1e-12).log10() } else { v };
    let all: Vec<(f64, f64)> = panel
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|&(x, y)| (tx(x), ty(y))))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    if all.is_empty() {
        return Ok(());
    }
    let span = |vals: Vec<f64>| {
        let lo = vals.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = vals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi - lo < 1e-12 {
            (lo - 0.5, hi + 0.5)
        } else {
            (lo, hi)
        }
    };
    let (x0, x1) = span(
        all.iter()
            .map(|p| p.0)
            .chain(panel.marker_x.map(tx))
            .collect(),
    );
    let (y0, y1) = match panel.y_range {
        Some((a, b)) => (ty(a), ty(b)),
        None => span(all.iter().map(|p| p.1).collect()),
    };
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(16)
        .y_label_area_size(34)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    // frame and ticks (no font: see `tiny_text`)
    let frame = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)];
    chart
        .draw_series(LineSeries::new(frame, BLACK))
        .map_err(|e| e.to_string())?;
    let grey = RGBColor(220, 220, 220);
    for i in 0..=4 {
        let fx = x0 + (x1 - x0) * i as f64 / 4.0;
        let fy = y0 + (y1 - y0) * i as f64 / 4.0;
        chart
            .draw_series(LineSeries::new([(fx, y0), (fx, y1)], grey))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(LineSeries::new([(x0, fy), (x1, fy)], grey))
            .map_err(|e| e.to_string())?;
        let shown = |v: f64, log: bool| label(if log { 10f64.powf(v) } else { v });
        let (px, py) = chart.backend_coord(&(fx, y0));
        tiny_text(area, &shown(fx, panel.log_x), (px - 8, py + 4), 2);
        let (px, py) = chart.backend_coord(&(x0, fy));
        tiny_text(area, &shown(fy, panel.log_y), (px - 34, py - 5), 2);
    }
    if let Some(m) = panel.marker_x {
        chart
            .draw_series(LineSeries::new(
                [(tx(m), y0), (tx(m), y1)],
                BLACK.stroke_width(1),
            ))
            .map_err(|e| e.to_string())?;
    }
    for s in &panel.series {
        let pts: Vec<(f64, f64)> = s.points.iter().map(|&(x, y)| (tx(x), ty(y))).collect();
        chart
            .draw_series(LineSeries::new(pts, s.color.stroke_width(2)))
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The empirical CDF of a sample: (value, fraction <= value).
pub fn cdf(values: &[f64]) -> Vec<(f64, f64)> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let n = v.len() as f64;
    v.iter()
        .enumerate()
        .map(|(i, &x)| (x, (i + 1) as f64 / n))
        .collect()
}
