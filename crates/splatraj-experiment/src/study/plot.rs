//! `frontier.svg`: every variant's mean error against its mean optimisation time (± sd bars
//! over seeds), the Pareto frontier joined and marked, each point labelled with its setting.
//! Drawn by plotters' SVG backend (the crate the run report's plots use); plotters places no
//! labels, so [`place_labels`] keeps them apart and inside the plot.

use anyhow::{Result, anyhow};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::summary::StudySummary;

/// Plot size in pixels.
const SIZE: (u32, u32) = (960, 620);
/// Label font size as given to plotters (its SVG backend writes `LABEL_FONT / 1.24` px).
const LABEL_FONT: f64 = 12.0;
/// Radius of a frontier marker, pixels (others are one smaller).
const MARKER_RADIUS: i32 = 5;

/// The frontier plot as an SVG document.
pub fn frontier_svg(summary: &StudySummary, title: &str) -> Result<String> {
    let fail = |e: &dyn std::fmt::Display| anyhow!("drawing frontier.svg: {e}");
    let points: Vec<(f64, f64, f64, bool, &str)> = summary
        .variants
        .iter()
        .filter_map(|v| {
            let (t, e) = v.figures.point();
            let sd = v.figures.error.map_or(0.0, |s| s.sd);
            (t.is_finite() && t > 0.0 && e.is_finite()).then_some((
                t,
                e,
                sd,
                v.on_frontier,
                v.label.as_str(),
            ))
        })
        .collect();
    // Time on a log axis: one slow variant (the tensor rasterizer, 10× the rest) would
    // otherwise squeeze every other point into a corner. The error axis spans the data, not
    // zero to the largest, since variants differ by a few per cent.
    let (t_lo, t_hi) = points.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
        (lo.min(p.0), hi.max(p.0))
    });
    let (t_lo, t_hi) = if points.is_empty() {
        (0.1, 10.0)
    } else {
        (t_lo / 1.3, t_hi * 1.3)
    };
    let (e_lo, e_hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.1 - p.2), hi.max(p.1 + p.2))
        });
    let (e_lo, e_hi) = if points.is_empty() {
        (0.0, 1.0)
    } else {
        let pad = ((e_hi - e_lo) * 0.12).max(e_hi.abs() * 0.02).max(1e-6);
        ((e_lo - pad).max(0.0), e_hi + pad)
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&e))?;
        let caption = format!("{title} (red, joined: the Pareto frontier)");
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 18))
            .margin(16)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((t_lo..t_hi).log_scale(), e_lo..e_hi)
            .map_err(|e| fail(&e))?;
        // plotters' log axis labels only powers of ten (none below the first one), so the
        // time axis gets its own ticks at 1-2-5 steps.
        chart
            .configure_mesh()
            .disable_x_mesh()
            .set_tick_mark_size(LabelAreaPosition::Bottom, 0)
            .x_label_formatter(&|_| String::new())
            .x_desc("optimisation time, s (mean over seeds, log scale)")
            .y_desc(format!("error: {}", summary.quality.describe()))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(|e| fail(&e))?;
        let (_, ys) = chart.plotting_area().get_pixel_range();
        for tick in time_ticks(t_lo, t_hi) {
            chart
                .draw_series([PathElement::new(
                    vec![(tick, e_lo), (tick, e_hi)],
                    BLACK.mix(0.2).stroke_width(1),
                )])
                .map_err(|e| fail(&e))?;
            let (x, _) = chart.backend_coord(&(tick, e_lo));
            root.draw(&Text::new(
                format!("{}", (tick * 1e6).round() / 1e6),
                (x, ys.end + 6),
                ("sans-serif", 12)
                    .into_font()
                    .color(&BLACK)
                    .pos(Pos::new(HPos::Center, VPos::Top)),
            ))
            .map_err(|e| fail(&e))?;
        }
        let frontier_colour = RGBColor(200, 40, 30);
        let other = RGBColor(110, 110, 110);
        let line: Vec<(f64, f64)> = summary
            .frontier
            .iter()
            .map(|&i| summary.variants[i].figures.point())
            .collect();
        chart
            .draw_series(LineSeries::new(line, frontier_colour.stroke_width(2)))
            .map_err(|e| fail(&e))?;
        for &(t, e, sd, on, _) in &points {
            let colour = if on { frontier_colour } else { other };
            if sd > 0.0 {
                chart
                    .draw_series([PathElement::new(
                        vec![(t, (e - sd).max(e_lo)), (t, e + sd)],
                        colour.mix(0.5).stroke_width(1),
                    )])
                    .map_err(|e| fail(&e))?;
            }
            let marker = if on {
                Circle::new((t, e), MARKER_RADIUS, colour.filled())
            } else {
                Circle::new((t, e), MARKER_RADIUS - 1, colour.stroke_width(1))
            };
            chart.draw_series([marker]).map_err(|e| fail(&e))?;
        }

        // Labels in pixels, frontier points first (they matter most), then left to right.
        let anchors: Vec<(f64, f64)> = points
            .iter()
            .map(|p| {
                let (x, y) = chart.backend_coord(&(p.0, p.1));
                (x as f64, y as f64)
            })
            .collect();
        let sizes: Vec<(f64, f64)> = points.iter().map(|p| label_size(p.4)).collect();
        let mut order: Vec<usize> = (0..points.len()).collect();
        order.sort_by(|&a, &b| {
            (!points[a].3, anchors[a].0)
                .partial_cmp(&(!points[b].3, anchors[b].0))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        let bounds = LabelBox {
            x: xs.start as f64 + 2.0,
            y: ys.start as f64 + 2.0,
            w: (xs.end - xs.start) as f64 - 4.0,
            h: (ys.end - ys.start) as f64 - 4.0,
        };
        // What a label must not cover: every marker, the frontier line and the sd bars.
        let marker = MARKER_RADIUS as f64 + 1.0;
        let mut obstacles: Vec<LabelBox> = anchors
            .iter()
            .map(|a| LabelBox::around(*a, marker))
            .collect();
        let pixel = |t: f64, e: f64| {
            let (x, y) = chart.backend_coord(&(t, e));
            (x as f64, y as f64)
        };
        let frontier_pixels: Vec<(f64, f64)> = summary
            .frontier
            .iter()
            .map(|&i| summary.variants[i].figures.point())
            .map(|(t, e)| pixel(t, e))
            .collect();
        for pair in frontier_pixels.windows(2) {
            obstacles.extend(segment_boxes(pair[0], pair[1]));
        }
        for &(t, e, sd, _, _) in points.iter().filter(|p| p.2 > 0.0) {
            obstacles.extend(segment_boxes(
                pixel(t, (e - sd).max(e_lo)),
                pixel(t, e + sd),
            ));
        }
        let placed = place_labels(&anchors, &sizes, &order, bounds, &obstacles);
        let font = ("sans-serif", LABEL_FONT).into_font();
        for ((p, anchor), label) in points.iter().zip(&anchors).zip(&placed) {
            let colour = if p.3 { frontier_colour } else { other };
            if label.needs_leader {
                let (lx, ly) = label.bbox.nearest_point(*anchor);
                root.draw(&PathElement::new(
                    vec![
                        (anchor.0 as i32, anchor.1 as i32),
                        (lx.round() as i32, ly.round() as i32),
                    ],
                    colour.mix(0.6).stroke_width(1),
                ))
                .map_err(|e| fail(&e))?;
            }
            let style = font
                .clone()
                .color(&colour)
                .pos(Pos::new(HPos::Left, VPos::Top));
            root.draw(&Text::new(
                p.4.to_string(),
                (label.bbox.x.round() as i32, label.bbox.y.round() as i32),
                style,
            ))
            .map_err(|e| fail(&e))?;
        }
        root.present().map_err(|e| fail(&e))?;
    }
    Ok(svg)
}

/// Tick values for a log time axis from `lo` to `hi`: 1, 2, 5 times the powers of ten in the
/// range, or 1, 1.5, 2, 3, 5, 7 times them where that gives fewer than four.
fn time_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let ticks = |steps: &[f64]| -> Vec<f64> {
        let first = lo.log10().floor() as i32;
        let last = hi.log10().ceil() as i32;
        (first..=last)
            .flat_map(|k| steps.iter().map(move |m| m * 10f64.powi(k)))
            .filter(|v| *v >= lo && *v <= hi)
            .collect()
    };
    let coarse = ticks(&[1.0, 2.0, 5.0]);
    if coarse.len() >= 4 {
        coarse
    } else {
        ticks(&[1.0, 1.5, 2.0, 3.0, 5.0, 7.0])
    }
}

/// A label's estimated size in pixels: plotters' SVG text carries no metrics, so the width is
/// an upper estimate for a sans-serif face (0.62 em per character), the height one line.
fn label_size(text: &str) -> (f64, f64) {
    let px = LABEL_FONT / 1.24;
    (text.chars().count() as f64 * 0.62 * px + 2.0, px * 1.3)
}

/// A rectangle in pixels (y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabelBox {
    /// Left edge.
    pub x: f64,
    /// Top edge.
    pub y: f64,
    /// Width.
    pub w: f64,
    /// Height.
    pub h: f64,
}

impl LabelBox {
    /// The square of half-side `half` centred on `p`.
    pub fn around(p: (f64, f64), half: f64) -> LabelBox {
        LabelBox {
            x: p.0 - half,
            y: p.1 - half,
            w: 2.0 * half,
            h: 2.0 * half,
        }
    }

    /// The area this box shares with `other`.
    pub fn overlap(&self, other: &LabelBox) -> f64 {
        let w = (self.x + self.w).min(other.x + other.w) - self.x.max(other.x);
        let h = (self.y + self.h).min(other.y + other.h) - self.y.max(other.y);
        w.max(0.0) * h.max(0.0)
    }

    /// Whether the box lies wholly inside `outer`.
    pub fn inside(&self, outer: &LabelBox) -> bool {
        self.x >= outer.x
            && self.y >= outer.y
            && self.x + self.w <= outer.x + outer.w
            && self.y + self.h <= outer.y + outer.h
    }

    /// The point of the box nearest to `p`.
    fn nearest_point(&self, p: (f64, f64)) -> (f64, f64) {
        (
            p.0.clamp(self.x, self.x + self.w),
            p.1.clamp(self.y, self.y + self.h),
        )
    }
}

/// Small boxes covering the segment from `a` to `b` (one every 4 px), as obstacles for labels.
fn segment_boxes(a: (f64, f64), b: (f64, f64)) -> Vec<LabelBox> {
    let length = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
    let steps = (length / 4.0).ceil().max(1.0) as usize;
    (0..=steps)
        .map(|k| {
            let s = k as f64 / steps as f64;
            LabelBox::around((a.0 + s * (b.0 - a.0), a.1 + s * (b.1 - a.1)), 1.5)
        })
        .collect()
}

/// Where a label went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedLabel {
    /// Its box.
    pub bbox: LabelBox,
    /// Whether it sits away from its point and needs a line to it.
    pub needs_leader: bool,
}

/// Distances of a label from its point, pixels, tried in turn: beyond the first a leader line
/// joins the label to its point.
const RINGS: [f64; 7] = [4.0, 16.0, 30.0, 48.0, 70.0, 100.0, 140.0];
/// Directions tried at each distance, degrees clockwise from the right (y points down):
/// right first (reading order), then the diagonals, left, above and below.
const DIRECTIONS: [f64; 12] = [
    0.0, -30.0, 30.0, 180.0, -150.0, 150.0, -90.0, 90.0, -60.0, 60.0, -120.0, 120.0,
];

/// Places the labels of `anchors` (label sizes `sizes`, placed in the order `order`): each at
/// the first position, ring by ring outwards, that overlaps no label placed before it and no
/// obstacle (markers first, then lines) and lies inside `bounds`; where no position is free,
/// at the one overlapping least. One box per anchor.
pub fn place_labels(
    anchors: &[(f64, f64)],
    sizes: &[(f64, f64)],
    order: &[usize],
    bounds: LabelBox,
    obstacles: &[LabelBox],
) -> Vec<PlacedLabel> {
    // Rings are measured from the edge of a point's marker (the first obstacle's size).
    let marker = obstacles.first().map_or(0.0, |o| o.w / 2.0);
    let mut placed: Vec<Option<PlacedLabel>> = vec![None; anchors.len()];
    for &i in order {
        let (w, h) = sizes[i];
        let (ax, ay) = anchors[i];
        let mut best: Option<(f64, PlacedLabel)> = None;
        'search: for (ring, r) in RINGS.iter().enumerate() {
            for deg in DIRECTIONS {
                let (dy, dx) = deg.to_radians().sin_cos();
                // The box's centre moves out along the direction far enough that its edge
                // facing the point is `r` away from the point's marker.
                let cx = ax + dx * (marker + r + w / 2.0);
                let cy = ay + dy * (marker + r + h / 2.0);
                let bbox = LabelBox {
                    x: cx - w / 2.0,
                    y: cy - h / 2.0,
                    w,
                    h,
                };
                let outside = if bbox.inside(&bounds) {
                    0.0
                } else {
                    w * h - bbox.overlap(&bounds) + 1.0
                };
                let clash: f64 = placed
                    .iter()
                    .flatten()
                    .map(|p| p.bbox.overlap(&bbox))
                    .chain(obstacles.iter().map(|m| m.overlap(&bbox)))
                    .sum::<f64>()
                    + 10.0 * outside;
                let candidate = PlacedLabel {
                    bbox,
                    needs_leader: ring > 0,
                };
                if best.is_none_or(|(c, _)| clash < c) {
                    best = Some((clash, candidate));
                }
                if clash == 0.0 {
                    break 'search;
                }
            }
        }
        placed[i] = best.map(|(_, p)| p);
    }
    placed
        .into_iter()
        .zip(anchors)
        .map(|(p, a)| {
            p.unwrap_or(PlacedLabel {
                bbox: LabelBox {
                    x: a.0,
                    y: a.1,
                    w: 0.0,
                    h: 0.0,
                },
                needs_leader: false,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points close together (the study's usual cluster of variants near the baseline) get
    /// labels that overlap neither each other nor any marker and stay in the plot.
    #[test]
    fn clustered_labels_do_not_overlap_and_stay_inside() {
        let bounds = LabelBox {
            x: 0.0,
            y: 0.0,
            w: 860.0,
            h: 520.0,
        };
        // Eight points within 30 px of each other, one near the right edge, one at a corner.
        let mut anchors: Vec<(f64, f64)> = (0..8)
            .map(|k| (300.0 + 4.0 * k as f64, 250.0 + 3.0 * (k % 3) as f64))
            .collect();
        anchors.push((855.0, 260.0));
        anchors.push((3.0, 3.0));
        let sizes: Vec<(f64, f64)> = (0..anchors.len())
            .map(|k| label_size(&"x".repeat(10 + 2 * k)))
            .collect();
        let order: Vec<usize> = (0..anchors.len()).collect();
        let markers: Vec<LabelBox> = anchors.iter().map(|a| LabelBox::around(*a, 6.0)).collect();
        let placed = place_labels(&anchors, &sizes, &order, bounds, &markers);
        assert_eq!(placed.len(), anchors.len());
        for (i, p) in placed.iter().enumerate() {
            assert!(p.bbox.inside(&bounds), "label {i} at {:?}", p.bbox);
            assert_eq!((p.bbox.w, p.bbox.h), sizes[i]);
            for (j, q) in placed.iter().enumerate().skip(i + 1) {
                assert_eq!(p.bbox.overlap(&q.bbox), 0.0, "labels {i} and {j}");
            }
            for (j, marker) in markers.iter().enumerate() {
                assert_eq!(p.bbox.overlap(marker), 0.0, "label {i} on marker {j}");
            }
        }
        // A lone point keeps its label right next to it, with no leader line.
        let lone_marker = [LabelBox::around((100.0, 100.0), 6.0)];
        let lone = place_labels(
            &[(100.0, 100.0)],
            &[(50.0, 12.0)],
            &[0],
            bounds,
            &lone_marker,
        );
        assert!(!lone[0].needs_leader);
        assert!(lone[0].bbox.x > 100.0 && lone[0].bbox.x < 120.0);
        // A line leaving the point to the right pushes the label off it.
        let mut with_line = lone_marker.to_vec();
        with_line.extend(segment_boxes((100.0, 100.0), (300.0, 100.0)));
        let moved = place_labels(&[(100.0, 100.0)], &[(50.0, 12.0)], &[0], bounds, &with_line);
        assert!(with_line.iter().all(|o| o.overlap(&moved[0].bbox) == 0.0));
    }

    #[test]
    fn time_ticks_step_1_2_5_and_stay_in_range() {
        assert_eq!(
            time_ticks(2.0, 210.0),
            [2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0]
        );
        // A narrow range gets the finer steps.
        assert_eq!(time_ticks(9.0, 52.0), [10.0, 15.0, 20.0, 30.0, 50.0]);
    }

    #[test]
    fn overlap_and_inside_agree_with_hand_figures() {
        let a = LabelBox {
            x: 0.0,
            y: 0.0,
            w: 10.0,
            h: 4.0,
        };
        let b = LabelBox {
            x: 8.0,
            y: 1.0,
            w: 10.0,
            h: 10.0,
        };
        assert_eq!(a.overlap(&b), 2.0 * 3.0);
        assert_eq!(b.overlap(&a), 6.0);
        assert!(!b.inside(&a));
        let c = LabelBox {
            x: 1.0,
            y: 1.0,
            w: 2.0,
            h: 2.0,
        };
        assert!(c.inside(&a));
        assert_eq!(a.nearest_point((20.0, -5.0)), (10.0, 0.0));
    }
}
