//! Errors of job files. Every message starts with the job file's path and,
//! where the offending key is known, its line and column, the way compilers
//! report (`jobs/cab.toml:7:9: camera.width = 0: must be 1 to 16384`), so
//! editors and terminals can jump to it.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::ReflectorSelector;
use vtfarm_scene::obj::ObjError;

/// A 1-based line and column (in characters) in a job file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Location {
    pub line: usize,
    pub column: usize,
}

impl Location {
    /// The location of byte `offset` in `text`.
    pub(crate) fn of(text: &str, offset: usize) -> Location {
        let before = &text.as_bytes()[..offset.min(text.len())];
        let line_start = before
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |i| i + 1);
        let line_bytes = &before[line_start..];
        // Columns count characters, as editors do; spans from toml always sit on
        // character boundaries, the byte count is only a fallback.
        let column =
            std::str::from_utf8(line_bytes).map_or(line_bytes.len(), |s| s.chars().count());
        Location {
            line: before.iter().filter(|&&b| b == b'\n').count() + 1,
            column: column + 1,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.column)
    }
}

/// Why a job could not be read, validated or set up.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// The job file could not be read.
    #[error("{file}: cannot read job file: {source}")]
    Read {
        file: PathBuf,
        source: std::io::Error,
    },
    /// The job file is not a valid job: TOML syntax, an unknown key, a wrong
    /// type, a missing key or a value out of range.
    #[error("{}: {message}", place(.file, .location))]
    Invalid {
        file: PathBuf,
        /// Where in the file, when the error can be tied to a key.
        location: Option<Location>,
        message: String,
    },
    /// The OBJ scene named by the job failed to load.
    // The importer's message already names the OBJ file and line. It is part
    // of this message and deliberately not a `source`: printing the error
    // chain would repeat it.
    #[error("{file}: cannot load the OBJ scene: {error}")]
    Obj {
        file: PathBuf,
        obj: PathBuf,
        // Boxed: the importer's error is large and this path is cold.
        error: Box<ObjError>,
    },
    /// The glTF scene named by the job failed to load.
    #[error("{file}: cannot load the glTF scene: {error}")]
    Gltf {
        file: PathBuf,
        error: Box<vtfarm_scene::gltf::GltfError>,
    },
    /// A `[reflectors]` name matches no triangle of the scene.
    #[error(
        "{}: reflector {selector} matches no triangle (objects: {}; materials: {})",
        place(.file, .location),
        .objects.join(", "),
        .materials.join(", ")
    )]
    NoReflector {
        file: PathBuf,
        /// Where the name stands in the job file.
        location: Option<Location>,
        // Boxed: keeps the error small on the hot `Result` paths.
        selector: Box<ReflectorSelector>,
        /// The scene's object names, to spot a misspelling.
        objects: Vec<String>,
        /// The scene's material names.
        materials: Vec<String>,
    },
}

/// `file:line:column`, or just `file` when the location is unknown.
fn place(file: &Path, location: &Option<Location>) -> String {
    match location {
        Some(at) => format!("{}:{at}", file.display()),
        None => file.display().to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_are_one_based_and_count_characters() {
        let text = "a = 1\nbé = 2\n";
        assert_eq!(Location::of(text, 0), Location { line: 1, column: 1 });
        assert_eq!(Location::of(text, 6), Location { line: 2, column: 1 });
        // "bé " is 4 bytes but 3 characters.
        assert_eq!(Location::of(text, 10), Location { line: 2, column: 4 });
        assert_eq!(Location::of(text, 999), Location { line: 3, column: 1 });
    }
}
