//! The report's line plots, as SVG strings drawn by `plotters`: metrics along t and the cost
//! history.

use plotters::prelude::*;

use super::{CostHistory, FrameMetrics, ReportError, Window, window_colour};

/// A line of the metrics plot: its name, colour and value of a frame.
type MetricLine = (&'static str, RGBColor, fn(&FrameMetrics) -> Option<f64>);

/// Plot size in pixels.
const SIZE: (u32, u32) = (1100, 380);

/// A `ReportError` for `plot` from any plotters error.
pub(crate) fn failed(plot: &'static str) -> impl Fn(&dyn std::fmt::Display) -> ReportError {
    move |e| ReportError {
        plot,
        problem: e.to_string(),
    }
}

/// TCE, TRE and coverage of every frame against t, with the window bounds and target ratios.
pub fn along_t(frames: &[FrameMetrics], windows: &[Window]) -> Result<String, ReportError> {
    let fail = failed("metrics along t");
    let top = frames
        .iter()
        .flat_map(|f| [f.tce.unwrap_or(0.0), f.tre, f.coverage])
        .chain(windows.iter().map(|w| w.target_ratio))
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(0.05)
        * 1.1;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(52)
            .build_cartesian_2d(0f64..1f64, 0f64..top)
            .map_err(|e| fail(&e))?;
        chart
            .configure_mesh()
            .x_desc("t")
            .y_desc("error / share of frame")
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(|e| fail(&e))?;
        for (i, w) in windows.iter().enumerate() {
            let (r, g, b) = window_colour(i);
            let colour = RGBColor(r, g, b);
            chart
                .draw_series(DashedLineSeries::new(
                    [(w.start, w.target_ratio), (w.end, w.target_ratio)],
                    6,
                    4,
                    colour.stroke_width(1),
                ))
                .map_err(|e| fail(&e))?;
            if i > 0 {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(w.start, 0.0), (w.start, top)],
                        6,
                        4,
                        BLACK.mix(0.4).stroke_width(1),
                    ))
                    .map_err(|e| fail(&e))?;
            }
            chart
                .draw_series([Text::new(
                    format!("{i}: {}", w.query),
                    (w.start + 0.005, top * 0.97),
                    ("sans-serif", 14).into_font().color(&colour),
                )])
                .map_err(|e| fail(&e))?;
        }
        let series: [MetricLine; 3] = [
            ("TCE", RGBColor(200, 30, 30), |f| f.tce),
            ("TRE", RGBColor(30, 90, 200), |f| Some(f.tre)),
            ("coverage", RGBColor(20, 150, 60), |f| Some(f.coverage)),
        ];
        for (name, colour, value) in series {
            // A frame without a value (TCE of a frame not showing its object) breaks the line.
            let runs: Vec<Vec<(f64, f64)>> = frames
                .iter()
                .map(|f| value(f).map(|v| (f.t, v)))
                .collect::<Vec<_>>()
                .split(Option::is_none)
                .filter(|run| !run.is_empty())
                .map(|run| run.iter().flatten().copied().collect())
                .collect();
            for (i, run) in runs.iter().enumerate() {
                let drawn = chart
                    .draw_series(LineSeries::new(run.clone(), colour.stroke_width(2)))
                    .map_err(|e| fail(&e))?;
                if i == 0 {
                    drawn.label(name).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
                }
            }
            let points: Vec<(f64, f64)> = runs.into_iter().flatten().collect();
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|p| Circle::new(p, 2, colour.filled())),
                )
                .map_err(|e| fail(&e))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .margin(24)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .draw()
            .map_err(|e| fail(&e))?;
        root.present().map_err(|e| fail(&e))?;
    }
    Ok(svg)
}

/// Each cost term (and the total) against the step, on a log scale.
pub fn cost_history(history: &CostHistory) -> Result<String, ReportError> {
    let fail = failed("cost history");
    // Terms can reach 0 (a centred object); a log axis needs a floor.
    let floor = 1e-4;
    let values = history
        .terms
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .filter(|v| v.is_finite());
    let high = values.fold(floor, f64::max) * 1.5;
    let last = history.steps.last().copied().unwrap_or(1.0).max(1.0);
    let first = history
        .steps
        .first()
        .copied()
        .unwrap_or(0.0)
        .min(last - 1.0);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(first..last, (floor..high).log_scale())
            .map_err(|e| fail(&e))?;
        chart
            .configure_mesh()
            .x_desc("step")
            .y_desc("cost (log)")
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(|e| fail(&e))?;
        for (k, (name, values)) in history.terms.iter().enumerate() {
            let (r, g, b) = if name == "total" {
                (0, 0, 0)
            } else {
                window_colour(k + 3)
            };
            let colour = RGBColor(r, g, b);
            let width = if name == "total" { 3 } else { 2 };
            let points: Vec<(f64, f64)> = history
                .steps
                .iter()
                .zip(values)
                .filter(|(_, v)| v.is_finite())
                .map(|(&s, &v)| (s, v.max(floor)))
                .collect();
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(width)))
                .map_err(|e| fail(&e))?
                .label(name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(width))
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .draw()
            .map_err(|e| fail(&e))?;
        root.present().map_err(|e| fail(&e))?;
    }
    Ok(svg)
}
