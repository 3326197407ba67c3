//! `views.html`: one self-contained page to pick a scene's parts by clicking on renders of it.
//!
//! A [`ViewsPage`] holds rendered views (each with its camera and depth image) and a sample of
//! the Gaussians' centres; [`ViewsPage::to_html`] lays them out with the run report's style and
//! a script (`page.js`, inlined) that, on a click, unprojects the pixel with its depth and
//! camera to the 3D point under it, draws a ball around it (drag or scroll to size it), counts
//! the Gaussians inside, and writes the `[targets]` lines `splatraj run` reads
//! (`name = { sphere = [x, y, z, r] }` under `[targets.regions]`). The data travel in one JSON
//! block ([`DATA_ELEMENT_ID`]): cameras as in `trajectory.json` (OpenCV axes, Φ = [ω, c] and
//! the 4×4 world-to-camera matrix), depths and centres as base64 ([`encode`]). Above the views,
//! a strip shows the scene upright for a few candidate ups with the line that sets each
//! ([`up_strip`]). Nothing is fetched, so the page works from a file, offline.

pub mod encode;
pub mod up_strip;

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use serde::Serialize;
use splatraj_camera::{Intrinsics, Pose};

use crate::report::{STYLE, escape};
use encode::{EncodedDepth, encode_depth, encode_points};
use up_strip::{STRIP_STYLE, UpChoice, strip_html};

/// The `id` of the `<script type="application/json">` element holding the page's data.
pub const DATA_ELEMENT_ID: &str = "splatraj-views";

/// The page's script, inlined.
const SCRIPT: &str = include_str!("page.js");

/// The page's own style, after the run report's.
const PAGE_STYLE: &str = "body{max-width:1500px}
.layout{display:flex;gap:18px;align-items:flex-start}.grid{flex:1;display:flex;flex-wrap:wrap;gap:12px}
.panel{position:sticky;top:8px;width:380px;flex:none;border:1px solid #ccc;padding:10px 12px;background:#fafafa;font-size:14px}
.panel input[type=text],.panel input[type=number]{width:120px}.panel button{margin:2px 4px 2px 0}
.panel textarea{width:100%;height:170px;font-family:monospace;font-size:12px}
.view{position:relative;display:block;line-height:0}.view img{display:block;width:100%;border:1px solid #ccc}
.view canvas{position:absolute;left:0;top:0;width:100%;height:100%;cursor:crosshair;touch-action:none}
figure.pick{width:520px;max-width:100%}code.line{display:block;background:#f0f0f0;padding:4px;word-break:break-all}
#parts li{margin:2px 0}.warn{color:#b00020}";

/// One rendered view with the camera that took it.
#[derive(Debug, Clone, PartialEq)]
pub struct PickView {
    /// Caption (where the camera stands).
    pub caption: String,
    /// The camera's intrinsics (the picture's size).
    pub intrinsics: Intrinsics,
    /// The camera's pose Φ = [ω, c].
    pub pose: Pose,
    /// The picture, PNG bytes.
    pub png: Vec<u8>,
    /// Camera depth z per pixel, row-major; not finite (or ≤ 0) where no surface is under it.
    pub depth: Vec<f32>,
}

/// Everything `views.html` shows.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewsPage {
    /// The scene's name (the title).
    pub title: String,
    /// Where the scene file is (shown under the title).
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// Centres of the Gaussians the page counts in a ball: all of them, or an even sample.
    pub centres: Vec<[f32; 3]>,
    /// World up the views were placed with.
    pub up: [f64; 3],
    /// Decimals of the coordinates written into the TOML lines.
    pub decimals: usize,
    /// The ball's radius before the user sizes it.
    pub radius: f64,
    /// The views.
    pub views: Vec<PickView>,
    /// The ups the "Which way is up?" strip shows, the one the views use first; none: no strip.
    pub up_choices: Vec<UpChoice>,
}

/// A page that cannot be laid out from its data.
#[derive(Debug, thiserror::Error)]
#[error("views page: {0}")]
pub struct ViewsPageError(pub String);

/// One view as the script reads it.
#[derive(Serialize)]
struct ViewData<'a> {
    caption: &'a str,
    width: usize,
    height: usize,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    /// Φ = [ω, c].
    pose: [f64; 6],
    /// R_wc row-major: columns are the camera's x, y, z axes in world.
    rotation_wc: [f64; 9],
    /// p_cam = R_wcᵀ (p − c), as a row-major 4×4.
    world_to_camera: [[f64; 4]; 4],
    depth: EncodedDepth,
}

/// The page's data block.
#[derive(Serialize)]
struct PageData<'a> {
    title: &'a str,
    gaussians: usize,
    /// Centres embedded (= `gaussians` when the count in a ball is exact).
    sampled: usize,
    centres: String,
    up: [f64; 3],
    decimals: usize,
    radius: f64,
    views: Vec<ViewData<'a>>,
}

impl ViewsPage {
    /// The page as one HTML string.
    pub fn to_html(&self) -> Result<String, ViewsPageError> {
        let views = self
            .views
            .iter()
            .enumerate()
            .map(|(i, v)| view_data(i, v))
            .collect::<Result<Vec<_>, _>>()?;
        let data = PageData {
            title: &self.title,
            gaussians: self.gaussians,
            sampled: self.centres.len(),
            centres: encode_points(&self.centres),
            up: self.up,
            decimals: self.decimals,
            radius: self.radius,
            views,
        };
        let json = serde_json::to_string(&data)
            .map_err(|e| ViewsPageError(format!("encoding the data: {e}")))?;
        let title = escape(&self.title);
        let mut page = format!(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"/>\
             <title>splatraj views: {title}</title><style>{STYLE}\n{PAGE_STYLE}\n{STRIP_STYLE}\
             </style></head>\n<body>\n<h1>splatraj views: {title}</h1><p class=\"sub\">{}</p>\n",
            escape(&self.scene)
        );
        page.push_str(&strip_html(&self.up_choices));
        page.push_str(&format!(
            "<p class=\"note\">Click a part in any view: the point under the pixel (from the \
             view's depth and camera) becomes the centre of a ball; drag from it, scroll over \
             the view, or type to size the ball. Name the part and add it; the block at the \
             right is the <code>[targets]</code> table to paste into a config. Balls of the \
             parts added show in every view. Sampled: {}.</p>\n",
            escape(&self.sample_note())
        ));
        page.push_str("<div class=\"layout\"><div class=\"grid\">");
        for (i, view) in self.views.iter().enumerate() {
            page.push_str(&format!(
                "<figure class=\"pick\"><div class=\"view\"><img alt=\"view {n}\" \
                 src=\"data:image/png;base64,{}\"/><canvas data-view=\"{i}\" width=\"{w}\" \
                 height=\"{h}\"></canvas></div><figcaption>view {n}: {}</figcaption></figure>",
                BASE64.encode(&view.png),
                escape(&view.caption),
                n = i + 1,
                w = view.intrinsics.width,
                h = view.intrinsics.height,
            ));
        }
        page.push_str("</div>");
        page.push_str(PANEL);
        page.push_str("</div>\n");
        page.push_str(&format!(
            "<section><h2>Cameras</h2><p class=\"note\">Each view's camera is in the data block \
             <code>#{DATA_ELEMENT_ID}</code> as in <code>trajectory.json</code>: OpenCV axes (x \
             right, y down, z forward), pixel (i, j) centred at (i + 0.5, j + 0.5), Φ = [ω, c] \
             (rotation vector of camera-to-world, camera centre) and the row-major world-to-camera \
             matrix; depth is camera z, composited as the renderer composites colour and divided \
             by the pixel's opacity, where that opacity exceeds one half. World up of the views: \
             [{:.3}, {:.3}, {:.3}].</p></section>\n",
            self.up[0], self.up[1], self.up[2]
        ));
        // `</` never occurs in base64 or numbers; escaping it (and `<` generally) in the text
        // fields keeps a name like `</script>` from closing the data block early.
        page.push_str(&format!(
            "<script type=\"application/json\" id=\"{DATA_ELEMENT_ID}\">{}</script>\n\
             <script>{SCRIPT}</script>\n</body></html>\n",
            json.replace('<', "\\u003c")
        ));
        Ok(page)
    }

    /// How the centres the page counts relate to the scene's.
    fn sample_note(&self) -> String {
        if self.centres.len() >= self.gaussians {
            format!(
                "all {} Gaussians are in the page, so counts are exact",
                self.gaussians
            )
        } else {
            format!(
                "{} of the scene's {} Gaussians are in the page (an even sample, 1 in {:.1}), so \
                 counts are estimates scaled from them",
                self.centres.len(),
                self.gaussians,
                self.gaussians as f64 / self.centres.len().max(1) as f64
            )
        }
    }
}

/// The script's record of view `i`, checked.
fn view_data(i: usize, view: &PickView) -> Result<ViewData<'_>, ViewsPageError> {
    let k = view.intrinsics;
    k.validate()
        .map_err(|p| ViewsPageError(format!("view {}: {p}", i + 1)))?;
    if view.depth.len() != k.width * k.height {
        return Err(ViewsPageError(format!(
            "view {}: {} depth values for a {}×{} picture",
            i + 1,
            view.depth.len(),
            k.width,
            k.height
        )));
    }
    if !view.pose.0.iter().all(|v| v.is_finite()) {
        return Err(ViewsPageError(format!(
            "view {}: pose is not finite",
            i + 1
        )));
    }
    let r = view.pose.rotation_wc();
    Ok(ViewData {
        caption: &view.caption,
        width: k.width,
        height: k.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        pose: view.pose.0,
        rotation_wc: [
            r.x_axis.x, r.y_axis.x, r.z_axis.x, r.x_axis.y, r.y_axis.y, r.z_axis.y, r.x_axis.z,
            r.y_axis.z, r.z_axis.z,
        ],
        world_to_camera: splatraj_camera::pose::matrix_rows(&view.pose.world_to_camera()),
        depth: encode_depth(&view.depth),
    })
}

/// The picking panel: the current point and ball, the part's name and line, the parts added
/// and the `[targets]` block. The script fills it; element ids are what tests drive.
const PANEL: &str = "<aside class=\"panel\" id=\"panel\"><h3>Part</h3>\
<div>point: <span id=\"point\">click a view</span></div>\
<div>radius: <input id=\"radius\" type=\"number\" step=\"any\" min=\"0\"/></div>\
<div>Gaussians in the ball: <span id=\"count\">-</span></div>\
<div>name: <input id=\"name\" type=\"text\" value=\"part1\"/> \
<button id=\"add-part\" type=\"button\">add part</button></div>\
<code class=\"line\" id=\"line\"></code><button id=\"copy-line\" type=\"button\">copy line</button>\
<div id=\"status\" class=\"note\"></div>\
<h3>Parts</h3><ul id=\"parts\"></ul>\
<h3>[targets]</h3><textarea id=\"targets\" readonly=\"readonly\"></textarea>\
<button id=\"copy-targets\" type=\"button\">copy [targets]</button>\
<button id=\"copy-config\" type=\"button\">copy with [[queries]]</button></aside>";

#[cfg(test)]
mod tests {
    use super::*;

    fn page() -> ViewsPage {
        let intrinsics = Intrinsics::from_fov_x(60.0, 4, 3).unwrap();
        ViewsPage {
            title: "a </script> b".into(),
            scene: "scene.ply".into(),
            gaussians: 10,
            centres: vec![[0.0, 1.0, 2.0]; 5],
            up: [0.0, 0.0, 1.0],
            decimals: 3,
            radius: 0.1,
            views: vec![PickView {
                caption: "around".into(),
                intrinsics,
                pose: Pose([0.0, 0.0, 0.0, 0.0, 0.0, -3.0]),
                png: vec![1, 2, 3],
                depth: vec![3.0; 12],
            }],
            up_choices: Vec::new(),
        }
    }

    #[test]
    fn data_block_holds_the_cameras_and_cannot_be_closed_by_a_name() {
        let html = page().to_html().unwrap();
        let start = html.find("id=\"splatraj-views\">").unwrap() + 20;
        let end = start + html[start..].find("</script>").unwrap();
        let data: serde_json::Value = serde_json::from_str(&html[start..end]).unwrap();
        assert_eq!(data["title"], "a </script> b");
        assert_eq!(data["sampled"], 5);
        assert_eq!(data["views"][0]["width"], 4);
        assert_eq!(data["views"][0]["world_to_camera"][2][3], 3.0);
        assert!(html.contains("counts are estimates"));
    }

    #[test]
    fn a_depth_of_the_wrong_size_is_refused() {
        let mut page = page();
        page.views[0].depth.pop();
        let error = page.to_html().unwrap_err().to_string();
        assert!(
            error.contains("11 depth values for a 4×3 picture"),
            "{error}"
        );
    }
}
