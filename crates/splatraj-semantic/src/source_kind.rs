//! The words a `[targets]` table is written in, shared by its two layers ([`crate::config`],
//! the table as written, and [`crate::source_config`], the typed config of its source): which
//! source it names ([`SourceKind`]) and how a region is written ([`RegionSpec`]).

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::sources::Region;

/// The kinds of target source: the built-in ones, or `custom.<name>` for a source registered
/// in a [`SourceRegistry`].
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum SourceKind {
    /// Per-Gaussian label ids with names ([`LabelsSource`](crate::sources::LabelsSource)).
    #[default]
    Labels,
    /// Named boxes and spheres ([`RegionSource`](crate::sources::RegionSource)).
    Region,
    /// Per-Gaussian embeddings and a phrase table ([`FeaturesSource`](crate::sources::FeaturesSource)).
    Features,
    /// LangSplat latents decoded by the checkpoint's decoder, then as `features`.
    Langsplat,
    /// A language field lifted from the scene's own renders (no training): built by the
    /// source registered as [`LIFTED`] (splatraj-lift), from `text_encoder` and `[targets.lifted]`.
    Lifted,
    /// A registered source, by its registered name (configs write `custom.<name>`).
    Custom(String),
}

/// The registry name of the `lifted` source (registered by splatraj-lift's users: the
/// experiment crate's registry holds it).
pub const LIFTED: &str = "lifted";

/// How configs name a registered source: `source = "custom.<name>"`.
pub const CUSTOM_PREFIX: &str = "custom.";

impl SourceKind {
    /// The built-in kinds, in documentation order.
    pub const ALL: [SourceKind; 5] = [
        SourceKind::Labels,
        SourceKind::Region,
        SourceKind::Features,
        SourceKind::Langsplat,
        SourceKind::Lifted,
    ];

    /// The name used in configs and on the command line (`custom.<name>` for a registered
    /// source).
    pub fn name(&self) -> String {
        match self {
            SourceKind::Labels => "labels".into(),
            SourceKind::Region => "region".into(),
            SourceKind::Features => "features".into(),
            SourceKind::Langsplat => "langsplat".into(),
            SourceKind::Lifted => LIFTED.into(),
            SourceKind::Custom(name) => format!("{CUSTOM_PREFIX}{name}"),
        }
    }
}

impl fmt::Display for SourceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for SourceKind {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        if let Some(name) = s.strip_prefix(CUSTOM_PREFIX)
            && !name.is_empty()
        {
            return Ok(SourceKind::Custom(name.to_string()));
        }
        SourceKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown source {s:?}: use labels, region, features, langsplat or lifted, \
                     or custom.<name> for a registered source"
                )
            })
    }
}

impl TryFrom<String> for SourceKind {
    type Error = String;

    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

impl From<SourceKind> for String {
    fn from(kind: SourceKind) -> String {
        kind.name()
    }
}

/// A region as written in a config: `{ box = [x0, y0, z0, x1, y1, z1] }` (two opposite corners),
/// `{ sphere = [cx, cy, cz, r] }`, or `{ selection = "head.ply" }` (the splats a user selected in
/// an editor and exported, matched to the scene's Gaussians: [`crate::sources::editor_selection`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum RegionSpec {
    /// Axis-aligned box: smallest corner then largest corner.
    Box([f32; 6]),
    /// Ball: centre then radius.
    Sphere([f32; 4]),
    /// A file of selected splats (any scene format; relative to the config's folder).
    Selection(PathBuf),
}

impl RegionSpec {
    /// The box or ball as a [`Region`]; `None` for a selection file, which is matched to the
    /// scene instead.
    pub fn shape(&self) -> Option<Region> {
        match *self {
            RegionSpec::Box(v) => Some(Region::Box {
                min: [v[0], v[1], v[2]],
                max: [v[3], v[4], v[5]],
            }),
            RegionSpec::Sphere(v) => Some(Region::Sphere {
                centre: [v[0], v[1], v[2]],
                radius: v[3],
            }),
            RegionSpec::Selection(_) => None,
        }
    }
}
