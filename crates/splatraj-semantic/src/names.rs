//! Matching queries to names: normalisation and "did you mean" suggestions.

/// How many suggestions a no-match error lists.
pub const SUGGESTIONS: usize = 5;

/// A name reduced for comparison: trimmed, lower-case, inner whitespace collapsed to one space,
/// so that "  Category   3" and "category 3" are the same name.
pub fn normalise(name: &str) -> String {
    name.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .to_lowercase()
}

/// The `limit` candidates closest to `query`, best first, without repeats.
///
/// Similarity is the normalised Damerau-Levenshtein similarity of the normalised strings, so a
/// swapped pair of letters ("Categroy") costs one edit, as a typist would expect. Ties keep
/// the candidates' order.
pub fn closest<'a>(
    query: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    limit: usize,
) -> Vec<String> {
    let q = normalise(query);
    let mut scored: Vec<(f64, String)> = Vec::new();
    for c in candidates {
        if scored.iter().any(|(_, s)| s == c) {
            continue;
        }
        let score = strsim::normalized_damerau_levenshtein(&q, &normalise(c));
        scored.push((score, c.to_string()));
    }
    // Stable sort: equal scores keep the order the candidates were given in.
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    scored.into_iter().take(limit).map(|(_, s)| s).collect()
}
