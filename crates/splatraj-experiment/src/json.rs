//! JSON read strictly: one value and nothing after it, errors with the key path (a leaf: the
//! camera files, the checkpoint and whatever else reads JSON share it).

use serde::de::DeserializeOwned;

/// `text` as exactly one JSON value of type `T`: anything but white space after the value is
/// refused (serde_json's reader stops after one value, so a file with a second object or stray
/// text after it would otherwise be read as if it ended there). On an error, the key path where
/// it happened (`.` for the whole document, or after the value) and serde's message.
pub fn strict_json<T: DeserializeOwned>(text: &str) -> Result<T, (String, serde_json::Error)> {
    let mut deserializer = serde_json::Deserializer::from_str(text);
    let value = serde_path_to_error::deserialize(&mut deserializer)
        .map_err(|e| (e.path().to_string(), e.into_inner()))?;
    deserializer.end().map_err(|e| (".".to_string(), e))?;
    Ok(value)
}
