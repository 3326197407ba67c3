//! `report.html`: one self-contained page about a run, to look at instead of reading JSON.
//!
//! A [`RunReport`] holds what the page shows, gathered by the caller from the run folder's
//! files; [`RunReport::to_html`] lays it out: the summary and per-window metrics as tables, the
//! video, a strip of keyframes per window, TCE/TRE/coverage along t, the cost history per term,
//! top and side views of the path over the scene's points, and the config. Plots are SVG drawn
//! by `plotters` ([`plots`], [`views`]), pictures and the video are inlined as base64 `data:`
//! URIs (or the video is linked when large), and nothing is fetched from the network. The page
//! is also well-formed XML (every tag closed, every attribute quoted, no named entities beyond
//! XML's), so an XML parser can check it.

pub mod plots;
pub mod views;

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;

pub use views::{PathSample, SceneView};

/// A plot could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("report: drawing {plot}: {problem}")]
pub struct ReportError {
    /// Which plot.
    pub plot: &'static str,
    /// What went wrong.
    pub problem: String,
}

/// A table: column names and rows of cells (already formatted).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows, one cell per column.
    pub rows: Vec<Vec<String>>,
}

/// One query window: its name and span of t.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    /// The query.
    pub query: String,
    /// Start of the window in t.
    pub start: f64,
    /// End of the window in t.
    pub end: f64,
    /// The share of the frame the object should cover.
    pub target_ratio: f64,
}

/// One shot of the run: a run of windows joined by pans; a cut begins every shot but the
/// first.
#[derive(Debug, Clone, PartialEq)]
pub struct Shot {
    /// Its windows.
    pub windows: Vec<usize>,
    /// Their queries.
    pub queries: Vec<String>,
    /// Start of the shot in t.
    pub start: f64,
    /// End of the shot in t.
    pub end: f64,
    /// Why the cut into it was made (None for the first shot).
    pub cut_reason: Option<String>,
}

/// One rendered frame with its metrics, in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameMetrics {
    /// Time t ∈ [0, 1].
    pub t: f64,
    /// The window t falls in.
    pub window: usize,
    /// Target centring error of the window's object in this frame; `None` when the frame does
    /// not show it (undefined, not 0).
    pub tce: Option<f64>,
    /// Target ratio error.
    pub tre: f64,
    /// Share of the frame the visible object covers.
    pub coverage: f64,
}

/// One keyframe picture.
#[derive(Debug, Clone, PartialEq)]
pub struct Keyframe {
    /// Time t ∈ [0, 1].
    pub t: f64,
    /// Its file name in the run folder (caption).
    pub name: String,
    /// PNG bytes.
    pub png: Vec<u8>,
}

/// The cost history: one value per step for each term (summed over windows), and the total.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CostHistory {
    /// Step number across restarts (x axis).
    pub steps: Vec<f64>,
    /// Term name and its value at each step.
    pub terms: Vec<(String, Vec<f64>)>,
}

/// How the page shows the video.
#[derive(Debug, Clone, PartialEq)]
pub enum VideoSource {
    /// MP4 bytes inlined in the page.
    Inline(Vec<u8>),
    /// A path relative to the page (the video is too large to inline).
    Link(String),
}

/// Everything `report.html` shows.
#[derive(Debug, Clone, Default)]
pub struct RunReport {
    /// Page title (the run's name).
    pub title: String,
    /// Where the run folder is (shown under the title).
    pub folder: String,
    /// Key facts (scene, stop reason, times, smoothness …).
    pub summary: Vec<(String, String)>,
    /// The run's verdict: None when the run folder holds none (an older run), else one
    /// sentence per failed check of any window (empty: every window passes).
    pub verdict: Option<Vec<String>>,
    /// Per-window metrics.
    pub metrics: Table,
    /// The query windows.
    pub windows: Vec<Window>,
    /// The shots (`trajectory.json`'s `shots`; empty for a run written before them).
    pub shots: Vec<Shot>,
    /// Keyframes of each window, in window order.
    pub keyframes: Vec<Vec<Keyframe>>,
    /// Metrics of every frame.
    pub along: Vec<FrameMetrics>,
    /// Cost history.
    pub history: Option<CostHistory>,
    /// Top and side views of the path over the scene.
    pub view: Option<SceneView>,
    /// The video.
    pub video: Option<VideoSource>,
    /// The resolved config (TOML).
    pub config: String,
}

/// Videos up to this size are inlined; larger ones are linked.
pub const INLINE_VIDEO_BYTES: usize = 8 << 20;

/// The style of the pages this crate writes (the run report, the views page).
pub(crate) const STYLE: &str = "body{font-family:system-ui,sans-serif;margin:24px auto;max-width:1180px;color:#222;padding:0 12px}
h1{margin-bottom:0}.sub{color:#666;margin-top:4px;font-family:monospace}
nav a{margin-right:14px}section{margin-top:28px}
table{border-collapse:collapse;font-size:14px}th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}
.strip{display:flex;gap:8px;overflow-x:auto}figure{margin:0}figure img{width:220px;display:block;border:1px solid #ccc}
figcaption{font-size:12px;color:#555;text-align:center}.views{display:flex;flex-wrap:wrap;gap:12px}
pre{background:#f6f6f6;padding:10px;font-size:13px;overflow-x:auto}video{width:640px;max-width:100%;border:1px solid #ccc;background:#000}
.note{color:#666;font-size:13px}
.fail{border:2px solid #b00020;background:#fdecee;padding:8px 14px;margin-top:14px}
.fail h2{color:#b00020;margin:4px 0}.pass{border:1px solid #2e7d32;background:#edf7ee;padding:6px 14px;margin-top:14px}";

impl RunReport {
    /// The page as one HTML string.
    pub fn to_html(&self) -> Result<String, ReportError> {
        let mut page = String::new();
        let title = escape(&self.title);
        page.push_str(&format!(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"/>\
             <title>splatraj run: {title}</title><style>{STYLE}</style></head>\n<body>\n\
             <h1>splatraj run: {title}</h1><p class=\"sub\">{}</p>\n<nav>",
            escape(&self.folder)
        ));
        for (id, name) in [
            ("summary", "summary"),
            ("video", "video"),
            ("shots", "shots"),
            ("keyframes", "keyframes"),
            ("along", "along t"),
            ("history", "cost history"),
            ("views", "path views"),
            ("config", "config"),
        ] {
            page.push_str(&format!("<a href=\"#{id}\">{name}</a>"));
        }
        page.push_str("</nav>\n");
        match &self.verdict {
            Some(problems) if !problems.is_empty() => {
                page.push_str(
                    "<section class=\"fail\" id=\"verdict\"><h2>Verdict: some windows do not \
                     show their object as asked</h2><ul>",
                );
                for problem in problems {
                    page.push_str(&format!("<li>{}</li>", escape(problem)));
                }
                page.push_str(
                    "</ul><p class=\"note\">The same warnings as on the console, and \
                     <code>verdict</code> in metrics.json. With <code>[output] verdict = \
                     \"fail\"</code> (the default) <code>splatraj run</code> exits with status \
                     3 after writing its folder.</p></section>\n",
                );
            }
            Some(_) => page.push_str(
                "<p class=\"pass\">Verdict: every window shows its object in frame, framed, \
                 unhidden, with the camera clear of the geometry.</p>\n",
            ),
            None => {}
        }

        page.push_str("<section id=\"summary\"><h2>Summary</h2>");
        let summary = Table {
            header: vec!["".into(), "".into()],
            rows: self
                .summary
                .iter()
                .map(|(k, v)| vec![k.clone(), v.clone()])
                .collect(),
        };
        page.push_str(&table_html(&summary, false));
        page.push_str("<h3>Per-window metrics</h3>");
        page.push_str(&table_html(&self.metrics, true));
        page.push_str("</section>\n");

        page.push_str("<section id=\"video\"><h2>Video</h2>");
        match &self.video {
            Some(VideoSource::Inline(bytes)) => page.push_str(&format!(
                "<video controls=\"controls\" loop=\"loop\" muted=\"muted\" \
                 src=\"data:video/mp4;base64,{}\"></video>",
                BASE64.encode(bytes)
            )),
            Some(VideoSource::Link(path)) => page.push_str(&format!(
                "<video controls=\"controls\" loop=\"loop\" muted=\"muted\" src=\"{0}\"></video>\
                 <p class=\"note\">The video is beside this page: <a href=\"{0}\">{0}</a>.</p>",
                escape(path)
            )),
            None => page.push_str("<p class=\"note\">No video in this run folder.</p>"),
        }
        page.push_str("</section>\n");

        page.push_str(&self.shot_list());

        page.push_str("<section id=\"keyframes\"><h2>Keyframes</h2>");
        if self.keyframes.iter().all(Vec::is_empty) {
            page.push_str("<p class=\"note\">No frames in this run folder.</p>");
        }
        for (i, frames) in self.keyframes.iter().enumerate() {
            let query = self.windows.get(i).map_or("", |w| w.query.as_str());
            page.push_str(&format!(
                "<h3>window {i}: {}</h3><div class=\"strip\">",
                escape(query)
            ));
            for frame in frames {
                page.push_str(&format!(
                    "<figure><img alt=\"{name}\" src=\"data:image/png;base64,{}\"/>\
                     <figcaption>{name}, t = {:.3}</figcaption></figure>",
                    BASE64.encode(&frame.png),
                    frame.t,
                    name = escape(&frame.name),
                ));
            }
            page.push_str("</div>");
        }
        page.push_str("</section>\n");

        page.push_str("<section id=\"along\"><h2>TCE, TRE and coverage along t</h2>");
        if self.along.is_empty() {
            page.push_str("<p class=\"note\">No per-frame metrics in this run folder.</p>");
        } else {
            page.push_str(&plots::along_t(&self.along, &self.windows)?);
            page.push_str(
                "<p class=\"note\">Each frame's metrics for the object of its window; dashed: \
                 window bounds and each window's target ratio.</p>",
            );
        }
        page.push_str("</section>\n");

        page.push_str("<section id=\"history\"><h2>Cost history</h2>");
        match &self.history {
            Some(history) if !history.steps.is_empty() => {
                page.push_str(&plots::cost_history(history)?);
                page.push_str(
                    "<p class=\"note\">Each term summed over the windows, per optimisation \
                     step (restarts one after another).</p>",
                );
            }
            _ => page.push_str("<p class=\"note\">No history in this run folder.</p>"),
        }
        page.push_str("</section>\n");

        page.push_str("<section id=\"views\"><h2>Path over the scene</h2>");
        match &self.view {
            Some(view) => {
                let [top, side] = views::top_and_side(view)?;
                page.push_str(&format!("<div class=\"views\">{top}{side}</div>"));
                page.push_str(
                    "<p class=\"note\">Scene points (a sample, in their colours), the camera \
                     centre along the path coloured by window, short strokes for the viewing \
                     direction, and each window's object (×). Top: looking down world up; \
                     side: world up pointing up.</p>",
                );
            }
            None => page.push_str("<p class=\"note\">No scene given for the views.</p>"),
        }
        page.push_str("</section>\n");

        page.push_str(&format!(
            "<section id=\"config\"><h2>Config</h2><pre>{}</pre></section>\n</body></html>\n",
            escape(&self.config)
        ));
        Ok(page)
    }
}

impl RunReport {
    /// The shot list: per shot its windows, its span of t, how it begins (a cut and why)
    /// and its first keyframe as a thumbnail.
    fn shot_list(&self) -> String {
        let mut html = String::from("<section id=\"shots\"><h2>Shots</h2>");
        if self.shots.is_empty() {
            html.push_str("<p class=\"note\">No shot list in this run folder.</p></section>\n");
            return html;
        }
        if self.shots.len() == 1 {
            html.push_str(
                "<p class=\"note\">One continuous shot: every window pans on to the next \
                 (<code>[output] transitions</code>).</p>",
            );
        }
        html.push_str(
            "<table><tr><th>shot</th><th>windows</th><th>t</th><th>begins with</th>\
             <th>first frame</th></tr>",
        );
        for (j, shot) in self.shots.iter().enumerate() {
            let windows: Vec<String> = shot
                .windows
                .iter()
                .zip(&shot.queries)
                .map(|(i, q)| format!("{i}: {}", escape(q)))
                .collect();
            let begins = match &shot.cut_reason {
                Some(reason) => format!("a cut: {}", escape(reason)),
                None => "the start".to_string(),
            };
            let thumbnail = shot
                .windows
                .first()
                .and_then(|&i| self.keyframes.get(i))
                .and_then(|frames| frames.first())
                .map_or(String::new(), |k| {
                    format!(
                        "<img alt=\"{}\" style=\"width:160px\" src=\"data:image/png;base64,{}\"/>",
                        escape(&k.name),
                        BASE64.encode(&k.png)
                    )
                });
            html.push_str(&format!(
                "<tr><td>{j}</td><td>{}</td><td>{:.3}–{:.3}</td><td>{begins}</td><td>{thumbnail}</td></tr>",
                windows.join(", "),
                shot.start,
                shot.end
            ));
        }
        html.push_str("</table></section>\n");
        html
    }
}

fn table_html(table: &Table, with_header: bool) -> String {
    let mut html = String::from("<table>");
    if with_header {
        html.push_str("<tr>");
        for h in &table.header {
            html.push_str(&format!("<th>{}</th>", escape(h)));
        }
        html.push_str("</tr>");
    }
    for row in &table.rows {
        html.push_str("<tr>");
        for cell in row {
            html.push_str(&format!("<td>{}</td>", escape(cell)));
        }
        html.push_str("</tr>");
    }
    html.push_str("</table>");
    html
}

/// Text as HTML (and XML) character data or attribute value. Five replacements are the whole
/// job, so no crate.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Colour of window `i` in every plot (matplotlib's tab10, which stays apart when printed grey).
pub fn window_colour(i: usize) -> (u8, u8, u8) {
    const TAB10: [(u8, u8, u8); 10] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ];
    TAB10[i % TAB10.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_covers_markup_and_quotes() {
        assert_eq!(
            escape("a<b & \"c\" 'd'>"),
            "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt;"
        );
    }
}
