//! Top and side views of a camera path over a scene's points, as SVG drawn by `plotters`.
//!
//! The views are orthographic projections on axes made from world up u: the top view looks down
//! −u and shows (e₁, e₂); the side view shows (e₁, u). e₁ is the direction, across u, in which
//! the camera centres and objects spread most (so the side view shows the path's length), and
//! e₂ = u × e₁ makes (e₁, e₂, u) right-handed, so the top view is not mirrored. Both axes of a
//! view have the same scale.

use glam::DVec3;
use plotters::prelude::*;

use super::plots::failed;
use super::{ReportError, window_colour};

/// One sample of the camera path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathSample {
    /// Camera centre (world).
    pub centre: [f64; 3],
    /// Viewing direction (the camera's +z in world, unit).
    pub forward: [f64; 3],
    /// The window it falls in.
    pub window: usize,
}

/// What the views draw.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SceneView {
    /// World up.
    pub up: [f64; 3],
    /// Scene points (a sample) and their colours.
    pub points: Vec<([f32; 3], [u8; 3])>,
    /// The camera path, in time order.
    pub path: Vec<PathSample>,
    /// Each window's object: its name and centre.
    pub objects: Vec<(String, [f64; 3])>,
}

/// Size of each view in pixels.
const SIZE: (u32, u32) = (560, 460);

/// Viewing-direction strokes drawn along the path.
const DIRECTION_STROKES: usize = 24;

/// The orthonormal view axes (e₁, e₂, u) for `view`.
pub fn view_axes(view: &SceneView) -> [DVec3; 3] {
    let up = DVec3::from(view.up).try_normalize().unwrap_or(DVec3::Z);
    // A start for e₁: the world axis least along up.
    let axis = [DVec3::X, DVec3::Y, DVec3::Z]
        .into_iter()
        .min_by(|a, b| a.dot(up).abs().total_cmp(&b.dot(up).abs()))
        .unwrap_or(DVec3::X);
    let a = (axis - up * axis.dot(up)).normalize();
    let b = up.cross(a);
    // Principal direction of the centres and objects in the plane across up (2×2 covariance).
    let marks: Vec<DVec3> = view
        .path
        .iter()
        .map(|p| DVec3::from(p.centre))
        .chain(view.objects.iter().map(|o| DVec3::from(o.1)))
        .collect();
    let mut e1 = a;
    if marks.len() >= 2 {
        let mean = marks.iter().sum::<DVec3>() / marks.len() as f64;
        let (mut saa, mut sab, mut sbb) = (0.0, 0.0, 0.0);
        for m in &marks {
            let (x, y) = ((*m - mean).dot(a), (*m - mean).dot(b));
            saa += x * x;
            sab += x * y;
            sbb += y * y;
        }
        let angle = 0.5 * (2.0 * sab).atan2(saa - sbb);
        if angle.is_finite() {
            e1 = a * angle.cos() + b * angle.sin();
        }
    }
    [e1, up.cross(e1), up]
}

/// The top view and the side view, as SVG strings.
pub fn top_and_side(view: &SceneView) -> Result<[String; 2], ReportError> {
    let [e1, e2, up] = view_axes(view);
    Ok([
        draw(view, [e1, e2], "top view (looking down world up)")?,
        draw(view, [e1, up], "side view (world up points up)")?,
    ])
}

/// `[lo, hi]` of each axis holding the path and objects, and most of the points (2nd to 98th
/// percentile, so a few stray Gaussians do not shrink the scene to a dot), with a margin.
fn extent(view: &SceneView, project: &dyn Fn(DVec3) -> (f64, f64)) -> [(f64, f64); 2] {
    let percentile = |mut v: Vec<f64>, q: f64| -> Option<f64> {
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(v[((v.len() - 1) as f64 * q).round() as usize])
    };
    let points: Vec<(f64, f64)> = view
        .points
        .iter()
        .map(|(p, _)| project(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let marks: Vec<(f64, f64)> = view
        .path
        .iter()
        .map(|p| project(DVec3::from(p.centre)))
        .chain(view.objects.iter().map(|o| project(DVec3::from(o.1))))
        .collect();
    let axis = |pick: fn(&(f64, f64)) -> f64| {
        let along: Vec<f64> = points.iter().map(pick).collect();
        let mut lo = percentile(along.clone(), 0.02).unwrap_or(f64::INFINITY);
        let mut hi = percentile(along, 0.98).unwrap_or(f64::NEG_INFINITY);
        for m in &marks {
            lo = lo.min(pick(m));
            hi = hi.max(pick(m));
        }
        if !(lo.is_finite() && hi.is_finite()) {
            return (-1.0, 1.0);
        }
        let margin = 0.06 * (hi - lo).max(1e-6);
        (lo - margin, hi + margin)
    };
    [axis(|p| p.0), axis(|p| p.1)]
}

/// `[x, y]` ranges widened so one unit is as long on both axes of a `w` × `h` plot.
fn same_scale([x, y]: [(f64, f64); 2], (w, h): (f64, f64)) -> [(f64, f64); 2] {
    let scale = ((x.1 - x.0) / w).max((y.1 - y.0) / h);
    let widen = |(lo, hi): (f64, f64), size: f64| {
        let (mid, half) = (0.5 * (lo + hi), 0.5 * scale * size);
        (mid - half, mid + half)
    };
    [widen(x, w), widen(y, h)]
}

fn draw(view: &SceneView, [ex, ey]: [DVec3; 2], caption: &str) -> Result<String, ReportError> {
    let fail = failed("path views");
    let project = |p: DVec3| (p.dot(ex), p.dot(ey));
    // The plotting area inside the label areas and margins below.
    let area = (f64::from(SIZE.0) - 72.0, f64::from(SIZE.1) - 84.0);
    let [(x0, x1), (y0, y1)] = same_scale(extent(view, &project), area);
    let inside = |(x, y): (f64, f64)| x > x0 && x < x1 && y > y0 && y < y1;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 16))
            .margin(10)
            .x_label_area_size(28)
            .y_label_area_size(52)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| fail(&e))?;
        chart
            .configure_mesh()
            .light_line_style(WHITE.mix(0.0))
            .x_labels(6)
            .y_labels(6)
            .draw()
            .map_err(|e| fail(&e))?;
        chart
            .draw_series(view.points.iter().filter_map(|(p, c)| {
                let at = project(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
                inside(at)
                    .then(|| Circle::new(at, 1, RGBColor(c[0], c[1], c[2]).mix(0.55).filled()))
            }))
            .map_err(|e| fail(&e))?;

        let length = 0.05 * (x1 - x0).max(y1 - y0);
        let stride = (view.path.len() / DIRECTION_STROKES).max(1);
        for sample in view.path.iter().step_by(stride) {
            let (r, g, b) = window_colour(sample.window);
            let c = DVec3::from(sample.centre);
            let tip = c + DVec3::from(sample.forward) * length;
            chart
                .draw_series([PathElement::new(
                    vec![project(c), project(tip)],
                    RGBColor(r, g, b).mix(0.8).stroke_width(1),
                )])
                .map_err(|e| fail(&e))?;
        }
        // The path, one colour per window; each piece runs on to the next window's first sample
        // so the line is unbroken.
        let mut start = 0;
        while start < view.path.len() {
            let window = view.path[start].window;
            let end = view.path[start..]
                .iter()
                .position(|s| s.window != window)
                .map_or(view.path.len(), |n| start + n);
            let (r, g, b) = window_colour(window);
            let piece = view.path[start..(end + 1).min(view.path.len())]
                .iter()
                .map(|s| project(DVec3::from(s.centre)));
            chart
                .draw_series(LineSeries::new(piece, RGBColor(r, g, b).stroke_width(3)))
                .map_err(|e| fail(&e))?;
            start = end;
        }
        if let Some(first) = view.path.first() {
            chart
                .draw_series([Circle::new(
                    project(DVec3::from(first.centre)),
                    5,
                    BLACK.filled(),
                )])
                .map_err(|e| fail(&e))?;
            chart
                .draw_series([Text::new(
                    "start",
                    project(DVec3::from(first.centre)),
                    ("sans-serif", 13).into_font(),
                )])
                .map_err(|e| fail(&e))?;
        }
        for (i, (name, centre)) in view.objects.iter().enumerate() {
            let (r, g, b) = window_colour(i);
            let at = project(DVec3::from(*centre));
            chart
                .draw_series([Cross::new(at, 7, RGBColor(r, g, b).stroke_width(3))])
                .map_err(|e| fail(&e))?;
            chart
                .draw_series([Text::new(
                    format!("{i}: {name}"),
                    at,
                    ("sans-serif", 14)
                        .into_font()
                        .color(&RGBColor(r, g, b))
                        .pos(plotters::style::text_anchor::Pos::new(
                            plotters::style::text_anchor::HPos::Left,
                            plotters::style::text_anchor::VPos::Bottom,
                        )),
                )])
                .map_err(|e| fail(&e))?;
        }
        root.present().map_err(|e| fail(&e))?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_are_right_handed_and_follow_the_path() {
        // A path along the world diagonal x = y at height z (up = +z).
        let path = (0..5)
            .map(|i| PathSample {
                centre: [i as f64, i as f64, 1.0],
                forward: [1.0, 0.0, 0.0],
                window: 0,
            })
            .collect();
        let view = SceneView {
            up: [0.0, 0.0, 2.0],
            path,
            ..SceneView::default()
        };
        let [e1, e2, up] = view_axes(&view);
        assert!((up - DVec3::Z).length() < 1e-12);
        let diagonal = DVec3::new(1.0, 1.0, 0.0).normalize();
        assert!(e1.dot(diagonal).abs() > 1.0 - 1e-9, "{e1}");
        assert!((e1.cross(e2) - up).length() < 1e-12);
    }

    #[test]
    fn same_scale_keeps_the_aspect() {
        let [x, y] = same_scale([(0.0, 10.0), (0.0, 1.0)], (200.0, 100.0));
        assert!(((x.1 - x.0) / 200.0 - (y.1 - y.0) / 100.0).abs() < 1e-12);
        assert_eq!(x, (0.0, 10.0));
        assert!(y.0 < 0.0 && y.1 > 1.0);
    }
}
