//! `--set KEY=VALUE`: one edit of the parsed TOML, checked later exactly like the file. An
//! [`Override`] is parsed once from the command line (or made from a key and a value a study
//! factor holds) and applied to each table it edits, never formatted back into text.

use anyhow::{Context, Result, bail};

/// One `KEY=VALUE` edit of a config table, parsed: the dotted key and its TOML value.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// The dotted key (`queries.0.text`), segments trimmed.
    pub key: String,
    /// The value to set there.
    pub value: toml::Value,
    /// The option that gave it (`--set`, `--source-key`), for errors.
    pub option: String,
    /// The assignment as written (`queries.0.text=lamp`), for errors.
    pub written: String,
}

impl Override {
    /// Parses `key=value`, given with `option` (errors name both); the value is parsed as
    /// TOML (a bare word that is not valid TOML is taken as a string, so `--set
    /// queries.0.text=lamp` works). An empty key segment or value, or a value that starts like
    /// a TOML number, list, table or quoted string but does not parse, is an error.
    pub fn parse(assignment: &str, option: &str) -> Result<Override> {
        let Some((key, raw)) = assignment.split_once('=') else {
            bail!("{option} {assignment}: expected KEY=VALUE");
        };
        Self::from_text(key, raw, option, assignment)
    }

    /// The edit setting `key` to the TOML text `raw` (as [`Override::parse`] reads it);
    /// `written` names it in errors as `option written`.
    pub fn from_text(key: &str, raw: &str, option: &str, written: &str) -> Result<Override> {
        let key = key.trim();
        if key.is_empty() {
            bail!("{option} {written}: no key before `=` (expected KEY=VALUE)");
        }
        let raw = raw.trim();
        if raw.is_empty() {
            bail!("{option} {written}: no value after `=` (a string needs quotes: {key}=\"\")");
        }
        let value: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {raw}")) {
            Ok(mut t) => t.remove("v").expect("just parsed"),
            Err(e)
                if raw.starts_with(['[', '{', '"', '\'', '+', '-', '.'])
                    || raw.starts_with(|c: char| c.is_ascii_digit()) =>
            {
                bail!(
                    "{option} {written}: `{raw}` is not a valid TOML value ({}; a string \
                     needs quotes: {key}='\"{raw}\"')",
                    e.message().trim_end()
                )
            }
            Err(_) => toml::Value::String(raw.to_string()),
        };
        Self::new(key, value, option, written)
    }

    /// The edit setting `key` to `value`, already parsed (a study factor's value); `written`
    /// names it in errors as `option written`.
    pub fn new(key: &str, value: toml::Value, option: &str, written: &str) -> Result<Override> {
        let parts: Vec<&str> = key.split('.').map(str::trim).collect();
        if parts.iter().any(|p| p.is_empty()) {
            bail!("{option} {written}: empty key segment in `{key}`");
        }
        Ok(Override {
            key: parts.join("."),
            value,
            option: option.to_string(),
            written: written.to_string(),
        })
    }

    /// `--set` edits parsed from the command line, in order.
    pub fn parse_all(assignments: &[String]) -> Result<Vec<Override>> {
        assignments
            .iter()
            .map(|a| Override::parse(a, "--set"))
            .collect()
    }

    /// Sets the value at the key in `root`, creating tables on the way; numeric segments
    /// index lists (`queries.0.text`).
    pub fn apply(&self, root: &mut toml::Table) -> Result<()> {
        let parts: Vec<&str> = self.key.split('.').collect();
        let mut tree = toml::Value::Table(std::mem::take(root));
        let assignment = format!("{} {}", self.option, self.written);
        let result = set_path(&mut tree, &parts, 0, self.value.clone(), &assignment);
        if let toml::Value::Table(t) = tree {
            *root = t;
        }
        result
    }
}

/// Sets `key=value` in the TOML table and returns the key (see [`Override::parse`]).
pub fn apply_override(root: &mut toml::Table, assignment: &str) -> Result<String> {
    apply_assignment(root, assignment, "--set")
}

/// [`apply_override`] for another command-line `option` (errors name it).
pub fn apply_assignment(root: &mut toml::Table, assignment: &str, option: &str) -> Result<String> {
    let edit = Override::parse(assignment, option)?;
    edit.apply(root)?;
    Ok(edit.key)
}

/// Sets `parts[depth..]` below `node` to `value`, creating tables on the way.
fn set_path(
    node: &mut toml::Value,
    parts: &[&str],
    depth: usize,
    value: toml::Value,
    key: &str,
) -> Result<()> {
    let part = parts[depth];
    let here = parts[..=depth].join(".");
    let last = depth + 1 == parts.len();
    let child = match node {
        toml::Value::Table(t) => {
            if last {
                t.insert(part.to_string(), value);
                return Ok(());
            }
            t.entry(part.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        }
        toml::Value::Array(a) => {
            let i: usize = part
                .parse()
                .with_context(|| format!("{key}: `{here}` must index a list (0-based)"))?;
            let len = a.len();
            let slot = a
                .get_mut(i)
                .with_context(|| format!("{key}: `{here}` is out of range ({len} entries)"))?;
            if last {
                *slot = value;
                return Ok(());
            }
            slot
        }
        _ => bail!(
            "{key}: `{}` is a value, not a table",
            parts[..depth].join(".")
        ),
    };
    set_path(child, parts, depth + 1, value, key)
}
