//! `splatraj scene views`: the page where a user picks a scene's parts by clicking on renders
//! of it ([`splatraj_report::views_page`]).
//!
//! The views are those the lifting plans ([`plan_views`]): rings around the content and,
//! for a room, views from inside looking out, chosen greedily by what each newly shows. Each is
//! rendered in colour and depth (camera z composited and divided by the pixel's opacity,
//! kept where that opacity exceeds [`MIN_COVER`]); the page also carries the Gaussians' centres,
//! all of them or an even sample of at most [`ViewsPageOptions::max_centres`], to count what a
//! ball holds. Above the views, the scene upright for the up they use and for the geometry's
//! next candidates ([`crate::picking::up_choices`]). [`write_views_page`] checks the request,
//! reads, renders and writes the page whole or not at all.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use burn::tensor::{DType, Device};
use glam::DVec3;
use splatraj_lift::{LiftStage, Placement, Progress, View, ViewOptions, ViewPlan, plan_views};
use splatraj_render::render::DeviceScene;
use splatraj_report::views_page::ViewsPage;
use splatraj_scene::atomic::write_atomically;
use splatraj_scene::formats::check_output_target;
use splatraj_scene::up_axis::{ResolvedUp, resolve_up};
use splatraj_scene::{ReadOptions, Scene, UpSource, read_scene};

use crate::picking::up_choices::{up_choices, vector};
use crate::picking::view_render::render_view;
use crate::resources::{MemoryLimit, MemoryPlan, render_bytes, scene_bytes};

pub use crate::picking::view_render::MIN_COVER;
/// Most views a page may hold (each adds its picture and depth, about 5 bytes a pixel).
pub const MAX_VIEWS: usize = 32;
/// Side of the views, pixels: least and most.
pub const SIZE_RANGE: (usize, usize) = (64, 1024);
/// Most centres a page may carry (4 bytes × 3 each, and a loop over them per redraw).
pub const MAX_CENTRES: usize = 2_000_000;
/// The ball's first radius, as a share of the scene's robust diagonal.
const FIRST_RADIUS: f64 = 0.05;
/// Coordinates in TOML lines step by at most this share of the scene's robust diagonal.
const COORDINATE_STEP: f64 = 1e-4;
/// The candidates [`plan_views`] weighs keep one f32 per Gaussian each; fewer than this many.
const PLAN_CANDIDATES: f64 = 100.0;
/// Side of the "Which way is up?" pictures at most, pixels (three side by side above the
/// views).
const UP_PICTURE_SIZE: usize = 320;

/// How the page is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewsPageOptions {
    /// Views to render (the planner may find fewer that show something).
    pub views: usize,
    /// Side of each (square) view, pixels.
    pub size: usize,
    /// Horizontal field of view, degrees.
    pub fov_degrees: f64,
    /// World up; `None`: guessed from the scene.
    pub up: Option<[f64; 3]>,
    /// Most Gaussian centres carried; beyond, an even sample and counts are estimates.
    pub max_centres: usize,
}

impl Default for ViewsPageOptions {
    fn default() -> Self {
        ViewsPageOptions {
            views: 8,
            size: 512,
            fov_degrees: 60.0,
            up: None,
            max_centres: 200_000,
        }
    }
}

impl ViewsPageOptions {
    /// Checks the sizes, naming the command-line option of each.
    pub fn check(&self) -> Result<()> {
        if !(1..=MAX_VIEWS).contains(&self.views) {
            bail!("--views {} must be in 1..={MAX_VIEWS}", self.views);
        }
        let (least, most) = SIZE_RANGE;
        if !(least..=most).contains(&self.size) {
            bail!("--size {} must be in {least}..={most} pixels", self.size);
        }
        if !(1..=MAX_CENTRES).contains(&self.max_centres) {
            bail!(
                "--max-centres {} must be in 1..={MAX_CENTRES}",
                self.max_centres
            );
        }
        if let Some(up) = self.up
            && !(up.iter().all(|v| v.is_finite()) && up.iter().any(|&v| v != 0.0))
        {
            bail!("--up {up:?} must be a finite, non-zero direction");
        }
        Ok(())
    }
}

/// What `scene views` asks for.
#[derive(Debug, Clone)]
pub struct ViewsPageRequest {
    /// The scene file.
    pub scene: PathBuf,
    /// The page to write.
    pub out: PathBuf,
    /// How the scene is read.
    pub read: ReadOptions,
    /// How the page is made.
    pub options: ViewsPageOptions,
    /// Memory limit in GB; `None`: the machine's default.
    pub max_memory_gb: Option<f64>,
}

/// What [`write_views_page`] wrote.
#[derive(Debug, Clone)]
pub struct WrittenViewsPage {
    /// Gaussians in the scene (after any dropped as invalid).
    pub gaussians: usize,
    /// Gaussians dropped as invalid.
    pub dropped: usize,
    /// Centres the page carries (all, or an even sample).
    pub centres: usize,
    /// Views around the content.
    pub around: usize,
    /// Views from inside, looking out.
    pub inside: usize,
    /// Share of the Gaussians at least one view shows.
    pub seen_share: f64,
    /// World up and where it came from.
    pub up: ResolvedUp,
    /// The ups the page's "Which way is up?" strip shows, `up` first.
    pub up_choices: Vec<[f64; 3]>,
    /// Size of the page, bytes.
    pub bytes: usize,
}

impl WrittenViewsPage {
    /// What `scene views` says after writing the page at `out`: the up it stood the views on,
    /// how many views and what they show, the file and whether its counts are exact.
    pub fn summary(&self, out: &Path) -> Vec<String> {
        let [x, y, z] = self.up.up;
        let from = match self.up.source {
            UpSource::Config => "given".to_string(),
            other => format!("{}; --up X,Y,Z to override", other.name()),
        };
        let counts = if self.centres < self.gaussians {
            format!(
                "{} of {} centres carried: counts in the page are estimates",
                self.centres, self.gaussians
            )
        } else {
            format!("all {} centres carried: counts are exact", self.gaussians)
        };
        vec![
            format!(
                "up [{x:.3}, {y:.3}, {z:.3}] ({from}); {} views around the scene, {} from \
                 inside; they show {:.0} % of the Gaussians",
                self.around,
                self.inside,
                100.0 * self.seen_share
            ),
            format!(
                "which way is up: the page's first strip shows the scene upright for {}",
                self.up_choices
                    .iter()
                    .enumerate()
                    .map(|(i, &up)| if i == 0 {
                        format!("{} (these views)", vector(up))
                    } else {
                        vector(up)
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            format!(
                "wrote {} ({:.1} MB; {counts})",
                out.display(),
                self.bytes as f64 / 1e6
            ),
        ]
    }
}

/// Checks the request, reads the scene, plans and renders the views and writes the page to
/// `request.out`, whole or not at all.
pub fn write_views_page(
    request: &ViewsPageRequest,
    device: &Device,
    progress: &Progress,
) -> Result<WrittenViewsPage> {
    request.options.check()?;
    check_page_target(&request.out, &request.scene)?;
    let loaded = read_scene(&request.scene, &request.read)?;
    let scene = &loaded.scene;
    if scene.is_empty() {
        bail!("{} holds no Gaussian to show", request.scene.display());
    }
    memory_plan(scene.len(), &request.options)
        .check(MemoryLimit::new(request.max_memory_gb)?, "--max-memory GB")?;
    // As runs take it: `--up`, else the capture's cameras beside the scene, else the guess.
    let up = match request.options.up {
        Some(_) => resolve_up(request.options.up, false, scene),
        None => crate::prepare::scene_up::up_beside(&request.scene, scene),
    };
    let uploaded = DeviceScene::new(scene, &device.clone().autodiff(), DType::F32);
    let plan = plan_views(
        scene,
        &uploaded,
        up.up,
        &ViewOptions {
            count: request.options.views,
            fov_degrees: request.options.fov_degrees,
            ..ViewOptions::default()
        },
        request.options.size,
        progress,
    )?;
    let views = overviews_first(scene, &plan);
    let title = request
        .scene
        .file_name()
        .map_or_else(|| "scene".into(), |n| n.to_string_lossy().into_owned());
    let mut page = views_page(
        scene,
        &uploaded,
        &views,
        &PageText {
            title,
            scene: request.scene.display().to_string(),
            up: up.up,
            max_centres: request.options.max_centres,
        },
        progress,
    )?;
    page.up_choices = up_choices(
        scene,
        &uploaded,
        &up,
        request.options.fov_degrees,
        request.options.size.min(UP_PICTURE_SIZE),
        progress,
    )?;
    let html = page.to_html()?;
    write_atomically(&request.out, |w| w.write_all(html.as_bytes()))
        .with_context(|| format!("cannot write the page {}", request.out.display()))?;
    let inside = plan
        .placements
        .iter()
        .filter(|&&p| p == Placement::Inside)
        .count();
    Ok(WrittenViewsPage {
        gaussians: scene.len(),
        dropped: loaded.dropped,
        centres: page.centres.len(),
        around: plan.views.len() - inside,
        inside,
        seen_share: plan.seen_share,
        up_choices: page.up_choices.iter().map(|c| c.up).collect(),
        up,
        bytes: html.len(),
    })
}

/// What the page says about the scene, beside its views.
#[derive(Debug, Clone)]
pub struct PageText {
    /// Title (the scene file's name).
    pub title: String,
    /// Where the scene file is.
    pub scene: String,
    /// World up the views were placed with.
    pub up: [f64; 3],
    /// Most centres carried.
    pub max_centres: usize,
}

/// The page of `scene` (uploaded as `uploaded`) seen from `views` (each with its caption).
pub fn views_page(
    scene: &Scene,
    uploaded: &DeviceScene,
    views: &[(View, String)],
    text: &PageText,
    progress: &Progress,
) -> Result<ViewsPage> {
    let bounds = scene
        .robust_bounds(0.02)
        .ok_or_else(|| anyhow!("the scene holds no Gaussian"))?;
    let diagonal = bounds
        .size()
        .iter()
        .map(|&s| f64::from(s) * f64::from(s))
        .sum::<f64>()
        .sqrt()
        .max(1e-9);
    let mut picked = Vec::with_capacity(views.len());
    for (done, (view, caption)) in views.iter().enumerate() {
        progress(LiftStage::Render, done, views.len());
        picked.push(render_view(uploaded, view, caption.clone())?);
    }
    progress(LiftStage::Render, views.len(), views.len());
    Ok(ViewsPage {
        title: text.title.clone(),
        scene: text.scene.clone(),
        gaussians: scene.len(),
        centres: even_sample(&scene.means, text.max_centres),
        up: text.up,
        decimals: (-(diagonal * COORDINATE_STEP).log10())
            .ceil()
            .clamp(1.0, 9.0) as usize,
        radius: FIRST_RADIUS * diagonal,
        views: picked,
        up_choices: Vec::new(),
    })
}

/// The planned views with captions: those around the content farthest first (an overview
/// before the close-ups), then those from inside. The planner orders them by what each newly
/// shows, which for picking puts a close-up first.
fn overviews_first(scene: &Scene, plan: &ViewPlan) -> Vec<(View, String)> {
    let middle = scene
        .robust_bounds(0.02)
        .map_or(DVec3::ZERO, |b| DVec3::from(b.center().map(f64::from)));
    let mut views: Vec<(View, Placement)> = plan
        .views
        .iter()
        .copied()
        .zip(plan.placements.iter().copied())
        .collect();
    views.sort_by(|(a, pa), (b, pb)| {
        let far = |v: &View| v.pose.centre().distance(middle);
        (*pa == Placement::Inside)
            .cmp(&(*pb == Placement::Inside))
            .then(far(b).total_cmp(&far(a)))
    });
    views
        .into_iter()
        .map(|(view, placement)| (view, caption(placement, &view)))
        .collect()
}

/// Where a view stands, in words.
fn caption(placement: Placement, view: &View) -> String {
    let c = view.pose.centre();
    let place = match placement {
        Placement::Around => "around the scene",
        Placement::Inside => "inside, looking out",
    };
    format!("{place}, camera at [{:.2}, {:.2}, {:.2}]", c.x, c.y, c.z)
}

/// All of `points`, or `most` of them evenly spaced through the list (a systematic sample:
/// files that store Gaussians in spatial order, as compressed PLY does, are then sampled
/// evenly in space as well).
pub fn even_sample(points: &[[f32; 3]], most: usize) -> Vec<[f32; 3]> {
    let n = points.len();
    if n <= most {
        return points.to_vec();
    }
    (0..most)
        .map(|k| points[(k as u128 * n as u128 / most as u128) as usize])
        .collect()
}

/// Refuses a page that would replace the scene file or something not a regular file, or that
/// lies in a folder that does not exist, before any work.
fn check_page_target(out: &Path, scene: &Path) -> Result<()> {
    if let (Ok(a), Ok(b)) = (out.canonicalize(), scene.canonicalize())
        && a == b
    {
        bail!("--out {} is the scene file itself", out.display());
    }
    check_output_target(out)?;
    let folder = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        bail!(
            "cannot write the page {}: the folder {} does not exist",
            out.display(),
            folder.display()
        );
    }
    Ok(())
}

/// The memory the page takes: the scene, the planner's candidates, the renders and the page.
fn memory_plan(gaussians: usize, options: &ViewsPageOptions) -> MemoryPlan {
    let scene = scene_bytes(gaussians, 4);
    let probe = ViewOptions::default().probe_size as f64;
    let pixels = (options.size * options.size) as f64;
    let page =
        options.views as f64 * pixels * 8.0 + gaussians.min(options.max_centres) as f64 * 16.0;
    let mut plan = MemoryPlan::default();
    plan.stage(
        format!("choosing the views of {gaussians} Gaussians"),
        scene
            + PLAN_CANDIDATES * gaussians as f64 * 4.0
            + render_bytes(1, probe * probe, gaussians, true, 4),
    )
    .stage(
        format!(
            "rendering {} views of {} × {} pixels (--views, --size)",
            options.views, options.size, options.size
        ),
        scene + render_bytes(1, pixels, gaussians, false, 4) + page,
    );
    plan
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn even_sample_keeps_all_or_spreads() {
        let points: Vec<[f32; 3]> = (0..10).map(|i| [i as f32, 0.0, 0.0]).collect();
        assert_eq!(even_sample(&points, 20).len(), 10);
        let sample = even_sample(&points, 4);
        let xs: Vec<f32> = sample.iter().map(|p| p[0]).collect();
        assert_eq!(xs, vec![0.0, 2.0, 5.0, 7.0]);
    }

    #[test]
    fn options_are_checked_naming_the_flag() {
        let bad = ViewsPageOptions {
            size: 10,
            ..ViewsPageOptions::default()
        };
        assert!(bad.check().unwrap_err().to_string().contains("--size 10"));
        let bad = ViewsPageOptions {
            up: Some([0.0; 3]),
            ..ViewsPageOptions::default()
        };
        assert!(bad.check().unwrap_err().to_string().contains("--up"));
    }
}
