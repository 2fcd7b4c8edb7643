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
        count_steps(before.len());
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

    /// The locations of every byte offset in `offsets`, in their order, in
    /// one pass over `text` (sorted offsets, a sweep): a job with 100,000
    /// eye points is located in linear time, where [`Location::of`] per key
    /// would rescan the text before each.
    pub(crate) fn all(text: &str, offsets: &[usize]) -> Vec<Location> {
        let bytes = text.as_bytes();
        let mut order: Vec<usize> = (0..offsets.len()).collect();
        order.sort_unstable_by_key(|&i| offsets[i]);
        let mut locations = vec![Location { line: 1, column: 1 }; offsets.len()];
        // The sweep's position: the byte reached, its line, that line's
        // start, and the characters from the line's start to it.
        let (mut at, mut line, mut line_start, mut column) = (0, 1, 0, 0);
        for i in order {
            let offset = offsets[i].min(bytes.len());
            count_steps(offset.saturating_sub(at));
            while at < offset {
                if bytes[at] == b'\n' {
                    (line, line_start, column) = (line + 1, at + 1, 0);
                } else if bytes[at] & 0xc0 != 0x80 {
                    // Not a UTF-8 continuation byte: a character starts here.
                    column += 1;
                }
                at += 1;
            }
            // The line starts on a character, so its bytes up to `offset`
            // are characters exactly when `offset` is on a boundary.
            let column = if text.is_char_boundary(offset) {
                column
            } else {
                // Not on a character boundary (spans from toml always are):
                // bytes, as `of` counts them.
                offset - line_start
            };
            locations[i] = Location {
                line,
                column: column + 1,
            };
        }
        locations
    }
}

#[cfg(test)]
thread_local! {
    /// Bytes of job text the locator stepped over on this thread (tests
    /// only): the measure of its work, which must grow with the text, not
    /// with the keys located in it.
    static LOCATOR_STEPS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Counts `bytes` of text stepped over by the locator (a no-op outside tests).
fn count_steps(bytes: usize) {
    #[cfg(test)]
    LOCATOR_STEPS.with(|steps| steps.set(steps.get() + bytes));
    #[cfg(not(test))]
    let _ = bytes;
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

    /// The one-pass sweep gives what `of` gives for every offset, in any
    /// order, past the end and inside a character included.
    #[test]
    fn all_locations_in_one_pass_equal_each_located_alone() {
        let text = "a = 1\nbé = [[1, 2], [3, é]]\n\nlast";
        let mut offsets: Vec<usize> = (0..=text.len() + 2).rev().collect();
        offsets.extend([7, 0, 7]);
        let alone: Vec<Location> = offsets.iter().map(|&o| Location::of(text, o)).collect();
        assert_eq!(Location::all(text, &offsets), alone);
    }

    /// How many bytes the locator steps over while `f` runs.
    fn locator_steps<T>(f: impl FnOnce() -> T) -> (usize, T) {
        let before = LOCATOR_STEPS.with(|s| s.get());
        let value = f();
        (LOCATOR_STEPS.with(|s| s.get()) - before, value)
    }

    /// A job file is located in one pass over its text, however many keys
    /// it holds: 20,000 eye points on lines of their own, 5,000 on one
    /// line, 1,000 material overrides with textures. Counted in bytes
    /// stepped over, not timed (a location computed per eye from the start
    /// of the text made 20,000 eyes take 7.6 s); every location is right.
    #[test]
    fn a_job_is_located_in_one_pass_over_its_text() {
        // Textures must exist beside the job (they are not read): the
        // crate's manifest stands in for one.
        let origin = Path::new(env!("CARGO_MANIFEST_DIR")).join("job.toml");
        let parsed_in_one_pass = |text: &str| {
            let (steps, job) = locator_steps(|| crate::parse_job(text, &origin));
            assert!(
                steps <= text.len(),
                "{steps} steps over {} bytes",
                text.len()
            );
            job.unwrap()
        };
        let cockpit = "[scene]\nbuiltin = \"cockpit\"\n";
        let eyes: String = (0..20_000)
            .map(|i| format!("  [{}, 1.2, 0.4],\n", i as f32 * 1e-5))
            .collect();
        let job = parsed_in_one_pass(&format!("{cockpit}[frames]\neyes = [\n{eyes}]\n"));
        assert_eq!(job.eyes.len(), 20_000);
        // Eye i stands on line 5 + i, after its two leading spaces.
        for i in [0, 1, 12_345, 19_999] {
            let at = job.locations[&format!("frames.eyes[{i}]")];
            assert_eq!((at.line, at.column), (5 + i, 3), "eye {i}");
        }

        let one_line: Vec<String> = (0..5_000)
            .map(|i| format!("[{}, 1.2, 0.4]", i as f32 * 1e-5))
            .collect();
        let job = parsed_in_one_pass(&format!(
            "{cockpit}[frames]\neyes = [{}]\n",
            one_line.join(", ")
        ));
        let column = "eyes = [".len() + (one_line[..7].iter()).map(|e| e.len() + 2).sum::<usize>();
        let at = job.locations["frames.eyes[7]"];
        assert_eq!((at.line, at.column), (4, column + 1));

        let materials: String = (0..1_000)
            .map(|i| {
                format!("[materials.\"m{i}\"]\ntexture = \"Cargo.toml\"\nkr = [0.5, 0.5, 0.5]\n")
            })
            .collect();
        let job = parsed_in_one_pass(&format!("{cockpit}{materials}"));
        let m = job.locations["materials.\"m999\""];
        assert_eq!((m.line, m.column), (3 + 3 * 999, 12));
        let t = job.locations["materials.\"m999\".texture"];
        assert_eq!((t.line, t.column), (4 + 3 * 999, 11));
    }
}
