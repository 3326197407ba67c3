//! How a study writes things down: a factor value in its short form, the command line as
//! typed. Leaves that the plan, the summary and the study's files share.

/// A factor value for a table: a table's `kind`, else the value without quotes.
pub fn short_value(raw: &str) -> String {
    let table = raw
        .trim_start()
        .starts_with('{')
        .then(|| toml::from_str::<toml::Table>(&format!("v = {raw}")).ok())
        .flatten()
        .and_then(|mut t| t.remove("v"));
    match table {
        Some(toml::Value::Table(t)) => match t.get("kind") {
            Some(toml::Value::String(kind)) => kind.clone(),
            _ => raw.chars().filter(|c| !c.is_whitespace()).collect(),
        },
        _ => raw.trim().trim_matches('"').to_string(),
    }
}

/// The command line as typed (arguments with spaces or shell characters quoted), the program
/// named `splatraj`.
pub fn command_line(args: impl IntoIterator<Item = String>) -> String {
    args.into_iter()
        .enumerate()
        .map(|(i, a)| {
            let a = if i == 0 { "splatraj".to_string() } else { a };
            if a.chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_./=,:".contains(c))
            {
                a
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_values_name_a_tables_kind() {
        assert_eq!(short_value("{ kind = \"waypoint\" }"), "waypoint");
        assert_eq!(short_value("\"prior-tce\""), "prior-tce");
        assert_eq!(short_value("{width=64, height=48}"), "{width=64,height=48}");
    }

    #[test]
    fn command_lines_quote_what_a_shell_would_split() {
        let args = ["/usr/bin/x", "study", "a b.toml", "--vary", "k=it's"].map(String::from);
        assert_eq!(
            command_line(args),
            "splatraj study 'a b.toml' --vary 'k=it'\\''s'"
        );
    }
}
