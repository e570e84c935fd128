//! Errors of the ingest stage: every one names the file, what is wrong and where.

use std::fmt;
use std::path::PathBuf;

/// Where in an input file a problem was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    /// 1-based line number of a text file (for `.ply.gz`: of the decompressed text).
    Line(u64),
    /// Byte offset from the start of the file (for `.ply.gz`: of the decompressed stream).
    Byte(u64),
    /// Record `index` (0-based) of PLY element `element`, starting at byte `offset`
    /// (decompressed offset for gzip input).
    Record {
        /// The PLY element.
        element: String,
        /// The record's index in the element (0-based).
        index: u64,
        /// Byte offset where the record starts.
        offset: u64,
    },
    /// Nowhere more precise than the file itself.
    File,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte offset {b}"),
            Location::Record {
                element,
                index,
                offset,
            } => {
                write!(f, "{element} {index} (byte offset {offset})")
            }
            Location::File => write!(f, "whole file"),
        }
    }
}

/// Why a mesh cannot be read. Bad input never panics; it ends up here.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// The operating system refused to open, map or read the file.
    #[error("{}: cannot read: {source}", .path.display())]
    Io {
        /// The input file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The input is a directory, device or FIFO: a mesh is read more than once.
    #[error("{}: it is {what}, not a mesh file (the input must be a regular file)", .path.display())]
    NotAFile {
        /// The input file.
        path: PathBuf,
        /// What it is instead (a directory, a device, a FIFO, …).
        what: &'static str,
    },
    /// The file has no bytes at all.
    #[error("{}: the file is empty", .path.display())]
    Empty {
        /// The input file.
        path: PathBuf,
    },
    /// Neither the extension nor the first bytes say PLY, OBJ or STL.
    #[error("{}: unknown mesh format: {reason}", .path.display())]
    UnknownFormat {
        /// The input file.
        path: PathBuf,
        /// Why the format was not recognized.
        reason: String,
    },
    /// The PLY header (or the STL preamble) is not well formed.
    #[error("{}: malformed header at line {line}: {message}", .path.display())]
    Header {
        /// The input file.
        path: PathBuf,
        /// 1-based line number.
        line: u64,
        /// What is wrong, in words.
        message: String,
    },
    /// A value in the body cannot be parsed or makes no sense (bad number, absurd list count,
    /// missing or extra values on a line, unknown keyword).
    #[error("{}: {at}: {message}", .path.display())]
    Malformed {
        /// The input file.
        path: PathBuf,
        /// Where in the file.
        at: Location,
        /// What is wrong, in words.
        message: String,
    },
    /// The file ends before the data its header (or its own counts) promise.
    #[error("{}: truncated at {at}: {what} needs {expected} bytes but only {got} are left", .path.display())]
    Truncated {
        /// The input file.
        path: PathBuf,
        /// Where in the file.
        at: Location,
        /// What was being read.
        what: String,
        /// Bytes needed.
        expected: u64,
        /// Bytes left in the file.
        got: u64,
    },
    /// A face refers to a vertex that does not exist.
    #[error(
        "{}: {at}: face {face} corner {corner} refers to vertex {index}, but the file has {vertices} vertices",
        .path.display()
    )]
    IndexOutOfRange {
        /// The input file.
        path: PathBuf,
        /// Where in the file.
        at: Location,
        /// The face (0-based).
        face: u64,
        /// The corner within the face (0-based).
        corner: u64,
        /// The vertex index as written.
        index: i64,
        /// Vertices in the file.
        vertices: u64,
    },
    /// A vertex coordinate is NaN or infinite. Such input is refused, not silently dropped.
    #[error("{}: {at}: vertex {vertex} has a non-finite coordinate {coords:?}", .path.display())]
    NonFinite {
        /// The input file.
        path: PathBuf,
        /// Where in the file.
        at: Location,
        /// The vertex (0-based).
        vertex: u64,
        /// Its coordinates as read.
        coords: [f64; 3],
    },
    /// The OBJ reader (tobj) failed; tobj does not report where, so neither can we.
    #[error("{}: OBJ reader (tobj) failed: {message}", .path.display())]
    Obj {
        /// The input file.
        path: PathBuf,
        /// What is wrong, in words.
        message: String,
    },
    /// A stream of triangles with their face records
    /// ([`crate::MeshSource::stream_indexed_prepared`]) met a face record that is not a
    /// triangle record at its fixed offset: the faces are not fixed-size records after all.
    /// The caller reads the input the general way instead.
    #[error("{}: face {face} is not a triangle record of the element's fixed size, so faces cannot be found by index", .path.display())]
    NotFixedRecords {
        /// The input file.
        path: PathBuf,
        /// The first face record that is not a triangle record.
        face: u64,
    },
    /// A triangle asked for by its face record ([`crate::MeshSource::triangles_at`]) is not
    /// what the stream gave for it (a record that is no longer a non-degenerate triangle):
    /// the input changed during the build.
    #[error("{}: face {face} no longer holds the triangle read from it earlier in this build: the input changed during the build", .path.display())]
    FaceChanged {
        /// The input file.
        path: PathBuf,
        /// The face record.
        face: u64,
    },
    /// The caller's batch callback failed; streaming stopped there. Its error is kept whole
    /// (and shown as it is): the caller takes its own type back with `downcast`.
    #[error(transparent)]
    Callback(Box<dyn std::error::Error + Send + Sync>),
}

impl IngestError {
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        IngestError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn malformed(
        path: &std::path::Path,
        at: Location,
        message: impl Into<String>,
    ) -> Self {
        IngestError::Malformed {
            path: path.to_path_buf(),
            at,
            message: message.into(),
        }
    }
}

/// A token from a file as a message shows it: in double quotes, control characters, quotes
/// and backslashes as `\xNN` (not Rust's debug escapes such as `\u{1}`), at most 40
/// characters.
pub(crate) fn quoted(token: &str) -> String {
    let mut out = String::from("\"");
    for (n, c) in token.chars().enumerate() {
        if n == 40 {
            out.push('…');
            break;
        }
        if c.is_control() || c == '"' || c == '\\' {
            let mut b = [0u8; 4];
            for byte in c.encode_utf8(&mut b).bytes() {
                out.push_str(&format!("\\x{byte:02x}"));
            }
        } else {
            out.push(c);
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod quoted_tests {
    #[test]
    fn tokens_are_quoted_without_rust_escapes() {
        assert_eq!(super::quoted("vertx"), "\"vertx\"");
        assert_eq!(
            super::quoted("prope\u{1}\0\0\0float"),
            "\"prope\\x01\\x00\\x00\\x00float\""
        );
        assert_eq!(super::quoted("é"), "\"é\"");
    }
}
