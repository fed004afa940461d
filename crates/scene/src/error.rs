//! Scene loading errors. Every error names the file and, where the format has lines,
//! the line, so that a user can go straight to the problem.

use std::fmt;
use std::path::PathBuf;

#[derive(Debug)]
pub enum SceneError {
    /// The file could not be opened or read.
    Io { path: PathBuf, source: std::io::Error },
    /// The file was read but its content is malformed.
    Parse { path: PathBuf, line: Option<usize>, message: String },
    /// The file extension or scene name is not known.
    Unsupported { what: String },
    /// The scene is structurally invalid (e.g. no camera and no geometry to frame).
    Invalid { message: String },
}

impl SceneError {
    pub fn parse(path: impl Into<PathBuf>, line: Option<usize>, message: impl Into<String>) -> Self {
        SceneError::Parse { path: path.into(), line, message: message.into() }
    }
}

/// `s` with control characters (ESC, BEL, CR, ...) written as escapes (`\u{1b}`), so that text
/// quoted from a file cannot drive the terminal it is printed on.
pub fn escape_control(s: &str) -> String {
    if !s.chars().any(char::is_control) {
        return s.to_string();
    }
    s.chars().map(|c| if c.is_control() { c.escape_default().to_string() } else { c.to_string() }).collect()
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let text = match self {
            SceneError::Io { path, source } => format!("{}: {}", path.display(), source),
            SceneError::Parse { path, line: Some(l), message } => {
                format!("{}:{}: {}", path.display(), l, message)
            }
            SceneError::Parse { path, line: None, message } => format!("{}: {}", path.display(), message),
            SceneError::Unsupported { what } => format!("unsupported: {what}"),
            SceneError::Invalid { message } => format!("invalid scene: {message}"),
        };
        f.write_str(&escape_control(&text))
    }
}

impl std::error::Error for SceneError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            SceneError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// The 1-based line of byte offset `span.start` in `src` (for TOML spans).
pub(crate) fn line_of(src: &str, span: std::ops::Range<usize>) -> usize {
    src[..span.start.min(src.len())].bytes().filter(|&b| b == b'\n').count() + 1
}
