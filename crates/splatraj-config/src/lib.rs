//! What every splatraj crate's configuration shares, at the bottom of the crate graph.
//!
//! [`ConfigError`] is the one way a bad config value is reported: the key as the user wrote it
//! (`costs.custom.height.weight`, `targets.lifted.views.count`) and what is wrong with it; each
//! crate's own error type converts from it, so every bad key is named the same way.
//! [`Registry`] is the one extension registry: names that configs write (`custom.<name>`)
//! mapped to factories that deserialise a config table (naming the exact key serde stopped at)
//! and build the part. Costs, trajectory models and target sources each wrap one, adding only
//! their `register` (which `init` to call with which context).
//!
//! It reads no files and knows no schema: the experiment crate owns those.

#![warn(missing_docs)]

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::de::DeserializeOwned;

/// A config value that cannot be used: which key, and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{key}` {reason}")]
pub struct ConfigError {
    /// The config key at fault, as written in a config file.
    pub key: String,
    /// What is wrong and what is allowed.
    pub reason: String,
}

impl ConfigError {
    /// The error of `key`.
    pub fn new(key: impl Into<String>, reason: impl Into<String>) -> Self {
        ConfigError {
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// The same error with its key inside `table` (`stop_transmittance` within
    /// `approximations` is `approximations.stop_transmittance`).
    pub fn within(mut self, table: &str) -> Self {
        self.key = if self.key.is_empty() {
            table.to_string()
        } else {
            format!("{table}.{}", self.key)
        };
        self
    }
}

/// Deserialises `table` (the config table at `key`) into `C`; an error names the key inside
/// the table serde stopped at (`key.views.count`), not just the table.
pub fn from_table<C: DeserializeOwned>(table: &toml::Value, key: &str) -> Result<C, ConfigError> {
    serde_path_to_error::deserialize(table.clone()).map_err(|e| {
        let path = e.path().to_string();
        let at = if path == "." {
            key.to_string()
        } else {
            format!("{key}.{path}")
        };
        ConfigError::new(at, e.into_inner().message().trim_end())
    })
}

/// What one registry builds: the context its factories get, what they make, their error.
pub trait Kind: 'static {
    /// What a factory needs besides its table (a window count, where paths start, a device).
    type Context<'a>;
    /// What a factory makes.
    type Output;
    /// Its error; a [`ConfigError`] converts into it.
    type Error: From<ConfigError>;
    /// What the registry holds, for messages ("cost", "trajectory model", "target source").
    const WHAT: &'static str;
}

/// Builds one registered part from its config table, the context, and the table's key.
pub type Factory<K> = Arc<
    dyn for<'a> Fn(
            &toml::Value,
            &<K as Kind>::Context<'a>,
            &str,
        ) -> Result<<K as Kind>::Output, <K as Kind>::Error>
        + Send
        + Sync,
>;

/// Names → factories of one [`Kind`].
pub struct Registry<K: Kind> {
    factories: BTreeMap<String, Factory<K>>,
}

impl<K: Kind> Clone for Registry<K> {
    fn clone(&self) -> Self {
        Registry {
            factories: self.factories.clone(),
        }
    }
}

impl<K: Kind> Default for Registry<K> {
    fn default() -> Self {
        Registry {
            factories: BTreeMap::new(),
        }
    }
}

impl<K: Kind> std::fmt::Debug for Registry<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.factories.keys()).finish()
    }
}

impl<K: Kind> Registry<K> {
    /// Registers config type `C` under `name` (replacing an earlier one): its table is
    /// deserialised with [`from_table`], then `init` builds the part (told the table's key, for
    /// its own errors).
    pub fn insert<C: DeserializeOwned + 'static>(
        &mut self,
        name: &str,
        init: impl for<'a> Fn(&C, &K::Context<'a>, &str) -> Result<K::Output, K::Error>
        + Send
        + Sync
        + 'static,
    ) -> &mut Self {
        let factory: Factory<K> = Arc::new(move |table, context, key| {
            let config: C = from_table(table, key)?;
            init(&config, context, key)
        });
        self.factories.insert(name.to_string(), factory);
        self
    }

    /// The registered names, sorted.
    pub fn names(&self) -> Vec<&str> {
        self.factories.keys().map(String::as_str).collect()
    }

    /// Whether `name` is registered.
    pub fn contains(&self, name: &str) -> bool {
        self.factories.contains_key(name)
    }

    /// What is wrong with a name no factory is registered under, in the one wording of every
    /// registry: "names no registered cost (registered: a, b)" ("none" when empty).
    pub fn unregistered(&self) -> String {
        format!(
            "names no registered {} (registered: {})",
            K::WHAT,
            if self.factories.is_empty() {
                "none".to_string()
            } else {
                self.names().join(", ")
            }
        )
    }

    /// Builds the part registered as `name` from its config table at `key`; an unknown name
    /// is a [`ConfigError`] on `key` listing the registered names ([`Registry::unregistered`]).
    pub fn build(
        &self,
        name: &str,
        table: &toml::Value,
        context: &K::Context<'_>,
        key: &str,
    ) -> Result<K::Output, K::Error> {
        match self.factories.get(name) {
            Some(factory) => factory(table, context, key),
            None => Err(ConfigError::new(key, self.unregistered()).into()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq)]
    struct Bad(String);

    impl From<ConfigError> for Bad {
        fn from(e: ConfigError) -> Self {
            Bad(e.to_string())
        }
    }

    struct Scaled;

    impl Kind for Scaled {
        type Context<'a> = &'a f64;
        type Output = f64;
        type Error = Bad;
        const WHAT: &'static str = "scaler";
    }

    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Times {
        by: f64,
    }

    fn registry() -> Registry<Scaled> {
        let mut r = Registry::<Scaled>::default();
        r.insert::<Times>("times", |c, x, _| Ok(c.by * **x));
        r
    }

    #[test]
    fn an_error_within_a_table_names_the_full_key() {
        let e = ConfigError::new("min_opacity", "= 2 must lie in [0, 1)").within("approximations");
        assert_eq!(e.key, "approximations.min_opacity");
        assert_eq!(
            e.to_string(),
            "`approximations.min_opacity` = 2 must lie in [0, 1)"
        );
        assert_eq!(ConfigError::new("", "x").within("costs").key, "costs");
    }

    #[test]
    fn builds_a_registered_part_with_its_context() {
        let table: toml::Value = toml::from_str("by = 3.0").unwrap();
        assert_eq!(registry().build("times", &table, &&2.0, "k"), Ok(6.0));
        assert_eq!(registry().names(), vec!["times"]);
    }

    #[test]
    fn errors_name_the_key_inside_the_table_and_unknown_names() {
        let table: toml::Value = toml::from_str("by = \"x\"").unwrap();
        let Err(Bad(e)) = registry().build("times", &table, &&2.0, "scalers.custom.times") else {
            panic!("a string is not a number");
        };
        assert!(e.contains("`scalers.custom.times.by`"), "{e}");
        let table: toml::Value = toml::from_str("bye = 1.0").unwrap();
        let Err(Bad(e)) = registry().build("times", &table, &&2.0, "s.times") else {
            panic!("an unknown key is refused");
        };
        assert!(e.contains("`s.times.bye` unknown field"), "{e}");
        let Err(Bad(e)) = registry().build("plus", &table, &&2.0, "s.plus") else {
            panic!("unknown name");
        };
        assert!(
            e.contains("no registered scaler (registered: times)"),
            "{e}"
        );
        assert_eq!(
            Registry::<Scaled>::default().unregistered(),
            "names no registered scaler (registered: none)"
        );
    }
}
