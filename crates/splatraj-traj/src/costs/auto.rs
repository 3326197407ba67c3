//! Config values that may be left to the scene: a number, or the word `"auto"`.
//!
//! A first-try config names only the scene and its queries, so the settings whose right value
//! depends on the scene's size (the clearance margin, the speed limit) cannot have a fixed
//! default. They are [`OrAuto`]: `margin = 0.1` is taken as given, `margin = "auto"` (the
//! default) is replaced by a value derived from the scene when the experiment is prepared
//! (`splatraj_experiment::Experiment::prepare`), and the run folder's `config.toml` holds the
//! resolved number, so a run can be repeated exactly.

use std::fmt;

use serde::de::{self, Deserializer, Visitor};
use serde::{Deserialize, Serialize, Serializer};

/// A number given in the config, or `"auto"`: derived from the scene before the run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum OrAuto {
    /// Derived from the scene when the experiment is prepared.
    #[default]
    Auto,
    /// As given.
    Value(f64),
}

impl OrAuto {
    /// The number, once given or resolved.
    pub fn value(self) -> Option<f64> {
        match self {
            OrAuto::Auto => None,
            OrAuto::Value(v) => Some(v),
        }
    }

    /// `self`, with `Auto` replaced by `derived()`.
    pub fn resolve(self, derived: impl FnOnce() -> f64) -> Self {
        match self {
            OrAuto::Auto => OrAuto::Value(derived()),
            given => given,
        }
    }

    /// Whether it is still `"auto"`.
    pub fn is_auto(self) -> bool {
        self == OrAuto::Auto
    }
}

impl From<f64> for OrAuto {
    fn from(v: f64) -> Self {
        OrAuto::Value(v)
    }
}

impl fmt::Display for OrAuto {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OrAuto::Auto => f.write_str("\"auto\""),
            OrAuto::Value(v) => write!(f, "{v}"),
        }
    }
}

impl Serialize for OrAuto {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            OrAuto::Auto => serializer.serialize_str("auto"),
            OrAuto::Value(v) => serializer.serialize_f64(*v),
        }
    }
}

impl<'de> Deserialize<'de> for OrAuto {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Expect;
        impl Visitor<'_> for Expect {
            type Value = OrAuto;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number or \"auto\"")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<OrAuto, E> {
                Ok(OrAuto::Value(v))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<OrAuto, E> {
                Ok(OrAuto::Value(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<OrAuto, E> {
                Ok(OrAuto::Value(v as f64))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<OrAuto, E> {
                if v == "auto" {
                    Ok(OrAuto::Auto)
                } else {
                    Err(E::invalid_value(de::Unexpected::Str(v), &self))
                }
            }
        }
        deserializer.deserialize_any(Expect)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize, Serialize, PartialEq)]
    struct Holder {
        v: OrAuto,
    }

    #[test]
    fn reads_numbers_and_auto_and_names_what_else_is_wrong() {
        let read = |text: &str| toml::from_str::<Holder>(text).map(|h| h.v);
        assert_eq!(read("v = 0.25").unwrap(), OrAuto::Value(0.25));
        assert_eq!(read("v = 2").unwrap(), OrAuto::Value(2.0));
        assert_eq!(read("v = \"auto\"").unwrap(), OrAuto::Auto);
        let error = read("v = \"big\"").unwrap_err().to_string();
        assert!(error.contains("a number or \"auto\""), "{error}");
        let written = toml::to_string(&Holder { v: OrAuto::Auto }).unwrap();
        assert_eq!(written.trim(), "v = \"auto\"");
        assert_eq!(OrAuto::Auto.resolve(|| 3.0), OrAuto::Value(3.0));
        assert_eq!(OrAuto::Value(1.0).resolve(|| 3.0), OrAuto::Value(1.0));
    }
}
