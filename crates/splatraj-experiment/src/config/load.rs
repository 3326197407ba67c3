//! Reading a config: the file and the files it `extends` (read and parsed once, a
//! [`ConfigFile`]), the first-try tables an override edits, the `--set` overrides, then the
//! schema and [`Config::validate_with`]. A command that needs several configs of one file (a
//! study's variants) reads the file once and makes each from the [`ConfigFile`].

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::Config;
use super::first_try::{FIRST_TRY_COSTS, FIRST_TRY_TRAJECTORY, first_try_table};
use super::overrides::Override;
use crate::extensions::Extensions;

/// A config file read and parsed once: its table merged over the files it `extends`, and
/// where it lies. [`ConfigFile::config`] makes the typed config with edits over it, as often
/// as a command needs, without reading the file again.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigFile {
    /// The file.
    pub path: PathBuf,
    /// Its table, over what it `extends`.
    pub table: toml::Table,
}

impl ConfigFile {
    /// Reads `path` and the files it `extends`.
    pub fn read(path: &Path) -> Result<ConfigFile> {
        Ok(ConfigFile {
            path: path.to_path_buf(),
            table: read_table(path, 0)?,
        })
    }

    /// The file with `layer` merged over it, key by key as `extends` merges (the keys a
    /// command's flags set, e.g. `splatraj query --phrases`).
    pub fn with_layer(mut self, layer: toml::Table) -> ConfigFile {
        merge(&mut self.table, layer);
        self
    }

    /// The folder relative paths of the file are read from.
    pub fn base_dir(&self) -> &Path {
        self.path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
    }

    /// The typed config of the file with `overrides` applied, checked with `extensions`.
    pub fn config(&self, overrides: &[Override], extensions: &Extensions) -> Result<Config> {
        self.config_edited(overrides, extensions, |_| {})
    }

    /// [`ConfigFile::config`] with `edit` applied to the typed config before the checks: a
    /// command's own options that set config fields, typed (`splatraj pose --restarts`), over
    /// the file and the overrides.
    pub fn config_edited(
        &self,
        overrides: &[Override],
        extensions: &Extensions,
        edit: impl FnOnce(&mut Config),
    ) -> Result<Config> {
        let origin = format!("config {}", self.path.display());
        let mut config =
            Config::unchecked(self.table.clone(), self.base_dir(), overrides, &origin)?;
        config.path = self.path.clone();
        edit(&mut config);
        config
            .validate_with(extensions)
            .with_context(|| origin.to_string())?;
        Ok(config)
    }
}

impl Config {
    /// Reads `path` (and the files it `extends`), applies `overrides` (`key=value`), and
    /// checks the result with the built-in costs only.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Config> {
        Self::load_with(path, overrides, &Extensions::default())
    }

    /// [`Config::load`] for a config that may name the costs, trajectory models and target
    /// sources registered in `extensions`.
    pub fn load_with(path: &Path, overrides: &[String], extensions: &Extensions) -> Result<Config> {
        ConfigFile::read(path)?.config(&Override::parse_all(overrides)?, extensions)
    }

    /// [`Config::load`] with `edit` applied over the file and `overrides` before the checks
    /// (see [`ConfigFile::config_edited`]).
    pub fn load_edited(
        path: &Path,
        overrides: &[String],
        edit: impl FnOnce(&mut Config),
    ) -> Result<Config> {
        let file = ConfigFile::read(path)?;
        file.config_edited(
            &Override::parse_all(overrides)?,
            &Extensions::default(),
            edit,
        )
    }

    /// A config from TOML text (no `extends`), checked with `extensions`; relative paths are
    /// resolved against `base_dir`.
    pub fn from_toml(text: &str, base_dir: &Path, extensions: &Extensions) -> Result<Config> {
        let table: toml::Table = toml::from_str(text)
            .map_err(|e| anyhow::anyhow!("config is not valid TOML: {}", e.message().trim_end()))?;
        Self::from_table(table, base_dir, &[], "config", extensions)
    }

    /// A config from a TOML table (a file's, or one a command makes of its options) with
    /// `overrides` (`key=value`) applied, checked with `extensions`; relative paths are
    /// resolved against `base_dir`, and `origin` (`config run.toml`) names it in errors.
    pub fn from_table(
        table: toml::Table,
        base_dir: &Path,
        overrides: &[String],
        origin: &str,
        extensions: &Extensions,
    ) -> Result<Config> {
        let overrides = Override::parse_all(overrides)?;
        Self::from_edited_table(table, base_dir, &overrides, origin, extensions)
    }

    /// [`Config::from_table`] with the overrides already parsed.
    pub fn from_edited_table(
        table: toml::Table,
        base_dir: &Path,
        overrides: &[Override],
        origin: &str,
        extensions: &Extensions,
    ) -> Result<Config> {
        let config = Self::unchecked(table, base_dir, overrides, origin)?;
        config
            .validate_with(extensions)
            .with_context(|| origin.to_string())?;
        Ok(config)
    }

    /// The config of `table` with `overrides` applied, read by the schema but not yet
    /// checked by [`Config::validate_with`].
    fn unchecked(
        mut table: toml::Table,
        base_dir: &Path,
        overrides: &[Override],
        origin: &str,
    ) -> Result<Config> {
        write_first_try_tables(&mut table, overrides);
        for o in overrides {
            o.apply(&mut table)?;
        }
        let mut config: Config = deserialize_table(table).map_err(|(key, message)| {
            let (key, message) = inner_key(key, message);
            // A key an override set, a key below it, or the table holding it (a tagged table
            // like `[trajectory]` reports its own name) is the option's fault, not the file's.
            let set_by = overrides.iter().rev().find(|o| {
                let k = &o.key;
                key == *k
                    || key.starts_with(&format!("{k}."))
                    || (!key.is_empty() && k.starts_with(&format!("{key}.")))
            });
            match set_by {
                Some(o) => anyhow::anyhow!("{} {}: `{key}`: {message}", o.option, o.written),
                None => anyhow::anyhow!("{origin}: {}", at_key(&key, &message)),
            }
        })?;
        config.base_dir = base_dir.to_path_buf();
        Ok(config)
    }
}

/// Writes the first-try `[costs]` and `[trajectory]` into a config that leaves them out, when
/// an override edits them: `--set costs.motion.weight=0` or `--set
/// trajectory.centres_per_window=4` then tunes the set the config runs with, instead of
/// becoming the only cost (a `[costs]` table lists exactly the costs that are on) or a model
/// without its `kind`.
fn write_first_try_tables(value: &mut toml::Table, overrides: &[Override]) {
    let edits = |table: &str| {
        overrides
            .iter()
            .any(|o| o.key.starts_with(&format!("{table}.")))
    };
    if !value.contains_key("costs") && edits("costs") {
        let defaults = first_try_table(FIRST_TRY_COSTS);
        value.insert("costs".into(), toml::Value::Table(defaults));
    }
    // A new `kind` is a new model: its own keys, not the first-try RBF's.
    let new_kind = overrides
        .iter()
        .any(|o| o.key == "trajectory" || o.key == "trajectory.kind");
    if !value.contains_key("trajectory") && edits("trajectory") && !new_kind {
        let defaults = first_try_table(FIRST_TRY_TRAJECTORY);
        value.insert("trajectory".into(), toml::Value::Table(defaults));
    }
}

/// Deserialises the whole config, or says at which key (dotted, list entries by index:
/// `queries.0.text`, as `--set` writes it; empty at the top level) and what went wrong.
fn deserialize_table(table: toml::Table) -> Result<Config, (String, String)> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let key = e
            .path()
            .iter()
            .map(|segment| match segment {
                serde_path_to_error::Segment::Seq { index } => index.to_string(),
                other => other.to_string(),
            })
            .collect::<Vec<_>>()
            .join(".");
        (key, e.into_inner().message().trim_end().to_string())
    })
}

/// The key a table's own checks name in `message` (`[targets]` reads its table itself, and
/// says "`targets.phrase` is an unknown field"), when it lies inside `key`; else `key` and
/// `message` as they are.
fn inner_key(key: String, message: String) -> (String, String) {
    let named = message
        .strip_prefix('`')
        .and_then(|rest| rest.split_once("` "))
        .filter(|(inner, _)| key.is_empty() || inner.starts_with(&format!("{key}.")));
    match named {
        Some((inner, reason)) => (inner.to_string(), reason.to_string()),
        None => (key, message),
    }
}

/// "`key`: message", or the message alone at the top level.
fn at_key(key: &str, message: &str) -> String {
    if key.is_empty() || key == "?" {
        message.to_string()
    } else {
        format!("`{key}`: {message}")
    }
}

/// How many `extends` a config may chain (a cycle ends here with an error).
const MAX_EXTENDS: usize = 8;

/// Reads a config file as a TOML table, merged over the file its `extends` key names.
///
/// `extends = "demo.toml"` (relative to this file) loads that config first; this file's keys
/// then replace its values, tables merging key by key (so a variant config states only what
/// differs; see [`merge`]). The `extends` key itself is not part of the schema.
/// The error of a config that does not parse: where (line and column) and what, without
/// quoting the line (toml's own message does, and a line can be megabytes long).
fn not_valid_toml(path: &Path, text: &str, error: &toml::de::Error) -> anyhow::Error {
    let place = error.span().map_or(String::new(), |span| {
        let before = &text.as_bytes()[..span.start.min(text.len())];
        let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
        let column = before.iter().rev().take_while(|&&b| b != b'\n').count() + 1;
        format!(" at line {line}, column {column}")
    });
    anyhow::anyhow!(
        "config {} is not valid TOML{place}: {}",
        path.display(),
        error.message().trim_end()
    )
}

fn read_table(path: &Path, depth: usize) -> Result<toml::Table> {
    if depth > MAX_EXTENDS {
        bail!(
            "config {}: more than {MAX_EXTENDS} nested `extends` (a cycle?)",
            path.display()
        );
    }
    let text = splatraj_scene::input::read_text(path)
        .with_context(|| format!("cannot read config {}", path.display()))?;
    let mut table: toml::Table =
        toml::from_str(&text).map_err(|e| not_valid_toml(path, &text, &e))?;
    match table.remove("extends") {
        None => Ok(table),
        Some(toml::Value::String(base)) => {
            let dir = path.parent().unwrap_or(Path::new("."));
            let mut merged = read_table(&dir.join(&base), depth + 1)
                .with_context(|| format!("`extends` of {}", path.display()))?;
            merge(&mut merged, table);
            Ok(merged)
        }
        Some(other) => bail!(
            "config {}: `extends` must be a file name, got {other}",
            path.display()
        ),
    }
}

/// Merges `over` into `base`: tables recursively, anything else replaced. A table whose
/// `kind` differs from the base's (`[trajectory] kind = "waypoint"` over an RBF) replaces it
/// whole: the other keys belonged to the old kind.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o))
                if o.get("kind").is_none_or(|k| Some(k) == b.get("kind")) =>
            {
                merge(b, o)
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A config whose `[targets]` holds `targets`, loaded with `overrides`: the error.
    fn error(targets: &str, overrides: &[&str]) -> String {
        let text = format!(
            "name = \"x\"\n[scene]\ndemo = {{ gaussians = 100 }}\n[targets]\n{targets}\n\
             [[queries]]\ntext = \"a\"\n"
        );
        let table: toml::Table = toml::from_str(&text).unwrap();
        let overrides: Vec<String> = overrides.iter().map(|o| o.to_string()).collect();
        let extensions = Extensions::default();
        match Config::from_table(
            table,
            Path::new("."),
            &overrides,
            "config x.toml",
            &extensions,
        ) {
            Ok(_) => String::new(),
            Err(e) => format!("{e:#}"),
        }
    }

    #[test]
    fn a_targets_key_error_names_the_key_and_whoever_set_it() {
        // The file's key, though a --set edits another key of [targets].
        let err = error("phrase = \"t.json\"", &["targets.selection.floor=0.6"]);
        assert!(
            err.starts_with("config x.toml: `targets.phrase`: is an unknown field"),
            "{err}"
        );
        // The --set that set it.
        let err = error("", &["targets.phrase=t.json"]);
        assert!(
            err.starts_with("--set targets.phrase=t.json: `targets.phrase`: is an unknown"),
            "{err}"
        );
    }
}
