//! `--set KEY=VALUE`: one edit of the parsed TOML, checked later exactly like the file.

use anyhow::{Context, Result, bail};

/// Sets `key=value` in the TOML table and returns the key; the value is parsed as TOML (a bare
/// word that is not valid TOML is taken as a string, so `--set queries.0.text=lamp` works).
/// Numeric path segments index arrays (`queries.0.text`). An empty value, or one that starts
/// like a TOML number, list, table or quoted string but does not parse, is an error naming
/// the option.
pub fn apply_override(root: &mut toml::Table, assignment: &str) -> Result<String> {
    apply_assignment(root, assignment, "--set")
}

/// [`apply_override`] for another command-line `option` (errors name it).
pub fn apply_assignment(root: &mut toml::Table, assignment: &str, option: &str) -> Result<String> {
    let Some((key, raw)) = assignment.split_once('=') else {
        bail!("{option} {assignment}: expected KEY=VALUE");
    };
    let key = key.trim();
    if key.is_empty() {
        bail!("{option} {assignment}: no key before `=` (expected KEY=VALUE)");
    }
    let raw = raw.trim();
    if raw.is_empty() {
        bail!("{option} {assignment}: no value after `=` (a string needs quotes: {key}=\"\")");
    }
    let value: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {raw}")) {
        Ok(mut t) => t.remove("v").expect("just parsed"),
        Err(e)
            if raw.starts_with(['[', '{', '"', '\'', '+', '-', '.'])
                || raw.starts_with(|c: char| c.is_ascii_digit()) =>
        {
            bail!(
                "{option} {assignment}: `{raw}` is not a valid TOML value ({}; a string needs \
                 quotes: {key}='\"{raw}\"')",
                e.message().trim_end()
            )
        }
        Err(_) => toml::Value::String(raw.to_string()),
    };
    let parts: Vec<&str> = key.split('.').map(str::trim).collect();
    if parts.iter().any(|p| p.is_empty()) {
        bail!("{option} {assignment}: empty key segment in `{key}`");
    }
    let mut tree = toml::Value::Table(std::mem::take(root));
    let assignment = format!("{option} {assignment}");
    let result = set_path(&mut tree, &parts, 0, value, &assignment);
    if let toml::Value::Table(t) = tree {
        *root = t;
    }
    result.map(|()| parts.join("."))
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
