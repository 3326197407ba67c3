//! `optimise_gaussians`: how many Gaussians the optimisation passes render.

use serde::{Deserialize, Serialize};

use super::ConfigError;

/// Scenes above this many Gaussians are optimised through a coarse copy of this many under
/// `"auto"`: a step of the demo config at 1 M costs 0.4–0.9 s on 2 cores, and at the
/// optimisation's 96 × 54 to 128 × 96 pixels a denser copy changes no pixel that matters
/// (docs/results.md, "Scale").
pub const AUTO_OPTIMISE_GAUSSIANS: usize = 1_000_000;

/// What the optimisation passes render (trajectory and pose runs and their start search):
/// the scene itself, or a coarse copy (neighbouring Gaussians of the same objects merged,
/// `splatraj_scene::coarse`). Metrics, verdicts and frames always render the scene itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(from = "Written", into = "Written")]
pub enum OptimiseGaussians {
    /// `"auto"`: a copy of [`AUTO_OPTIMISE_GAUSSIANS`] when the scene holds more.
    #[default]
    Auto,
    /// `"all"`: the scene itself, however large.
    All,
    /// A number: a copy of at most this many when the scene holds more.
    AtMost(usize),
}

impl OptimiseGaussians {
    /// Whether it is the default (`"auto"`).
    pub fn is_auto(&self) -> bool {
        *self == OptimiseGaussians::Auto
    }

    /// The size of the copy for a scene of `gaussians`; None: the scene itself.
    pub fn budget(self, gaussians: usize) -> Option<usize> {
        let most = match self {
            OptimiseGaussians::Auto => AUTO_OPTIMISE_GAUSSIANS,
            OptimiseGaussians::All => return None,
            OptimiseGaussians::AtMost(most) => most,
        };
        (gaussians > most).then_some(most)
    }

    /// A count of at least 1.
    pub fn check(self) -> Result<(), ConfigError> {
        match self {
            OptimiseGaussians::AtMost(0) => Err(ConfigError::new(
                "optimise_gaussians",
                "= 0: give at least 1, \"auto\" or \"all\"",
            )),
            _ => Ok(()),
        }
    }
}

/// The file's spelling: a word or a count.
#[derive(Serialize, Deserialize)]
#[serde(untagged, expecting = "\"auto\", \"all\" or a number of Gaussians")]
enum Written {
    Word(Word),
    Count(usize),
}

#[derive(Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Word {
    Auto,
    All,
}

impl From<Written> for OptimiseGaussians {
    fn from(w: Written) -> Self {
        match w {
            Written::Word(Word::Auto) => OptimiseGaussians::Auto,
            Written::Word(Word::All) => OptimiseGaussians::All,
            Written::Count(n) => OptimiseGaussians::AtMost(n),
        }
    }
}

impl From<OptimiseGaussians> for Written {
    fn from(o: OptimiseGaussians) -> Self {
        match o {
            OptimiseGaussians::Auto => Written::Word(Word::Auto),
            OptimiseGaussians::All => Written::Word(Word::All),
            OptimiseGaussians::AtMost(n) => Written::Count(n),
        }
    }
}
