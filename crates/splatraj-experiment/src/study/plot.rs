//! `frontier.svg`: every variant's mean error against its mean optimisation time (± sd bars
//! over seeds), the Pareto frontier joined and marked, each point labelled with its setting.
//! Drawn by plotters' SVG backend (the crate the run report's plots use).

use anyhow::{Result, anyhow};
use plotters::prelude::*;

use super::summary::StudySummary;

/// Plot size in pixels.
const SIZE: (u32, u32) = (960, 620);

/// The frontier plot as an SVG document.
pub fn frontier_svg(summary: &StudySummary, title: &str) -> Result<String> {
    let fail = |e: &dyn std::fmt::Display| anyhow!("drawing frontier.svg: {e}");
    let points: Vec<(f64, f64, f64, bool, &str)> = summary
        .variants
        .iter()
        .filter_map(|v| {
            let (t, e) = v.figures.point();
            let sd = v.figures.error.map_or(0.0, |s| s.sd);
            (t.is_finite() && e.is_finite()).then_some((t, e, sd, v.on_frontier, v.label.as_str()))
        })
        .collect();
    let (t_max, e_max) = points
        .iter()
        .fold((0.0f64, 0.0f64), |(t, e), p| (t.max(p.0), e.max(p.1 + p.2)));
    let (t_max, e_max) = (t_max.max(1e-3) * 1.15, e_max.max(1e-3) * 1.15);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(16)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..t_max, 0f64..e_max)
            .map_err(|e| fail(&e))?;
        chart
            .configure_mesh()
            .x_desc("optimisation time, s (mean over seeds)")
            .y_desc(format!("error: {}", summary.quality.describe()))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(|e| fail(&e))?;
        let frontier_colour = RGBColor(200, 40, 30);
        let other = RGBColor(110, 110, 110);
        let line: Vec<(f64, f64)> = summary
            .frontier
            .iter()
            .map(|&i| summary.variants[i].figures.point())
            .collect();
        chart
            .draw_series(LineSeries::new(line, frontier_colour.stroke_width(2)))
            .map_err(|e| fail(&e))?
            .label("Pareto frontier")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], frontier_colour.stroke_width(2))
            });
        for &(t, e, sd, on, label) in &points {
            let colour = if on { frontier_colour } else { other };
            if sd > 0.0 {
                chart
                    .draw_series([PathElement::new(
                        vec![(t, (e - sd).max(0.0)), (t, e + sd)],
                        colour.mix(0.5).stroke_width(1),
                    )])
                    .map_err(|e| fail(&e))?;
            }
            let marker = if on {
                Circle::new((t, e), 5, colour.filled())
            } else {
                Circle::new((t, e), 4, colour.stroke_width(1))
            };
            chart.draw_series([marker]).map_err(|e| fail(&e))?;
            chart
                .draw_series([Text::new(
                    label.to_string(),
                    (t, e),
                    ("sans-serif", 12).into_font().color(&colour).pos(
                        plotters::style::text_anchor::Pos::new(
                            plotters::style::text_anchor::HPos::Left,
                            plotters::style::text_anchor::VPos::Bottom,
                        ),
                    ),
                )])
                .map_err(|e| fail(&e))?;
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
