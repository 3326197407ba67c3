//! The arguments of `splatraj query`, and how they become the library's typed options
//! ([`QueryOptions`]: each scene and source option sets a key of the config) and
//! [`PictureOptions`].

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::{Context, Result};
use clap::Args;
use splatraj::experiment::picking::query::{
    PictureOptions, RejectedView, option_of_key, parse_direction, parse_region, parse_source_keys,
    parse_synonyms,
};
use splatraj::experiment::picking::query_options::{QueryOptions, SelectionKeys, TargetOptions};
use splatraj::experiment::prepare::views::ViewOptions;
use splatraj_render::backend::BackendKind;
use splatraj_semantic::{
    Activation, FeaturesConfig, LabelsConfig, LangsplatConfig, RegionSpec, SourceKind, TextKeys,
};

use crate::cli::ReadArgs;

/// Default elevation of the viewing direction above the horizontal, degrees.
const DEFAULT_ELEVATION_DEGREES: f64 = 30.0;

/// Arguments of `splatraj query`.
#[derive(Debug, Args)]
pub struct QueryArgs {
    /// A run config: its `[scene]` and `[targets]` (source, built-in or registered, with its
    /// keys and text encoder; `[targets.selection]`) are read and built as `splatraj run`
    /// builds them. The scene and source options given override its keys (each sets the key
    /// it sets without a config; paths relative to the working directory), and --set
    /// overrides both.
    #[arg(long, value_name = "RUN.toml")]
    pub(super) config: Option<PathBuf>,
    /// Override a config key, e.g. `targets.selection.floor=0.6` (repeatable), after the
    /// config file and the options; without --config, a key of the config the options make
    /// (`targets.<key>`: any `[targets]` key, also one without an option of its own).
    #[arg(long = "set", value_name = "KEY=VALUE")]
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
    /// entry from 1. With --selection, by default the selection file's name.
    #[arg(long, required_unless_present_any = ["config", "selection"])]
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
    /// region: the splats selected in an editor (SuperSplat: select, then export the
    /// selection), in any scene format, matched to the scene's Gaussians; refused when it is
    /// not part of this scene. Names the region after --query, else after the file.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["region_box", "sphere"])]
    selection: Option<PathBuf>,
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
    /// Fraction (0, 1] of all Gaussians kept by the relevancy percentile (features)
    /// [default: the config's, else 0.02].
    #[arg(long)]
    top_fraction: Option<f32>,
    /// Relevancy a Gaussian must exceed, in [0, 1) (features) [default: the config's, else
    /// 0.5].
    #[arg(long)]
    floor: Option<f32>,
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

    /// The scene and source options, typed: what they set of the config
    /// ([`QueryOptions::config`] makes it).
    pub(super) fn options(&self) -> Result<QueryOptions> {
        Ok(QueryOptions {
            scene: self.scene.clone(),
            read: self.read.options(),
            query: self.query_text(),
            targets: self.source_options.targets()?,
        })
    }

    /// The query: `--query`, else the name of the `--selection` file (`head` for
    /// `head.compressed.ply`), which names its region.
    pub(super) fn query_text(&self) -> Option<String> {
        self.query.clone().or_else(|| {
            let path = self.source_options.selection.as_deref()?;
            let name = path.file_name()?.to_string_lossy();
            Some(name.split('.').next().unwrap_or(&name).to_string())
        })
    }

    /// Whether `--source` chose the source (else the inputs point to it).
    pub(super) fn source_given(&self) -> bool {
        self.source_options.source.is_some()
    }
}

impl SourceArgs {
    /// The `[targets]` keys these options set, typed.
    fn targets(&self) -> Result<TargetOptions> {
        let synonyms = parse_synonyms(&self.synonym)?;
        let region = match &self.selection {
            Some(path) => Some(RegionSpec::Selection(path.clone())),
            None => parse_region(self.region_box.as_deref(), self.sphere.as_deref())?,
        };
        Ok(TargetOptions {
            source: self.source.clone(),
            labels: LabelsConfig {
                synonyms,
                ..LabelsConfig::default()
            },
            region,
            features: FeaturesConfig {
                features: self.features.clone(),
                ..FeaturesConfig::default()
            },
            langsplat: LangsplatConfig {
                latents: self.latents.clone(),
                checkpoint: self.checkpoint.clone(),
                ..LangsplatConfig::default()
            },
            text: TextKeys {
                phrases: self.phrases.clone(),
                phrase_names: self.phrase_names.clone(),
                text_encoder: self.text_encoder.clone(),
                text_activation: self.text_activation,
                text_heads: None,
                negatives: (!self.negative.is_empty()).then(|| self.negative.clone()),
                temperature: self.temperature,
            },
            source_keys: parse_source_keys(&self.source_key)?,
            selection: SelectionKeys {
                top_fraction: self.top_fraction,
                floor: self.floor,
                cluster: self.no_cluster.then_some(false),
            },
        })
    }
}

/// The option that sets a `[targets]` key, for errors: its own flag ([`option_of_key`]) when
/// `query` has it, else `--set targets.<key>`.
pub(super) fn option_naming(key: &str) -> String {
    let option = option_of_key(key);
    let long = option.trim_start_matches('-').split(['/', ' ']).next();
    let command = QueryArgs::augment_args(clap::Command::new("query"));
    if command.get_arguments().any(|a| a.get_long() == long) {
        option
    } else if let Some(["custom", _, inner]) = key.splitn(3, '.').collect::<Vec<_>>().get(..) {
        // A registered source's own key, set with --source-key.
        format!("--source-key {inner}")
    } else {
        format!("--set targets.{key}")
    }
}
