//! One semantic query against a scene, as `splatraj query` runs it: the target source, the
//! selection, a diagnostic picture of it, and the report (text or JSON).
//!
//! The scene and source always come from a config ([`ConfigQuery`]): a run config's `[scene]`
//! and `[targets]`, built exactly as `splatraj run` builds them ([`crate::prepare::grounding`]), or the
//! config the command-line options make (each option sets a `[targets]` key; without
//! `--source` the source is the one the inputs point to, [`inferred_source`], and errors name
//! the options, [`option_of_key`]). Both end in [`find_and_draw`].

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use burn::tensor::Device;
use serde::Serialize;
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::to_host;
use splatraj_render::render::{AlphaChannel, Channel, DeviceScene, RenderRequest, render_poses};
use splatraj_scene::{Scene, UpSource};
use splatraj_semantic::{
    Cluster, ClusteringSummary, Explanation, RegionSpec, SelectionOptions, SourceKind, Spread,
    Target, TargetSource, TargetsConfig, TextKeys, explain, select,
};

use crate::config::{Config, apply_assignment};
use crate::extensions::Extensions;
use crate::prepare::experiment::load_scene;
use crate::prepare::views::{
    CameraReport, FOV_X_DEGREES, ViewOptions, diagnostic_camera, highlighted_picture,
    highlighted_png,
};
use crate::resources::{MemoryLimit, RenderWork};
use splatraj_traj::shots::ShotSpec;

/// Colour of the rejected candidates in `query.png` (cyan, against the selection's magenta).
pub const REJECTED_RGB: [f64; 3] = [0.1, 0.85, 1.0];
/// Strength of the rejected candidates' tint.
const REJECTED_STRENGTH: f64 = 0.6;
/// Runner-up clusters listed one by one in the text report.
const LISTED_RUNNER_UPS: usize = 5;

/// Whether `query.png` shows the candidates the selection dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RejectedView {
    /// Only the selection is tinted.
    #[default]
    Hidden,
    /// The dropped candidates (runner-up clusters and noise) are tinted [`REJECTED_RGB`].
    Tinted,
}

/// How `query.png` shows the selection: the camera's view, size and what it tints.
#[derive(Debug, Clone)]
pub struct PictureOptions {
    /// How the picture's camera looks at the selection.
    pub view: ViewOptions,
    /// Whether the picture shows the dropped candidates.
    pub rejected: RejectedView,
    /// The picture's camera.
    pub intrinsics: Intrinsics,
}

impl PictureOptions {
    /// Checked options for a `width` × `height` picture with the horizontal field of view the
    /// query pictures use; the view's elevation must lie within ±89° (at ±90° the camera looks
    /// along the up axis and its roll is undefined).
    pub fn new(
        width: usize,
        height: usize,
        view: ViewOptions,
        rejected: RejectedView,
    ) -> Result<Self> {
        if width == 0 || height == 0 {
            bail!("width and height must be at least 1 (got {width}×{height})");
        }
        RenderWork {
            what: "a picture".to_string(),
            renders: 1.0,
            at_once: 1,
            size: (width, height),
            gaussians: 0,
            gradient: false,
            float_bytes: 4,
        }
        .check(MemoryLimit::new(None)?, "")?;
        let elevation = view.elevation_degrees;
        if !(elevation.is_finite() && elevation.abs() <= 89.0) {
            bail!(
                "elevation {elevation}° must lie in [-89, 89] (at ±90 the view is along the up axis)"
            );
        }
        Ok(PictureOptions {
            view,
            rejected,
            intrinsics: Intrinsics::from_fov_x(FOV_X_DEGREES, width, height)?,
        })
    }
}

/// Which target source a query uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SourceChoice {
    /// `[targets] source` (labels when the config leaves it out).
    #[default]
    Configured,
    /// The one the `[targets]` inputs and the scene point to ([`inferred_source`]): what
    /// `splatraj query` does without `--source`.
    FromInputs,
}

/// How errors name a `[targets]` key.
#[derive(Debug, Clone, Copy)]
pub enum KeyNaming {
    /// As a config file writes it (`targets.phrases`), after the config's name.
    Config,
    /// As the command-line option that sets it (`--phrases`: the function names it, e.g.
    /// [`option_of_key`]), after the scene's name and the source.
    Options(fn(&str) -> String),
}

/// A query against a config's scene and target source: `[scene]`, and `[targets]` (the
/// source, built-in or registered, with its keys, text encoder and `[targets.selection]`),
/// read and built as `splatraj run` reads and builds them.
#[derive(Debug, Clone)]
pub struct ConfigQuery {
    /// The picture; a view without `up` takes the config's world up (`[scene] up`, the demo
    /// room's, or the guess), as runs do.
    pub picture: PictureOptions,
    /// The backend; `None`: the config's `backend`.
    pub backend: Option<BackendKind>,
    /// The configured source, or the one the inputs point to.
    pub source: SourceChoice,
    /// How errors name the keys.
    pub naming: KeyNaming,
}

impl ConfigQuery {
    /// Loads `config`'s scene and builds its target source from the sources of `extensions`
    /// (paths relative to the config's folder), ready to find any number of queries. Errors
    /// name the config file and the key (`targets.custom.legaussians.codebook`), or the
    /// option ([`KeyNaming::Options`]).
    pub fn prepare(&self, config: &Config, extensions: &Extensions) -> Result<PreparedQueries> {
        let device = self.backend.unwrap_or(config.backend).device()?;
        let (scene, scene_name) = load_scene(config)?;
        let mut config = config.clone();
        if self.source == SourceChoice::FromInputs {
            let query = config.queries.first().map_or("", |q| q.text.as_str());
            config.targets.source = inferred_source(&config.targets, &scene, &scene_name, query)?;
        }
        let kind = config.targets.source.clone();
        let key: &dyn Fn(&str) -> String = match &self.naming {
            KeyNaming::Config => &crate::config::targets_key,
            KeyNaming::Options(name) => name,
        };
        let at = match self.naming {
            KeyNaming::Config => format!("config {}", config.path.display()),
            KeyNaming::Options(_) => format!("{scene_name} ({kind} source)"),
        };
        // A selection key as the user set it: its config key, or its flag (`--top-fraction`;
        // flags are spelt with dashes), or `--set` for a key without a flag.
        let selection_key = |k: &str| match &self.naming {
            KeyNaming::Config => format!("targets.selection.{k}"),
            KeyNaming::Options(name) => match name(k) {
                flag if flag.starts_with("--set") => format!("--set targets.selection.{k}"),
                flag => flag,
            },
        };
        config
            .targets
            .selection
            .validate_named(&selection_key)
            .map_err(|e| anyhow!("{at}: {e}"))?;
        let source =
            crate::prepare::grounding::build_source(&config, scene.len(), &device, extensions, key)
                .map_err(|e| anyhow!("{at}: {e:#}"))?;
        // The config's up (or the demo room's, or the capture's cameras') as runs take it;
        // else the picture guesses it by the same rule and says so.
        let mut picture = self.picture.clone();
        let mut up_from = None;
        if picture.view.up.is_none() {
            let resolved = crate::prepare::scene_up::scene_up(&config, &scene)
                .map_err(|e| anyhow!("{at}: {e:#}"))?;
            if resolved.source != UpSource::Guess {
                picture.view.up = Some(resolved.up);
                up_from = Some(resolved.source.name());
            }
        }
        Ok(PreparedQueries {
            scene,
            scene_name,
            source,
            kind,
            selection: config.targets.selection,
            picture,
            up_from,
            device,
        })
    }
}

/// A config's scene and built source, ready to answer queries ([`ConfigQuery::prepare`]).
pub struct PreparedQueries {
    scene: Scene,
    scene_name: String,
    source: Box<dyn TargetSource>,
    kind: SourceKind,
    selection: SelectionOptions,
    picture: PictureOptions,
    /// Where the picture's up came from when the config decided it (the picture's camera
    /// only sees a given up).
    up_from: Option<&'static str>,
    device: Device,
}

impl PreparedQueries {
    /// Finds and draws `query` ([`find_and_draw`]); writes nothing.
    pub fn find(&self, query: &str) -> Result<QueryOutcome> {
        let grounding = Grounding {
            scene: &self.scene,
            scene_name: &self.scene_name,
            source: self.source.as_ref(),
            kind: self.kind.clone(),
        };
        let mut outcome = find_and_draw(
            &grounding,
            query,
            &self.selection,
            &self.picture,
            &self.device,
        )?;
        if let Some(from) = self.up_from {
            outcome.camera.up_from = from;
        }
        Ok(outcome)
    }
}

/// One text a config grounds through its target source.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigQueryText {
    /// Index of its `[[queries]]` entry.
    pub window: usize,
    /// For a group shot, the index of the object in `shot.objects`.
    pub object: Option<usize>,
    /// The text.
    pub text: String,
}

impl ConfigQueryText {
    /// The config key that holds it (`queries.0.text`, `queries.2.shot.objects.1`).
    pub fn key(&self) -> String {
        match self.object {
            None => format!("queries.{}.text", self.window),
            Some(j) => format!("queries.{}.shot.objects.{j}", self.window),
        }
    }
}

/// The texts `config` grounds through its target source, in window order: each
/// `[[queries]] text`, or for a group shot each of its objects. Queries with a `mask` file do
/// not use the source and are left out.
pub fn config_query_texts(config: &Config) -> Vec<ConfigQueryText> {
    let mut texts = Vec::new();
    for (window, q) in config.queries.iter().enumerate() {
        if q.mask.is_some() {
            continue;
        }
        match &q.shot {
            Some(ShotSpec::Group(group)) => texts.extend(group.objects.iter().enumerate().map(
                |(j, text)| ConfigQueryText {
                    window,
                    object: Some(j),
                    text: text.clone(),
                },
            )),
            _ => texts.push(ConfigQueryText {
                window,
                object: None,
                text: q.text.clone(),
            }),
        }
    }
    texts
}

/// A graded query whose selection failed (nothing above the thresholds, no cluster), with
/// the explanation of its relevancy for the caller to show.
#[derive(Debug, Clone)]
pub struct SelectionFailed {
    /// The error, naming the scene, the source and the query.
    pub message: String,
    /// The relevancy over all Gaussians, thresholds and most relevant groups.
    pub explanation: Explanation,
}

impl std::fmt::Display for SelectionFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for SelectionFailed {}

/// What [`find_and_draw`] found and drew.
#[derive(Debug, Clone)]
pub struct QueryOutcome {
    /// The scene's name (its file, or `demo (…)`).
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// The source that grounded the query.
    pub source: SourceKind,
    /// The selection.
    pub target: Target,
    /// Why it was found: the relevancy over all Gaussians (graded sources only).
    pub explanation: Option<Explanation>,
    /// The picture's camera.
    pub camera: CameraReport,
    /// `query.png`: the RGB render with the selection tinted magenta (and the dropped
    /// candidates cyan with [`RejectedView::Tinted`]).
    pub png: Vec<u8>,
    /// Share of the picture's pixels where the selection dominates (mask > 0.5).
    pub highlighted_share: f64,
}

/// What `query --json` prints (and, as text, `query`).
#[derive(Debug, Clone, Serialize)]
pub struct QueryReport {
    /// The scene file.
    pub scene: String,
    /// The source's name.
    pub source: String,
    /// The query as given.
    pub query: String,
    /// What the query matched (label name, phrase, region name).
    pub name: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// Gaussians selected.
    pub count: usize,
    /// `count / gaussians`.
    pub fraction: f64,
    /// Gaussians above the thresholds, before clustering.
    pub candidates: usize,
    /// How the candidates were clustered (`null`: not clustered).
    pub clustering: Option<ClusteringSummary>,
    /// Every cluster, largest relevancy mass first: the kept one(s) and the runner-ups.
    pub clusters: Vec<Cluster>,
    /// Candidates in no cluster.
    pub noise: usize,
    /// Candidates left out (runner-up clusters and noise).
    pub rejected: usize,
    /// Relevancy at the percentile, for graded sources.
    pub percentile_threshold: Option<f32>,
    /// Spread of the relevancy over the selected Gaussians only (the explanation has it over
    /// all of them).
    pub selected_relevancy: Spread,
    /// The relevancy over all Gaussians, thresholds and most relevant groups (graded sources).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub explanation: Option<Explanation>,
    /// Robust centre of the selection.
    pub centre: [f32; 3],
    /// Robust extent of the selection.
    pub extent: [f32; 3],
    /// The picture's camera.
    pub camera: CameraReport,
    /// Share of the picture's pixels where the selection dominates (mask > 0.5).
    pub highlighted_share: f64,
    /// Where the picture was written.
    pub image: String,
    /// Doubts about the selection, each naming the query.
    pub warnings: Vec<String>,
    /// What the source said about how it matched (a selection file's matched share).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// The source `targets`' inputs point to (the scene's own data deciding the rest), for a query
/// that names none: `region` with a region, `langsplat` with latents or a checkpoint,
/// `lifted` with CLIP weights and nothing else to score them against, `features` with phrase
/// or feature inputs, else `labels` when the scene has labels. Inputs of another source are
/// refused when the source is built, as is a source without the inputs it needs.
pub fn inferred_source(
    targets: &TargetsConfig,
    scene: &Scene,
    scene_name: &str,
    query: &str,
) -> Result<SourceKind> {
    use SourceKind::{Features, Labels, Langsplat, Lifted, Region};
    let has = |key: &str| targets.keys.contains_key(key);
    let text_options = TextKeys::keys().iter().any(|k| has(k));
    Ok(match () {
        () if has("regions") => Region,
        () if has("latents") || has("checkpoint") => Langsplat,
        // CLIP weights and nothing to score them against: the field is lifted from renders.
        () if has("text_encoder")
            && !has("phrases")
            && !has("features")
            && scene.extras.features.is_none() =>
        {
            Lifted
        }
        () if text_options || has("features") => Features,
        () if scene.extras.labels.is_some() => Labels,
        () if scene.extras.features.is_some() => bail!(
            "{scene_name} has per-Gaussian feature vectors but no labels: give a phrase table \
             with --phrases TABLE (.json, .npy with --phrase-names, or .safetensors) to query \
             them, or --box/--sphere for a region"
        ),
        () => bail!(
            "{scene_name} has neither labels nor feature vectors, so there is nothing to match \
             {query:?} against: give a label sidecar with --labels SIDECAR.json, feature vectors \
             with --features SIDECAR.npy and a phrase table with --phrases TABLE, or a region \
             with --box MINX,MINY,MINZ,MAXX,MAXY,MAXZ or --sphere CX,CY,CZ,R"
        ),
    })
}

/// A scene and the target source that grounds queries in it.
#[derive(Debug, Clone)]
pub struct Grounding<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// Its name for messages (the file).
    pub scene_name: &'a str,
    /// The source, built.
    pub source: &'a dyn TargetSource,
    /// Its kind, as configs name it (`custom.gaussian_grouping`).
    pub kind: SourceKind,
}

/// Grounds `query` in `grounding`'s scene through its source with `selection`, explains a
/// graded relevancy (before selecting, so that a query that selects nothing says why:
/// [`SelectionFailed`]) and draws the picture on `device`; writes nothing.
pub fn find_and_draw(
    grounding: &Grounding,
    query: &str,
    selection: &SelectionOptions,
    picture: &PictureOptions,
    device: &Device,
) -> Result<QueryOutcome> {
    let Grounding {
        scene,
        scene_name,
        source,
        ..
    } = *grounding;
    if scene.is_empty() {
        bail!("{scene_name} holds no Gaussian: there is nothing to select");
    }
    let in_scene = || format!("{scene_name} ({} source)", grounding.kind);
    let relevancy = source.relevancy(scene, query).with_context(in_scene)?;
    let explanation = explain(scene, query, &relevancy, selection)?;
    let target = select(scene, query, &relevancy, selection).map_err(|e| {
        let message = format!("{}: {e}", in_scene());
        match explanation.clone() {
            Some(explanation) => anyhow!(SelectionFailed {
                message,
                explanation
            }),
            None => anyhow!(message),
        }
    })?;
    let k = &picture.intrinsics;
    let uploaded = DeviceScene::new(scene, device, Precision::F32.dtype());
    let (pose, camera) = diagnostic_camera(scene, &uploaded, &target, k, picture.view)?;
    let (png, highlighted_share) = match picture.rejected {
        RejectedView::Hidden => highlighted_picture(&uploaded, &target, &pose, k)?,
        RejectedView::Tinted => picture_with_rejected(&uploaded, &target, &pose, k)?,
    };
    Ok(QueryOutcome {
        scene: scene_name.to_string(),
        gaussians: scene.len(),
        source: grounding.kind.clone(),
        target,
        explanation,
        camera,
        png,
        highlighted_share,
    })
}

impl QueryOutcome {
    /// The report, its picture written to `image`.
    pub fn report(&self, image: &Path) -> QueryReport {
        let t = &self.target;
        let gaussians = self.gaussians;
        QueryReport {
            scene: self.scene.clone(),
            source: self.source.name(),
            query: t.query.clone(),
            name: t.name.clone(),
            gaussians,
            count: t.count,
            fraction: t.count as f64 / gaussians as f64,
            candidates: t.candidates,
            clustering: t.clustering.clone(),
            clusters: t.clusters.clone(),
            noise: t.noise,
            rejected: t.rejected.len(),
            percentile_threshold: t.percentile_threshold,
            selected_relevancy: t.relevancy_spread,
            explanation: self.explanation.clone(),
            centre: t.centre,
            extent: t.extent,
            camera: self.camera.clone(),
            highlighted_share: self.highlighted_share,
            image: image.display().to_string(),
            warnings: t.warnings.clone(),
            notes: t.notes.clone(),
        }
    }
}

/// The RGB render at `pose` with the dropped candidates of `target` tinted [`REJECTED_RGB`]
/// and its selection magenta over them, as PNG bytes, and the share of pixels where the
/// selection dominates.
pub fn picture_with_rejected(
    scene: &DeviceScene,
    target: &Target,
    pose: &Pose,
    k: &Intrinsics,
) -> Result<(Vec<u8>, f64)> {
    let request = RenderRequest {
        alpha: AlphaChannel::Dropped,
        ..RenderRequest::new(
            *k,
            vec![
                Channel::Rgb,
                Channel::Mask(target.mask.clone()),
                Channel::Mask(target.rejected_mask()),
            ],
        )
    };
    let pixels = to_host(render_poses(scene, &[*pose], &request)?.images)?;
    // [H·W·5] (R, G, B, selected, rejected) → [H·W·4] with the rejected tint blended in.
    let tinted: Vec<f64> = pixels
        .chunks_exact(5)
        .flat_map(|px| {
            let a = REJECTED_STRENGTH * px[4].clamp(0.0, 1.0);
            let rgb: [f64; 3] =
                std::array::from_fn(|c| px[c].clamp(0.0, 1.0) * (1.0 - a) + a * REJECTED_RGB[c]);
            [rgb[0], rgb[1], rgb[2], px[3]]
        })
        .collect();
    highlighted_png(&tinted, k)
}

/// The command-line option that sets a `[targets]` key, for error messages.
pub fn option_of_key(key: &str) -> String {
    let head = key.split('.').next().unwrap_or(key);
    match head {
        "synonyms" => "--synonym".to_string(),
        "regions" if key.ends_with(".selection") => "--selection".to_string(),
        "regions" => "--box/--sphere/--selection".to_string(),
        "negatives" => "--negative".to_string(),
        // A registered source's table: `custom.<name>` is the --source value; a key inside it
        // was set by its own option (`--text-encoder`) where the command has one.
        "custom" => match key.splitn(3, '.').nth(2) {
            Some(inner) => format!("--{}", inner.replace('_', "-")),
            None => format!("--source {key}"),
        },
        // The lifted source's own table comes from --source-key items.
        "lifted" => match key.split_once('.') {
            Some((_, rest)) => format!("--source-key {rest}"),
            None => "--source-key".to_string(),
        },
        other => format!("--{}", other.replace('_', "-")),
    }
}

/// `--source-key KEY=VALUE` items (values parsed as TOML, a bare word as a string; dotted
/// keys make subtables, `label_names.34=bear`) into a registered source's table.
pub fn parse_source_keys(items: &[String]) -> Result<toml::Table> {
    let mut table = toml::Table::new();
    for item in items {
        apply_assignment(&mut table, item, "--source-key")?;
    }
    Ok(table)
}

/// `--box MINX,MINY,MINZ,MAXX,MAXY,MAXZ` or `--sphere CX,CY,CZ,R` (at most one), parsed and
/// checked.
pub fn parse_region(region_box: Option<&str>, sphere: Option<&str>) -> Result<Option<RegionSpec>> {
    let (spec, key) = match (region_box, sphere) {
        (Some(text), _) => (
            RegionSpec::Box(parse_floats::<6>(
                text,
                "--box",
                "MINX,MINY,MINZ,MAXX,MAXY,MAXZ",
            )?),
            "--box",
        ),
        (None, Some(text)) => (
            RegionSpec::Sphere(parse_floats::<4>(text, "--sphere", "CX,CY,CZ,R")?),
            "--sphere",
        ),
        (None, None) => return Ok(None),
    };
    if let Some(region) = spec.shape() {
        region.validate(key).map_err(|e| anyhow!("{e}"))?;
    }
    Ok(Some(spec))
}

/// `N` comma-separated finite numbers; errors name `option` and the expected `form`.
pub fn parse_floats<const N: usize>(text: &str, option: &str, form: &str) -> Result<[f32; N]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != N {
        bail!(
            "{option} {text:?}: expected {N} comma-separated numbers {form}, got {}",
            parts.len()
        );
    }
    let mut values = [0.0f32; N];
    for (v, p) in values.iter_mut().zip(&parts) {
        *v = p
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| anyhow!("{option} {text:?}: {p:?} is not a finite number ({form})"))?;
    }
    Ok(values)
}

/// `X,Y,Z` as a unit direction; errors name `option`.
pub fn parse_direction(text: &str, option: &str) -> Result<[f64; 3]> {
    let [x, y, z] = parse_floats::<3>(text, option, "X,Y,Z")?.map(f64::from);
    let length = (x * x + y * y + z * z).sqrt();
    if !(length.is_finite() && length > 0.0) {
        bail!("{option} {text:?}: must be a finite, non-zero direction");
    }
    Ok([x / length, y / length, z / length])
}

/// `NAME=ALT1,ALT2` items into label name → synonyms (repeated names merge).
pub fn parse_synonyms(items: &[String]) -> Result<BTreeMap<String, Vec<String>>> {
    let mut synonyms: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for item in items {
        let Some((name, alts)) = item.split_once('=') else {
            bail!("--synonym {item:?}: expected NAME=ALT1,ALT2 (e.g. \"red mug=cup,coffee mug\")");
        };
        let name = name.trim();
        let alts: Vec<String> = alts
            .split(',')
            .map(str::trim)
            .filter(|a| !a.is_empty())
            .map(String::from)
            .collect();
        if name.is_empty() || alts.is_empty() {
            bail!(
                "--synonym {item:?}: both the label name and at least one synonym are needed (NAME=ALT1,ALT2)"
            );
        }
        synonyms.entry(name.to_string()).or_default().extend(alts);
    }
    Ok(synonyms)
}

fn fmt3(v: [f32; 3]) -> String {
    format!("({:.4}, {:.4}, {:.4})", v[0], v[1], v[2])
}

impl QueryReport {
    /// The human-readable report, one fact a line (the warnings are the caller's to show).
    pub fn text(&self) -> String {
        let r = self;
        let mut s = String::new();
        s.push_str(&format!(
            "query {:?} ({} source) matched {:?} in {}\n",
            r.query, r.source, r.name, r.scene
        ));
        s.push_str(&format!(
            "selected: {} of {} Gaussians ({:.3}%)\n",
            r.count,
            r.gaussians,
            100.0 * r.fraction
        ));
        for note in &r.notes {
            s.push_str(&format!("{note}\n"));
        }
        let threshold = r
            .percentile_threshold
            .map_or(String::new(), |t| format!(" (percentile threshold {t:.4})"));
        s.push_str(&format!("candidates: {}{threshold}\n", r.candidates));
        match &r.clustering {
            None => s.push_str("clustering: none\n"),
            Some(c) => s.push_str(&format!(
                "clustering: {}, min_points {}, radius {:.4} (median; {:.4} to {:.4})\n",
                c.method, c.min_points, c.eps, c.eps_range[0], c.eps_range[1]
            )),
        }
        let (kept, runner_ups): (Vec<&Cluster>, Vec<&Cluster>) =
            r.clusters.iter().partition(|c| c.kept);
        let sizes: Vec<String> = kept.iter().map(|c| c.count.to_string()).collect();
        let mass: f64 = kept.iter().map(|c| c.relevancy_mass).sum();
        s.push_str(&format!(
            "kept: {} cluster(s) [{}], relevancy mass {mass:.1}\n",
            kept.len(),
            sizes.join(", ")
        ));
        s.push_str(&format!(
            "dropped: {} candidates ({} in {} runner-up cluster(s), {} noise)\n",
            r.rejected,
            runner_ups.iter().map(|c| c.count).sum::<usize>(),
            runner_ups.len(),
            r.noise
        ));
        for c in runner_ups.iter().take(LISTED_RUNNER_UPS) {
            s.push_str(&format!(
                "  runner-up: {} Gaussians, relevancy mass {:.1}, centre {}, extent {}\n",
                c.count,
                c.relevancy_mass,
                fmt3(c.centre),
                fmt3(c.extent)
            ));
        }
        if runner_ups.len() > LISTED_RUNNER_UPS {
            s.push_str(&format!(
                "  and {} smaller runner-ups\n",
                runner_ups.len() - LISTED_RUNNER_UPS
            ));
        }
        let spread = &r.selected_relevancy;
        s.push_str(&format!(
            "relevancy of the {} selected Gaussians: min {:.4}, median {:.4}, max {:.4}\n",
            r.count, spread.min, spread.median, spread.max
        ));
        if let Some(x) = &r.explanation {
            s.push_str(&x.text());
        }
        s.push_str(&format!("centre: {}\n", fmt3(r.centre)));
        s.push_str(&format!("extent: {}\n", fmt3(r.extent)));
        let c = &r.camera;
        s.push_str(&format!(
            "camera: eye ({:.4}, {:.4}, {:.4}), distance {:.4}, up ({:.2}, {:.2}, {:.2}) ({}), \
             azimuth {:.0}°, elevation {:.0}°\n",
            c.eye[0],
            c.eye[1],
            c.eye[2],
            c.distance,
            c.up[0],
            c.up[1],
            c.up[2],
            c.up_from,
            c.azimuth_degrees,
            c.elevation_degrees
        ));
        s.push_str(&format!(
            "image: {} ({}×{}, {:.1}% of the pixels highlighted)\n",
            r.image,
            c.width,
            c.height,
            100.0 * r.highlighted_share
        ));
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synonyms_parse_and_merge() {
        let s = parse_synonyms(&["red mug=cup, mug".into(), "red mug=beaker".into()]).unwrap();
        assert_eq!(s["red mug"], vec!["cup", "mug", "beaker"]);
        assert!(parse_synonyms(&["no equals".into()]).is_err());
        assert!(parse_synonyms(&["=x".into()]).is_err());
    }

    #[test]
    fn floats_parse_with_counts_checked() {
        assert_eq!(
            parse_floats::<4>("1, 2,3,0.5", "--sphere", "").unwrap(),
            [1.0, 2.0, 3.0, 0.5]
        );
        assert!(parse_floats::<4>("1,2,3", "--sphere", "").is_err());
        assert!(parse_floats::<4>("1,2,3,nan", "--sphere", "").is_err());
    }
}
