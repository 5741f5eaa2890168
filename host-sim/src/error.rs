//! Errors that point into an input: the file, and where known the line and column. They print
//! as `file:line:column: message` (the form editors jump to) and give `--json` its `error`
//! object's fields without re-parsing text.

use std::fmt;

/// A problem at a place in an input.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Located {
    /// The input's name as given (`<stdin>` for `-`).
    pub file: String,
    /// 1-based line, when the problem is on one line.
    pub line: Option<u64>,
    /// 1-based column (field number in a CSV), when the problem is in one cell.
    pub column: Option<u64>,
    /// What is wrong.
    pub message: String,
}

impl Located {
    /// A problem with a whole file.
    pub fn file(file: &str, message: impl Into<String>) -> Self {
        Self { file: file.to_string(), line: None, column: None, message: message.into() }
    }

    /// A problem on a line (and in a column).
    pub fn at(file: &str, line: u64, column: Option<u64>, message: impl Into<String>) -> Self {
        Self { file: file.to_string(), line: Some(line), column, message: message.into() }
    }
}

impl fmt::Display for Located {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.column {
                write!(f, ":{c}")?;
            }
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for Located {}

/// A problem with one recording as a whole (a drive that never changes, too few samples), under
/// the recording's name. On the command line every recording is a file, so `--json` gives the
/// name as the error's `file`; the Python API does not, as its recordings may be arrays under
/// a caller's label.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InRecording {
    /// The recording's name (a file's path as given, `<stdin>`, or a caller's label).
    pub recording: String,
    /// What is wrong.
    pub message: String,
}

impl InRecording {
    /// `message` about the recording named `recording`, as an error.
    pub fn error(recording: &str, message: impl Into<String>) -> anyhow::Error {
        Self { recording: recording.to_string(), message: message.into() }.into()
    }
}

impl fmt::Display for InRecording {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.recording, self.message)
    }
}

impl std::error::Error for InRecording {}

/// Returns early with a [`Located`] error: `located!(file, line, col; "format", args…)`
/// (`line`, `col` are `Option`s), or `located!(file; "format", args…)` for a whole file.
#[macro_export]
macro_rules! located {
    ($file:expr; $($fmt:tt)*) => {
        return Err($crate::error::Located::file(&$file, format!($($fmt)*)).into())
    };
    ($file:expr, $line:expr, $col:expr; $($fmt:tt)*) => {
        return Err($crate::error::Located {
            file: $file.to_string(),
            line: $line,
            column: $col,
            message: format!($($fmt)*),
        }
        .into())
    };
}
