//! The arguments of `splatraj query`, and how they become the library's [`QueryRequest`] and
//! [`PictureOptions`].

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::{Context, Result};
use clap::Args;
use splatraj::experiment::query::{
    PictureOptions, QueryRequest, RejectedView, parse_direction, parse_region, parse_source_keys,
    parse_synonyms,
};
use splatraj::experiment::views::ViewOptions;
use splatraj_render::backend::BackendKind;
use splatraj_semantic::selection::{DEFAULT_FLOOR, DEFAULT_TOP_FRACTION};
use splatraj_semantic::sources::TextKeys;
use splatraj_semantic::{Activation, ClusterOptions, SelectionOptions, SourceKind};

use crate::cli::ReadArgs;

/// Default elevation of the viewing direction above the horizontal, degrees.
const DEFAULT_ELEVATION_DEGREES: f64 = 30.0;
/// Name of the picture written into `--out`.
pub(super) const IMAGE_NAME: &str = "query.png";

/// Options that set the scene or the source, which a run config sets instead.
const SET_BY_CONFIG: [&str; 20] = [
    "scene",
    "labels",
    "drop_invalid",
    "source",
    "source_key",
    "synonym",
    "region_box",
    "sphere",
    "features",
    "phrases",
    "phrase_names",
    "text_encoder",
    "text_activation",
    "negative",
    "temperature",
    "latents",
    "checkpoint",
    "top_fraction",
    "floor",
    "no_cluster",
];

/// Arguments of `splatraj query`.
#[derive(Debug, Args)]
pub struct QueryArgs {
    /// A run config: its `[scene]` and `[targets]` (source, built-in or registered, with its
    /// keys and text encoder; `[targets.selection]`) are read and built as `splatraj run`
    /// builds them, instead of the scene and source options.
    #[arg(long, value_name = "RUN.toml", conflicts_with_all = SET_BY_CONFIG)]
    pub(super) config: Option<PathBuf>,
    /// With --config: override a config key, e.g. `targets.selection.floor=0.6`
    /// (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE", requires = "config")]
    pub(super) set: Vec<String>,
    /// Scene file (INRIA PLY, compressed PLY or SPZ).
    #[arg(long, required_unless_present = "config")]
    pub(super) scene: Option<PathBuf>,
    #[command(flatten)]
    pub(super) read: ReadArgs,
    /// What to look for: a label name or id (labels, custom.gaussian_grouping), any name
    /// (region), a phrase (features, langsplat and the registered language fields). With
    /// --config and no --query: every query of the config (group shots' objects included),
    /// pictured as query-N.png (query-N-M.png for a group's objects), N the `[[queries]]`
    /// entry from 1.
    #[arg(long, required_unless_present = "config")]
    pub(super) query: Option<String>,
    // Boxed: the source options would make this the largest command by far.
    #[command(flatten)]
    source_options: Box<SourceArgs>,
    /// Also tint, in cyan, the candidates the clustering dropped (runner-up clusters and
    /// outliers) in query.png.
    #[arg(long)]
    show_rejected: bool,
    /// Output folder for query.png (created if missing).
    #[arg(long, default_value = ".")]
    pub(super) out: PathBuf,
    /// Picture width in pixels.
    #[arg(long, default_value_t = 320)]
    pub(super) width: usize,
    /// Picture height in pixels.
    #[arg(long, default_value_t = 240)]
    pub(super) height: usize,
    /// Elevation of the viewing direction above the horizontal, degrees (the camera looks
    /// down at the selection from this angle).
    #[arg(long, default_value_t = DEFAULT_ELEVATION_DEGREES, allow_negative_numbers = true)]
    elevation: f64,
    /// Keep the preferred view even when the selection is hidden in it (by default other
    /// azimuths and the view from below are tried, and the one showing most of the selection
    /// is used when the preferred one shows less than half as much).
    #[arg(long)]
    fixed_view: bool,
    /// World up of the scene, `X,Y,Z` (e.g. `0,-1,0` for y-down captures); by default the
    /// config's `[scene] up`, else guessed from the scene.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    up: Option<String>,
    /// Tensor backend: flex (CPU), ndarray or wgpu, among those compiled in [default: the
    /// config's, else flex].
    #[arg(long, value_parser = BackendKind::from_str)]
    pub(super) backend: Option<BackendKind>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub(super) json: bool,
}

/// The scene's target source and selection, from the command line (a run config's
/// `[targets]` sets them instead).
#[derive(Debug, Args)]
pub(super) struct SourceArgs {
    /// Target source: labels, region, features, langsplat, or a registered one,
    /// custom.<name> (custom.feature3dgs, custom.opengaussian, custom.gaussian_grouping,
    /// custom.legaussians; its keys with --source-key); by default `region` when
    /// --box/--sphere is given, `langsplat` when --latents or --checkpoint is given,
    /// `features` when --phrases or --features is given, else `labels` when the scene has
    /// labels.
    #[arg(long, value_parser = SourceKind::from_str)]
    source: Option<SourceKind>,
    /// custom.<name>: a key of the source's table, as `[targets.custom.<name>]` holds it
    /// (e.g. `classifier=classifier.pth`; paths relative to the working directory;
    /// repeatable).
    #[arg(long = "source-key", value_name = "KEY=VALUE")]
    source_key: Vec<String>,
    /// labels, custom.gaussian_grouping: synonyms of a label, `NAME=ALT1,ALT2` (repeatable).
    #[arg(long, value_name = "NAME=ALT1,ALT2")]
    synonym: Vec<String>,
    /// region: an axis-aligned box in world coordinates.
    #[arg(
        long = "box",
        value_name = "MINX,MINY,MINZ,MAXX,MAXY,MAXZ",
        conflicts_with = "sphere",
        allow_hyphen_values = true
    )]
    region_box: Option<String>,
    /// region: a ball in world coordinates.
    // Coordinates may start with '-': take the next word as the value, not as a flag.
    #[arg(long, value_name = "CX,CY,CZ,R", allow_hyphen_values = true)]
    sphere: Option<String>,
    /// features: per-Gaussian feature vectors, `[N, D]` (.npy or .safetensors); by default
    /// the scene's own feature properties.
    #[arg(long, value_name = "SIDECAR")]
    features: Option<PathBuf>,
    /// features, langsplat, custom.<name>: phrase table of text embeddings (.json, .npy with
    /// --phrase-names, or .safetensors).
    #[arg(long, value_name = "TABLE")]
    phrases: Option<PathBuf>,
    /// features, langsplat, custom.<name>: phrases of an .npy (or .safetensors) table, one
    /// per line in row order.
    #[arg(long, value_name = "FILE.txt")]
    phrase_names: Option<PathBuf>,
    /// features, langsplat, custom.<name>: CLIP text-tower weights (open_clip_model.safetensors,
    /// open_clip_pytorch_model.bin): the query can then be any phrase.
    #[arg(long, value_name = "FILE")]
    text_encoder: Option<PathBuf>,
    /// features, langsplat, custom.<name>: the text tower's activation, gelu (open_clip) or
    /// quick-gelu (OpenAI) [default: open_clip_config.json beside the weights, else gelu].
    #[arg(long, value_name = "gelu|quick-gelu", value_parser = Activation::from_str)]
    text_activation: Option<Activation>,
    /// features, langsplat, custom.<name>: canonical negative phrase (repeatable; default:
    /// object, things, stuff, texture).
    #[arg(long)]
    negative: Vec<String>,
    /// features, langsplat, custom.<name>: temperature of the relevancy softmax [default: 10].
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
    /// Keep every Gaussian above the thresholds: no density clustering (features).
    #[arg(long)]
    no_cluster: bool,
}

impl QueryArgs {
    /// The picture these options ask for.
    pub(super) fn picture(&self) -> Result<PictureOptions> {
        let view = ViewOptions {
            elevation_degrees: self.elevation,
            search: !self.fixed_view,
            up: self
                .up
                .as_deref()
                .map(|up| parse_direction(up, "--up"))
                .transpose()?,
        };
        let rejected = if self.show_rejected {
            RejectedView::Tinted
        } else {
            RejectedView::Hidden
        };
        PictureOptions::new(self.width, self.height, view, rejected)
            .context("the picture (--width, --height, --elevation)")
    }

    /// The request the scene and source options make: they fill the same `[targets]` table a
    /// run config holds (paths relative to the working directory).
    pub(super) fn request(&self, picture: PictureOptions) -> Result<QueryRequest> {
        let options = &self.source_options;
        Ok(QueryRequest {
            query: self
                .query
                .clone()
                .context("--query is needed without --config")?,
            source: options.source.clone(),
            source_keys: parse_source_keys(&options.source_key)?,
            synonyms: parse_synonyms(&options.synonym)?,
            region: parse_region(options.region_box.as_deref(), options.sphere.as_deref())?,
            features: options.features.clone(),
            text: TextKeys {
                phrases: options.phrases.clone(),
                phrase_names: options.phrase_names.clone(),
                text_encoder: options.text_encoder.clone(),
                text_activation: options.text_activation,
                negatives: (!options.negative.is_empty()).then(|| options.negative.clone()),
                temperature: options.temperature,
            },
            latents: options.latents.clone(),
            checkpoint: options.checkpoint.clone(),
            selection: SelectionOptions {
                top_fraction: options.top_fraction,
                floor: options.floor,
                cluster: (!options.no_cluster).then(ClusterOptions::default),
            },
            picture,
        })
    }
}
