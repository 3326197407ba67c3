//! The views page's "Which way is up?" strip: the scene stood upright for each of a few ups,
//! side by side, each with the `[scene]` line that sets it, so a user settles up in one look.
//!
//! The first choice is the up the page's views use (given, the capture's cameras' or the
//! geometry's guess); the others are the geometry's next candidates. Each carries the line to
//! paste and the line for the opposite direction, since a candidate's picture upside down
//! means its axis is right and its sign is not.

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;

use crate::report::escape;

/// One up the strip shows the scene upright for.
#[derive(Debug, Clone, PartialEq)]
pub struct UpChoice {
    /// The direction, unit length.
    pub up: [f64; 3],
    /// Where it comes from and how sure that is, in words.
    pub why: String,
    /// Whether the page's views use it.
    pub in_use: InUse,
    /// The `[scene]` line that sets it: `up = [0, 0, 1]`.
    pub line: String,
    /// The `[scene]` line that sets the opposite direction.
    pub opposite: String,
    /// The scene seen upright for `up`, PNG bytes.
    pub png: Vec<u8>,
    /// The picture's width and height, pixels.
    pub size: (usize, usize),
}

/// Whether the page's views stand on a choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InUse {
    /// The views use this up.
    Yes,
    /// Another candidate.
    No,
}

/// The strip's own style, after the page's.
pub const STRIP_STYLE: &str =
    ".up-strip{margin:8px 0 16px}.up-choices{display:flex;gap:12px;flex-wrap:wrap}
.up-choice{width:300px;margin:0;border:1px solid #ccc;padding:6px;background:#fafafa;font-size:13px}
.up-choice.in-use{border:2px solid #1f77b4}.up-choice img{display:block;width:100%}
.up-choice code{background:#f0f0f0;padding:1px 3px}.up-choice button{margin-left:4px}";

/// The strip as HTML; empty for no choices. Copy buttons carry their text in `data-copy`.
pub fn strip_html(choices: &[UpChoice]) -> String {
    if choices.is_empty() {
        return String::new();
    }
    let mut html = String::from(
        "<section class=\"up-strip\" id=\"up-strip\"><h2>Which way is up?</h2><p class=\"note\">\
         The scene stood upright for each of these ups, seen from a little above. Pick the one \
         that stands as the capture did and paste its line under <code>[scene]</code> in the \
         config (or give <code>scene views --up X,Y,Z</code> to see the views below on it). A \
         picture upside down: its axis is right, take the opposite line. The views below use \
         the framed one.</p><div class=\"up-choices\">",
    );
    for (i, choice) in choices.iter().enumerate() {
        let [x, y, z] = choice.up;
        let (class, tag) = match choice.in_use {
            InUse::Yes => (" in-use", " (these views)"),
            InUse::No => ("", ""),
        };
        html.push_str(&format!(
            "<figure class=\"up-choice{class}\" data-up=\"[{x}, {y}, {z}]\" data-in-use=\"{}\">\
             <img alt=\"the scene upright for up {line}\" src=\"data:image/png;base64,{png}\" \
             width=\"{w}\" height=\"{h}\"/><figcaption><b>{n}. {line}</b>{tag}<br/>{why}<br/>\
             <code class=\"up-line\">{line}</code><button type=\"button\" class=\"copy-up\" \
             data-copy=\"{line}\">copy</button><br/>upside down? \
             <code class=\"up-opposite\">{opposite}</code><button type=\"button\" \
             class=\"copy-up\" data-copy=\"{opposite}\">copy</button></figcaption></figure>",
            choice.in_use == InUse::Yes,
            png = BASE64.encode(&choice.png),
            w = choice.size.0,
            h = choice.size.1,
            n = i + 1,
            line = escape(&choice.line),
            opposite = escape(&choice.opposite),
            why = escape(&choice.why),
        ));
    }
    html.push_str("</div><div class=\"note\" id=\"up-status\"></div></section>\n");
    html
}

#[cfg(test)]
mod tests {
    use super::*;

    fn choice(up: [f64; 3], in_use: InUse) -> UpChoice {
        UpChoice {
            up,
            why: "guess <a>".into(),
            in_use,
            line: "up = [0, 0, 1]".into(),
            opposite: "up = [0, 0, -1]".into(),
            png: vec![1, 2],
            size: (4, 3),
        }
    }

    #[test]
    fn one_figure_per_choice_with_its_lines_and_the_one_in_use_marked() {
        let html = strip_html(&[
            choice([0.0, 0.0, 1.0], InUse::Yes),
            choice([1.0, 0.0, 0.0], InUse::No),
        ]);
        assert_eq!(html.matches("<figure class=\"up-choice").count(), 2);
        assert_eq!(html.matches("data-in-use=\"true\"").count(), 1);
        assert!(html.contains("data-copy=\"up = [0, 0, 1]\""));
        assert!(html.contains("data-copy=\"up = [0, 0, -1]\""));
        assert!(html.contains("guess &lt;a&gt;"), "{html}");
        assert_eq!(strip_html(&[]), "");
    }
}
