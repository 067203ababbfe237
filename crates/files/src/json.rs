//! Reading JSON inputs (plans, calibrations, reports): every error names
//! the file and says what it should have been, and whether it is not JSON
//! at all or JSON of another kind.

use std::path::Path;

use anyhow::Context;
use serde::de::DeserializeOwned;

/// What a plan file should be.
pub const PLAN: &str = "a twindrive mission plan";

/// Reads `path` as `what` (e.g. "a twindrive mission plan").
pub fn read<T: DeserializeOwned>(path: &Path, what: &str) -> anyhow::Result<T> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    parse(&bytes, path, what)
}

/// Parses the bytes of `path` as `what`.
pub fn parse<T: DeserializeOwned>(bytes: &[u8], path: &Path, what: &str) -> anyhow::Result<T> {
    serde_json::from_slice(bytes).map_err(|e| anyhow::anyhow!(describe(&e, path, what)))
}

fn describe(e: &serde_json::Error, path: &Path, what: &str) -> String {
    use serde_json::error::Category;
    let text = e.to_string();
    let position = format!(" at line {} column {}", e.line(), e.column());
    let bare = text.strip_suffix(&position).unwrap_or(&text);
    let path = path.display();
    match e.classify() {
        Category::Data => format!(
            "{path} is not {what}: a JSON document, but not {what} ({bare}, line {}, column {})",
            e.line(),
            e.column()
        ),
        Category::Eof if e.line() <= 1 && e.column() == 0 => {
            format!("{path} is not {what}: an empty file")
        }
        Category::Syntax | Category::Eof => format!(
            "{path} is not {what}: not JSON (line {}, column {}: {bare})",
            e.line(),
            e.column()
        ),
        Category::Io => format!("{path}: {text}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[allow(dead_code)]
    struct Thing {
        header: u32,
    }

    fn err(bytes: &str) -> String {
        parse::<Thing>(bytes.as_bytes(), Path::new("t.json"), "a thing")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn says_what_the_file_is_and_what_was_expected() {
        assert_eq!(
            err("x,y\n"),
            "t.json is not a thing: not JSON (line 1, column 1: expected value)"
        );
        assert_eq!(
            err("{\"other\": 1}"),
            "t.json is not a thing: a JSON document, but not a thing (missing field `header`, line 1, column 12)"
        );
        assert_eq!(err(""), "t.json is not a thing: an empty file");
        assert_eq!(
            parse::<Thing>(b"{\"header\": 3}", Path::new("t.json"), "a thing")
                .unwrap()
                .header,
            3
        );
    }
}
