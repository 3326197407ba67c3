//! `splatraj query`: what a semantic query selects in a scene, as text (or JSON) and as a
//! picture.
//!
//! The query goes through one of the semantic sources (labels, a region, per-Gaussian
//! language features scored against a phrase table, or LangSplat latents decoded by the
//! scene's autoencoder checkpoint and then scored as features) and the selection (percentile,
//! floor, DBSCAN) of `splatraj-semantic`. The command prints the counts, clusters, relevancy spread,
//! centre and extent, and renders `query.png`: the RGB render from a camera that looks at the
//! selection's centre from 30° above the horizontal (`--elevation`), at a distance where its extent fills
//! about a third of the frame, with the selected Gaussians tinted magenta. Every input is read
//! and checked, and the picture rendered, before the file is written (whole or not at all).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{Context, Result, anyhow, bail};
use clap::{Args, ValueEnum};
use serde::Serialize;
use splatraj::experiment::outputs::write_bytes;
use splatraj::experiment::views::{
    CameraReport, FOV_X_DEGREES, ViewOptions, diagnostic_camera, highlighted_picture,
};
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::camera::Intrinsics;
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_semantic::selection::{DEFAULT_FLOOR, DEFAULT_TOP_FRACTION};
use splatraj_semantic::{
    ClusterOptions, Region, RegionSpec, SelectionOptions, TargetsConfig, find_target,
};

use crate::cli::ReadArgs;

/// Default elevation of the viewing direction above the horizontal, degrees.
const DEFAULT_ELEVATION_DEGREES: f64 = 30.0;
/// Name of the picture written into `--out`.
const IMAGE_NAME: &str = "query.png";

/// Arguments of `splatraj query`.
#[derive(Debug, Args)]
pub struct QueryArgs {
    /// Scene file (INRIA PLY, compressed PLY or SPZ).
    #[arg(long)]
    scene: PathBuf,
    #[command(flatten)]
    read: ReadArgs,
    /// What to look for: a label name or id (labels), any name (region), a phrase of the
    /// phrase table (features).
    #[arg(long)]
    query: String,
    /// Target source; by default `region` when --box/--sphere is given, `langsplat` when
    /// --latents or --checkpoint is given, `features` when --phrases or --features is given,
    /// else `labels` when the scene has labels.
    #[arg(long, value_enum)]
    source: Option<SourceKind>,
    /// labels: synonyms of a label, `NAME=ALT1,ALT2` (repeatable).
    #[arg(long, value_name = "NAME=ALT1,ALT2")]
    synonym: Vec<String>,
    /// region: an axis-aligned box in world coordinates.
    #[arg(
        long = "box",
        value_name = "MINX,MINY,MINZ,MAXX,MAXY,MAXZ",
        conflicts_with = "sphere"
    )]
    region_box: Option<String>,
    /// region: a ball in world coordinates.
    #[arg(long, value_name = "CX,CY,CZ,R")]
    sphere: Option<String>,
    /// features: per-Gaussian feature vectors, `[N, D]` (.npy or .safetensors); by default
    /// the scene's own feature properties.
    #[arg(long, value_name = "SIDECAR")]
    features: Option<PathBuf>,
    /// features, langsplat: phrase table of text embeddings (.json, .npy with
    /// --phrase-names, or .safetensors).
    #[arg(long, value_name = "TABLE")]
    phrases: Option<PathBuf>,
    /// features, langsplat: phrases of an .npy (or .safetensors) table, one per line in row
    /// order.
    #[arg(long, value_name = "FILE.txt")]
    phrase_names: Option<PathBuf>,
    /// features, langsplat: canonical negative phrase (repeatable; default: object, things,
    /// stuff, texture).
    #[arg(long)]
    negative: Vec<String>,
    /// features, langsplat: temperature of the relevancy softmax [default: 10].
    #[arg(long)]
    temperature: Option<f32>,
    /// langsplat: per-Gaussian LangSplat latents, `[N, 3]` (.npy), decoded by --checkpoint.
    #[arg(long, value_name = "LATENTS.npy")]
    latents: Option<PathBuf>,
    /// langsplat: the scene's LangSplat autoencoder checkpoint (PyTorch state dict,
    /// e.g. best_ckpt.pth); decoded on --backend's device.
    #[arg(long, value_name = "CKPT.pth")]
    checkpoint: Option<PathBuf>,
    /// Fraction (0, 1] of all Gaussians kept by the relevancy percentile (features).
    #[arg(long, default_value_t = DEFAULT_TOP_FRACTION)]
    top_fraction: f32,
    /// Relevancy a Gaussian must exceed, in [0, 1) (features).
    #[arg(long, default_value_t = DEFAULT_FLOOR)]
    floor: f32,
    /// Keep every Gaussian above the thresholds: no DBSCAN (features).
    #[arg(long)]
    no_cluster: bool,
    /// Output folder for query.png (created if missing).
    #[arg(long, default_value = ".")]
    out: PathBuf,
    /// Picture width in pixels.
    #[arg(long, default_value_t = 320)]
    width: usize,
    /// Picture height in pixels.
    #[arg(long, default_value_t = 240)]
    height: usize,
    /// Elevation of the viewing direction above the horizontal, degrees (the camera looks
    /// down at the selection from this angle).
    #[arg(long, default_value_t = DEFAULT_ELEVATION_DEGREES, allow_negative_numbers = true)]
    elevation: f64,
    /// Keep the preferred view even when the selection is hidden in it (by default other
    /// azimuths and the view from below are tried, and the one showing most of the selection
    /// is used when the preferred one shows less than half as much).
    #[arg(long)]
    fixed_view: bool,
    /// Tensor backend: flex (CPU, default), ndarray or wgpu, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// The target sources on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SourceKind {
    /// Per-Gaussian labels with names.
    Labels,
    /// A box or a sphere (--box, --sphere).
    Region,
    /// Per-Gaussian language features and a phrase table.
    Features,
    /// LangSplat latents decoded by the scene's autoencoder, then as features.
    Langsplat,
}

impl SourceKind {
    fn name(self) -> &'static str {
        self.config().name()
    }

    /// The same kind in the semantic crate's config.
    fn config(self) -> splatraj_semantic::SourceKind {
        match self {
            SourceKind::Labels => splatraj_semantic::SourceKind::Labels,
            SourceKind::Region => splatraj_semantic::SourceKind::Region,
            SourceKind::Features => splatraj_semantic::SourceKind::Features,
            SourceKind::Langsplat => splatraj_semantic::SourceKind::Langsplat,
        }
    }
}

/// What `query --json` prints.
#[derive(Debug, Serialize)]
struct QueryReport {
    scene: String,
    source: SourceKind,
    query: String,
    /// What the query matched (label name, phrase, region name).
    name: String,
    gaussians: usize,
    count: usize,
    fraction: f64,
    candidates: usize,
    clusters: Vec<usize>,
    noise: usize,
    eps: Option<f32>,
    percentile_threshold: Option<f32>,
    relevancy: splatraj_semantic::Spread,
    centre: [f32; 3],
    extent: [f32; 3],
    camera: CameraReport,
    /// Share of the picture's pixels where the selection dominates (mask > 0.5).
    highlighted_share: f64,
    image: String,
}

/// Runs `splatraj query`.
pub fn run(args: QueryArgs) -> Result<()> {
    // Cheap checks first, then the scene and the source, then the render; the file last.
    if args.query.trim().is_empty() {
        bail!("--query is empty: give a label name, a phrase or a region name");
    }
    if args.width == 0 || args.height == 0 {
        bail!(
            "--width and --height must be at least 1 (got {}×{})",
            args.width,
            args.height
        );
    }
    if !(args.elevation.is_finite() && args.elevation.abs() <= 89.0) {
        bail!(
            "--elevation {} must lie in [-89, 89] degrees (at ±90 the view is along the up axis)",
            args.elevation
        );
    }
    let intrinsics = Intrinsics::from_fov_x(FOV_X_DEGREES, args.width, args.height)?;
    let region = parse_region(&args)?;
    let synonyms = parse_synonyms(&args.synonym)?;
    let device = args.backend.device()?;
    let dtype = Precision::F32.dtype();

    let scene = args.read.load(&args.scene)?.scene;
    let kind = choose_source(&args, &scene, region.is_some())?;
    // The command line fills the same `[targets]` table a run config holds, so both build
    // their source through one path; paths stay relative to the working directory.
    let config = TargetsConfig {
        source: kind.config(),
        synonyms,
        regions: region
            .map(|r| BTreeMap::from([(args.query.trim().to_string(), r)]))
            .unwrap_or_default(),
        features: args.features.clone(),
        phrases: args.phrases.clone(),
        phrase_names: args.phrase_names.clone(),
        negatives: (!args.negative.is_empty()).then(|| args.negative.clone()),
        temperature: args.temperature,
        latents: args.latents.clone(),
        checkpoint: args.checkpoint.clone(),
        selection: SelectionOptions {
            top_fraction: args.top_fraction,
            floor: args.floor,
            cluster: (!args.no_cluster).then(ClusterOptions::default),
        },
        label_names: BTreeMap::new(),
    };
    config.selection.validate_as("--")?;
    let options = config.selection;
    let source = config
        .build_named(Path::new(""), &device, &option_of_key)
        .with_context(|| format!("{} ({} source)", args.scene.display(), kind.name()))?;
    let target = find_target(source.as_ref(), &scene, &args.query, &options)
        .with_context(|| format!("{} ({} source)", args.scene.display(), source.kind()))?;

    let uploaded = DeviceScene::new(&scene, &device, dtype);
    let view = ViewOptions {
        elevation_degrees: args.elevation,
        search: !args.fixed_view,
    };
    let (pose, camera) = diagnostic_camera(&scene, &uploaded, &target, &intrinsics, view)?;
    let (png, highlighted_share) = highlighted_picture(&uploaded, &target, &pose, &intrinsics)?;

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    let path = args.out.join(IMAGE_NAME);
    write_bytes(&path, &png)?;

    let report = QueryReport {
        scene: args.scene.display().to_string(),
        source: kind,
        query: target.query.clone(),
        name: target.name.clone(),
        gaussians: scene.len(),
        count: target.count,
        fraction: target.count as f64 / scene.len() as f64,
        candidates: target.candidates,
        clusters: target.clusters.clone(),
        noise: target.noise,
        eps: target.eps,
        percentile_threshold: target.percentile_threshold,
        relevancy: target.relevancy_spread,
        centre: target.centre,
        extent: target.extent,
        camera,
        highlighted_share,
        image: path.display().to_string(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report_text(&report));
    }
    eprintln!(
        "wrote {} ({}×{}, {:.1}% of the pixels highlighted)",
        path.display(),
        intrinsics.width,
        intrinsics.height,
        100.0 * highlighted_share
    );
    Ok(())
}

/// The source asked for, or the one the inputs point to (see `--source`).
fn choose_source(args: &QueryArgs, scene: &Scene, has_region: bool) -> Result<SourceKind> {
    let phrase_options = args.phrases.is_some()
        || args.phrase_names.is_some()
        || !args.negative.is_empty()
        || args.temperature.is_some();
    let langsplat_options = args.latents.is_some() || args.checkpoint.is_some();
    let kind = match args.source {
        Some(kind) => kind,
        None if has_region => SourceKind::Region,
        None if langsplat_options => SourceKind::Langsplat,
        None if phrase_options || args.features.is_some() => SourceKind::Features,
        None if scene.extras.labels.is_some() => SourceKind::Labels,
        None if scene.extras.features.is_some() => {
            bail!(
                "{} has per-Gaussian feature vectors but no labels: give a phrase table with \
                 --phrases TABLE (.json, .npy with --phrase-names, or .safetensors) to query \
                 them, or --box/--sphere for a region",
                args.scene.display()
            )
        }
        None => bail!(
            "{} has neither labels nor feature vectors, so there is nothing to match {:?} \
             against: give a label sidecar with --labels SIDECAR.json, feature vectors with \
             --features SIDECAR.npy and a phrase table with --phrases TABLE, or a region with \
             --box MINX,MINY,MINZ,MAXX,MAXY,MAXZ or --sphere CX,CY,CZ,R",
            args.scene.display(),
            args.query
        ),
    };
    // Options of another source would be silently ignored: refuse them.
    let stray: Vec<&str> = [
        (
            kind != SourceKind::Labels && !args.synonym.is_empty(),
            "--synonym",
        ),
        (kind != SourceKind::Region && has_region, "--box/--sphere"),
        (
            kind != SourceKind::Features && args.features.is_some(),
            "--features",
        ),
        (
            !matches!(kind, SourceKind::Features | SourceKind::Langsplat) && phrase_options,
            "--phrases/--phrase-names/--negative/--temperature",
        ),
        (
            kind != SourceKind::Langsplat && langsplat_options,
            "--latents/--checkpoint",
        ),
    ]
    .into_iter()
    .filter_map(|(bad, name)| bad.then_some(name))
    .collect();
    if !stray.is_empty() {
        bail!(
            "{} do not apply to the {} source (--synonym is for labels, --box/--sphere for \
             region, --features for features, --phrases/--phrase-names/--negative/--temperature \
             for features and langsplat, --latents/--checkpoint for langsplat)",
            stray.join(", "),
            kind.name()
        );
    }
    match kind {
        SourceKind::Region if !has_region => bail!(
            "the region source needs a region: give --box MINX,MINY,MINZ,MAXX,MAXY,MAXZ or \
             --sphere CX,CY,CZ,R"
        ),
        SourceKind::Features | SourceKind::Langsplat if args.phrases.is_none() => bail!(
            "the {} source needs text embeddings: give a phrase table with --phrases TABLE \
             (.json, .npy with --phrase-names, or .safetensors)",
            kind.name()
        ),
        SourceKind::Langsplat if args.latents.is_none() || args.checkpoint.is_none() => bail!(
            "the langsplat source needs the per-Gaussian latents (--latents LATENTS.npy, [N, 3]) \
             and the scene's autoencoder checkpoint (--checkpoint best_ckpt.pth)"
        ),
        _ => {}
    }
    Ok(kind)
}

/// The command-line option that sets a `[targets]` key, for error messages.
fn option_of_key(key: &str) -> String {
    let head = key.split('.').next().unwrap_or(key);
    match head {
        "synonyms" => "--synonym".to_string(),
        "regions" => "--box/--sphere".to_string(),
        "negatives" => "--negative".to_string(),
        other => format!("--{}", other.replace('_', "-")),
    }
}

/// `--box` or `--sphere`, parsed and checked.
fn parse_region(args: &QueryArgs) -> Result<Option<RegionSpec>> {
    let (spec, key) = match (&args.region_box, &args.sphere) {
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
    Region::from(spec)
        .validate(key)
        .map_err(|e| anyhow!("{e}"))?;
    Ok(Some(spec))
}

/// `N` comma-separated finite numbers.
fn parse_floats<const N: usize>(text: &str, option: &str, form: &str) -> Result<[f32; N]> {
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

/// `NAME=ALT1,ALT2` options into label name → synonyms (repeated names merge).
fn parse_synonyms(items: &[String]) -> Result<BTreeMap<String, Vec<String>>> {
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

/// The human-readable report.
fn report_text(r: &QueryReport) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "query {:?} ({} source) matched {:?} in {}\n",
        r.query,
        r.source.name(),
        r.name,
        r.scene
    ));
    s.push_str(&format!(
        "selected: {} of {} Gaussians ({:.3}%)\n",
        r.count,
        r.gaussians,
        100.0 * r.fraction
    ));
    let threshold = r
        .percentile_threshold
        .map_or(String::new(), |t| format!(" (percentile threshold {t:.4})"));
    s.push_str(&format!("candidates: {}{threshold}\n", r.candidates));
    let sizes: Vec<String> = r.clusters.iter().map(|c| c.to_string()).collect();
    let eps = r
        .eps
        .map_or("no DBSCAN".to_string(), |e| format!("DBSCAN eps {e:.4}"));
    s.push_str(&format!(
        "clusters: {} [{}], noise {} ({eps})\n",
        r.clusters.len(),
        sizes.join(", "),
        r.noise
    ));
    s.push_str(&format!(
        "relevancy: min {:.4}, median {:.4}, max {:.4}\n",
        r.relevancy.min, r.relevancy.median, r.relevancy.max
    ));
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
