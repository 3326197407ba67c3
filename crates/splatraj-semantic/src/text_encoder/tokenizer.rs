//! CLIP's tokenizer as open_clip applies it: text clean-up, byte-pair encoding with the
//! vocabulary OpenAI's CLIP and open_clip ship, start and end markers, 77 ids per text.
//!
//! The byte-pair encoding is `instant-clip-tokenizer` (a maintained port that bundles the
//! vocabulary file and is tested against the Python tokenizer). What open_clip does before
//! it (`_clean_lower`: `ftfy.fix_text`, `html.unescape` twice, whitespace collapsed, lower
//! case) is done here, with the parts of `ftfy.fix_text` that change ordinary typed text:
//! curly quotes to straight ones, Latin ligatures split, full-width ASCII to ASCII, Unicode
//! NFC. ftfy's repair of mis-decoded text (mojibake such as "cafÃ©") is not done: it is a
//! heuristic for broken files, not for a phrase typed by a user.

use std::borrow::Cow;

use instant_clip_tokenizer::{Token, Tokenizer};
use unicode_normalization::UnicodeNormalization;

/// Tokens per text of every CLIP text tower (OpenAI's and open_clip's).
pub const CONTEXT_LENGTH: usize = 77;

/// Token id of `<start_of_text>` in CLIP's vocabulary.
pub const START_OF_TEXT: u32 = 49406;

/// Token id of `<end_of_text>`: the largest id, which is why the EOT position is the argmax.
pub const END_OF_TEXT: u32 = 49407;

/// Size of CLIP's vocabulary (the token embedding's rows).
pub const VOCAB_SIZE: usize = 49408;

/// CLIP's tokenizer with open_clip's clean-up.
pub struct ClipTokenizer {
    bpe: Tokenizer,
}

impl std::fmt::Debug for ClipTokenizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ClipTokenizer")
    }
}

impl Default for ClipTokenizer {
    fn default() -> Self {
        Self::new()
    }
}

impl ClipTokenizer {
    /// The tokenizer with the bundled vocabulary (building it parses the merge rules: keep one).
    pub fn new() -> Self {
        ClipTokenizer {
            bpe: Tokenizer::new(),
        }
    }

    /// The ids of `text` as open_clip's `tokenize` gives them: `<start_of_text>`, the text's
    /// tokens, `<end_of_text>`, without the zero padding. A text of more than 75 tokens is cut
    /// to its first 75 so that the end marker still fits the 77-token context.
    pub fn ids(&self, text: &str) -> Vec<u32> {
        let cleaned = clean(text);
        let mut tokens: Vec<Token> = vec![self.bpe.start_of_text()];
        self.bpe.encode(&cleaned, &mut tokens);
        tokens.truncate(CONTEXT_LENGTH - 1);
        tokens.push(self.bpe.end_of_text());
        tokens.into_iter().map(|t| u32::from(t.to_u16())).collect()
    }

    /// [`ClipTokenizer::ids`] padded with zeros to [`CONTEXT_LENGTH`].
    pub fn padded_ids(&self, text: &str) -> Vec<u32> {
        let mut ids = self.ids(text);
        ids.resize(CONTEXT_LENGTH, 0);
        ids
    }
}

/// open_clip's `_clean_lower` (see the module docs for which parts of ftfy are done).
pub fn clean(text: &str) -> String {
    let fixed: String = text.chars().map(fix_char).collect();
    let fixed: String = fixed.nfc().collect();
    // open_clip unescapes twice, so "&amp;amp;" becomes "&".
    let once = html_escape::decode_html_entities(&fixed);
    let twice = html_escape::decode_html_entities(&once);
    let collapsed = twice.split_whitespace().collect::<Vec<_>>().join(" ");
    collapsed.to_lowercase()
}

/// ftfy's per-character fixes: quotes, ligatures, character width.
fn fix_char(c: char) -> Cow<'static, str> {
    let s: &'static str = match c {
        // uncurl_quotes
        '\u{2018}' | '\u{2019}' | '\u{201A}' | '\u{201B}' => "'",
        '\u{201C}' | '\u{201D}' | '\u{201E}' | '\u{201F}' => "\"",
        // fix_latin_ligatures
        '\u{FB00}' => "ff",
        '\u{FB01}' => "fi",
        '\u{FB02}' => "fl",
        '\u{FB03}' => "ffi",
        '\u{FB04}' => "ffl",
        '\u{FB05}' | '\u{FB06}' => "st",
        '\u{0132}' => "IJ",
        '\u{0133}' => "ij",
        // fix_character_width: the ideographic space and full-width ASCII.
        '\u{3000}' => " ",
        c @ '\u{FF01}'..='\u{FF5E}' => {
            let ascii = char::from_u32(c as u32 - 0xFEE0).unwrap_or(c);
            return Cow::Owned(ascii.to_string());
        }
        c => return Cow::Owned(c.to_string()),
    };
    Cow::Borrowed(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clean_does_what_open_clip_does_to_typed_text() {
        assert_eq!(clean("  Glass\tOF \n water "), "glass of water");
        assert_eq!(clean("fish &amp;amp; chips"), "fish & chips");
        assert_eq!(clean("it\u{2019}s \u{201C}x\u{201D}"), "it's \"x\"");
        assert_eq!(clean("\u{FB01}sh"), "fish");
        assert_eq!(clean("\u{FF52}\u{FF45}\u{FF44}"), "red");
        assert_eq!(clean("cafe\u{301}"), "caf\u{e9}");
    }
}
