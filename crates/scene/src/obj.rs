//! Wavefront OBJ/MTL import (through `tobj`) and export.
//!
//! # Import
//!
//! [`load_obj`] first checks the OBJ file and every MTL library it names line
//! by line, because `tobj` reports errors without line numbers and panics or
//! overflows on some malformed input (`Kd 1 2`, face index 0 with texture
//! coordinates). Only text that passed the check reaches `tobj`, as a
//! normalised copy (lines trimmed, inline comments and `l` polylines dropped,
//! `\` in file names turned into `/`), so every error message names the file
//! and, for a bad line, its number. Quoted input in messages is cut short.
//!
//! What exporters write and vtfarm accepts: CRLF line ends, a byte-order
//! mark, tabs, trailing spaces after names, inline comments (`Ka 0.1 0.1 0.8
//! # Blue`: a `#` that starts a word ends the line, except on lines that carry
//! a name or file name — `o`, `g`, `usemtl`, `newmtl`, `mtllib`, textures —
//! where `Material #25` is a name), Windows paths (`textures\glass.png`).
//! Textures: `map_Kd` and `map_d` are loaded (PNG, JPEG; see
//! [`crate::texture`]) with the faces' `vt` coordinates per corner; one that
//! cannot be read is an [`ObjWarning`] at its MTL line (logged by
//! [`load_obj`]) and the material keeps its flat colour. Other texture
//! kinds are not used: a missing one is a warning too, not an error.
//!
//! Refused with file and line: non-finite numbers and vertex coordinates
//! beyond ±[`MAX_COORDINATE`], and faces with more than
//! [`MAX_FACE_VERTICES`] vertices.
//!
//! Each OBJ object or group (`o`/`g`) becomes an [`Object`]; groups that share
//! a name share the object. Faces before the first `o`/`g` belong to an
//! object named after their material (`usemtl`), as other tools do, or
//! "default". Points and lines are ignored; polygons are triangulated as fans.
//! Faces before any `usemtl` get the material named "default" (the MTL's, or
//! [`Material::default`]). A model whose faces all
//! carry `vn` normals keeps them (normalised); otherwise its normals are
//! computed per object by [`normals::compute_normals`] with the crease angle
//! from [`ObjOptions`]. The result is in the vertex layout of
//! [`normals::compute_scene_normals`]: per run of triangles with one object
//! and material, vertices in order of first use.
//!
//! # MTL mapping
//!
//! | MTL                | [`Material`]                                           |
//! |--------------------|--------------------------------------------------------|
//! | `Ka r g b`         | `ambient` (default: the diffuse colour)                |
//! | `Kd r g b`         | `diffuse` (default: 0.6 grey)                          |
//! | `Ks r g b`         | `specular` (default: black)                            |
//! | `Ns s`             | `shininess` (default: 1)                               |
//! | `Ke r g b`         | `emission` (default: black)                            |
//! | `Kr r g b`         | `reflectance`, overriding `illum` (vtfarm extension)   |
//! | `illum 3` to `7`   | `reflectance = Ks` (the specification's ray-traced     |
//! |                    | models); 5 and 7 without `Ks`: Fresnel at normal       |
//! |                    | incidence from `Ni`, `((Ni - 1) / (Ni + 1))²`, glass   |
//! |                    | (1.5) without `Ni`                                     |
//! | `illum 5`, `7`     | `fresnel`: "Fresnel on", kr rises towards grazing      |
//! | `illum 6`, `7`     | `transmittance` times `1 - kr` (the spec's `(1-Ks) Tf`)|
//! |                    | unless `Kr` is given                                   |
//! | other `illum`      | `reflectance` = that Fresnel term when the material    |
//! |                    | transmits and has `Ni`, otherwise 0                    |
//!
//! The reflectance rule is [`crate::mtl_reflectance`]'s.
//! | `d a`              | `transmittance = 1 - a` (clamped to 0..=1)             |
//! | `Tr t`             | `transmittance = t` when there is no `d`               |
//! | `Tf r g b`         | filters the transmittance; with `illum 4`/`6`/`7` and  |
//! |                    | no `d`/`Tr` it is the transmittance                    |
//! | `Ni n`             | `ior` (default: 1)                                     |
//! | `map_Kd file`      | `diffuse_texture`: the base colour, times `Kd`, `Ka`   |
//! | `map_d file`       | `alpha_texture`: alpha (or grey), times `d`            |
//! | other `map_*`, …   | checked to exist (a warning if not); not used          |
//!
//! kr is the head-on reflectance; for `illum` 5 and 7, or any material with
//! `[quality] fresnel`, the tracer raises it towards grazing angles (the
//! Fresnel equations at `Ni` for see-through materials, Schlick's
//! approximation for opaque ones).
//!
//! # Export
//!
//! [`write_obj`] writes `name.obj` and `name.mtl` so that [`load_obj`] gives
//! the same scene back: floats are printed with Rust's shortest round-trip
//! formatting, and a scene that came from [`load_obj`] reloads bit for bit.
//! MTL's `d` is a single number, so a transmittance that is not grey is
//! written (and read back) as its mean. Textures are written beside them
//! as PNG (`NAME_textureI.png`), with a `vt` per triangle corner. MTL has
//! no thin sheet: a `thin` material is written as what its rays do, `Ni 1`.

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;
use std::fs;
use std::io;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::file;
use crate::normals::{self, DEFAULT_CREASE_ANGLE_DEG};
use crate::{
    Material, MaterialId, Object, ObjectId, Scene, SceneError, Texture, TextureId, Triangle,
};
use crate::{MtlOptics, mtl_reflectance};

/// Options for [`load_obj`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjOptions {
    /// Crease angle in degrees for normals computed for models that have no
    /// `vn` normals; see [`normals::compute_normals`].
    pub crease_angle_deg: f32,
    /// Keep the faces' texture coordinates even when no material of the
    /// file is textured (a job gives one a texture); otherwise they are kept
    /// only for textured scenes.
    pub keep_uvs: bool,
}

impl Default for ObjOptions {
    fn default() -> Self {
        ObjOptions {
            crease_angle_deg: DEFAULT_CREASE_ANGLE_DEG,
            keep_uvs: false,
        }
    }
}

pub use crate::MAX_COORDINATE;

/// The most vertices one face may have. A face's fan puts all its triangles
/// around one vertex, where computing normals costs O(k²) in the worst case
/// (a badly non-planar face; a flat one costs O(k)), so the size is bounded.
pub const MAX_FACE_VERTICES: usize = 65_536;

/// How many characters of user input an error message quotes.
const QUOTE_CHARS: usize = 40;

/// Why an OBJ or MTL file could not be read or written. Every message starts
/// with the file concerned and, for a bad line, `:line`. Messages are
/// complete in themselves: a variant's `Display` includes the I/O error it
/// carries, so none is reported as a separate `source` (printing the chain
/// would repeat it).
#[derive(Debug, thiserror::Error)]
pub enum ObjError {
    /// A file could not be read or written.
    #[error("{}: {error}", .path.display())]
    Io { path: PathBuf, error: io::Error },
    /// A line of an OBJ or MTL file is malformed.
    #[error("{}:{line}: {error}", .path.display())]
    Syntax {
        path: PathBuf,
        line: usize,
        error: LineError,
    },
    /// A file named on a line (`mtllib`) cannot be read.
    #[error("{}:{line}: cannot read {what} {}: {error}", .path.display(), .file.display())]
    Reference {
        path: PathBuf,
        line: usize,
        what: &'static str,
        file: PathBuf,
        error: io::Error,
    },
    /// The file as a whole is unusable (no triangles, a scene that cannot be
    /// written, an error `tobj` found that the line check did not).
    #[error("{}: {message}", .path.display())]
    Invalid { path: PathBuf, message: String },
}

/// A value that is not what its keyword takes.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ValueError {
    /// The word, quoted.
    #[error("{0} is not a finite number")]
    NotFinite(String),
    #[error("expected a number, found {0}")]
    OneNumber(usize),
    #[error("expected {expected} numbers, found {found}")]
    Numbers { expected: usize, found: usize },
    #[error("expected {start} to {end} numbers, found {found}")]
    NumberRange {
        start: usize,
        end: usize,
        found: usize,
    },
    #[error("expected r g b or one number")]
    Filter,
}

/// A face index that names no element.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IndexError {
    /// The text, quoted.
    #[error("{kind} index {text} is not an integer")]
    NotInteger { kind: &'static str, text: String },
    #[error("{kind} index 0 (OBJ indices start at 1)")]
    Zero { kind: &'static str },
    #[error("{kind} index {index} is out of range: {defined} defined so far")]
    OutOfRange {
        kind: &'static str,
        index: isize,
        defined: usize,
    },
}

/// What is wrong with one line of an OBJ or MTL file (the message of an
/// [`ObjError::Syntax`]). Quoted input is cut short.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LineError {
    #[error("not valid UTF-8")]
    NotUtf8,
    /// A keyword's numbers (`v`, `vt`, `vn`, `Kd`, `Ns`, …).
    #[error("{keyword}: {error}")]
    Value { keyword: String, error: ValueError },
    #[error("v: expected x y z, x y z w or x y z r g b")]
    VertexForm,
    #[error("v: cannot divide by w = {0}")]
    ZeroW(f32),
    #[error("v: coordinate {0} is beyond ±{MAX_COORDINATE:e}, the largest vtfarm traces precisely")]
    Coordinate(f32),
    #[error("v: vertex colours must be given for all vertices or none")]
    MixedColours,
    /// The face vertex, quoted.
    #[error("f: {vertex}: {error}")]
    FaceIndex { vertex: String, error: IndexError },
    #[error("f: {0} has more than v/vt/vn")]
    FaceVertexParts(String),
    #[error(
        "f: a face with more than {MAX_FACE_VERTICES} vertices; split it into smaller polygons"
    )]
    FaceTooLarge,
    #[error("f: a face needs at least 3 vertices, found {0}")]
    FaceTooSmall(usize),
    #[error("usemtl without a material name")]
    UsemtlWithoutName,
    /// The name, quoted.
    #[error("usemtl names material {0}, which no mtllib defines")]
    UnknownMaterial(String),
    #[error("mtllib without a file name")]
    MtllibWithoutName,
    #[error("newmtl: no material name")]
    NoMaterialName,
    /// The text, quoted.
    #[error("illum: {0} is not a model number")]
    Illum(String),
    #[error("{0}: no texture file name")]
    NoTextureName(String),
}

/// A material value tobj handed on that does not parse.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("material {material}: {key}: {error}")]
pub struct MaterialError {
    /// The name, quoted.
    pub material: String,
    pub key: &'static str,
    pub error: ValueError,
}

/// Why a scene cannot be written as OBJ.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WriteError {
    #[error(transparent)]
    Invalid(#[from] SceneError),
    #[error("vertex {0} is not finite")]
    NotFinite(usize),
    #[error("material {0:?} has a non-finite value")]
    MaterialNotFinite(String),
    #[error("{what} name {name:?} cannot be written to OBJ")]
    Name { what: &'static str, name: String },
    #[error("two {what}s are named {name:?}")]
    Duplicate { what: &'static str, name: String },
}

/// Something in an OBJ or MTL file that vtfarm ignores but a user may want
/// to fix (a missing texture).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}:{line}: {message}", .path.display())]
pub struct ObjWarning {
    pub path: PathBuf,
    pub line: usize,
    pub message: String,
}

/// A loaded scene and the warnings found on the way.
#[derive(Clone, Debug)]
pub struct ImportedObj {
    pub scene: Scene,
    pub warnings: Vec<ObjWarning>,
}

/// Loads an OBJ file and the MTL libraries it names into a [`Scene`],
/// logging each [`ObjWarning`] with `tracing`.
///
/// See the [module documentation](self) for the mapping. Never panics; any
/// problem is an [`ObjError`] naming the file and, where there is one, the
/// line.
pub fn load_obj(path: &Path, options: &ObjOptions) -> Result<Scene, ObjError> {
    let imported = import_obj(path, options)?;
    for warning in &imported.warnings {
        tracing::warn!("{warning}");
    }
    Ok(imported.scene)
}

/// [`load_obj`], returning the warnings instead of logging them.
pub fn import_obj(path: &Path, options: &ObjOptions) -> Result<ImportedObj, ObjError> {
    let bytes =
        file::read_regular(path, file::MAX_SCENE_FILE_BYTES).map_err(|error| ObjError::Io {
            path: path.to_owned(),
            error,
        })?;
    let text = decode_text(path, bytes)?;
    let checked = check_obj(path, &text)?;
    // tobj's `merging` and `reordering` features add fields; keep their defaults.
    #[allow(clippy::needless_update)]
    let load_options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    // The libraries were read and checked already; tobj asks for them by the
    // name on the `mtllib` line.
    let libraries = |name: &Path| {
        name.to_str()
            .and_then(|name| checked.libraries.get(name))
            .cloned()
            .unwrap_or(Err(tobj::LoadError::OpenFileFailed))
    };
    let (models, materials) =
        tobj::load_obj_buf(&mut checked.text.as_bytes(), &load_options, libraries)
            .map_err(|e| invalid(path, format!("tobj: {e}")))?;
    let materials = materials.map_err(|e| invalid(path, format!("tobj: {e}")))?;
    let mut warnings = checked.warnings;
    let scene = build_scene(path, &models, &materials, options, |scene| {
        load_textures(scene, &checked.textures, &mut warnings)
    })?;
    tracing::debug!(
        path = %path.display(),
        vertices = scene.positions.len(),
        triangles = scene.triangles.len(),
        objects = scene.objects.len(),
        materials = scene.materials.len(),
        "loaded OBJ"
    );
    Ok(ImportedObj { scene, warnings })
}

/// Writes `scene` as `dir/name.obj` and `dir/name.mtl`.
///
/// The OBJ has one `mtllib` line, all vertices as `v` and `vn` (index `i` of
/// both is scene vertex `i - 1`), then the triangles in scene order as
/// `f v//vn`, with an `o` line whenever the object changes and a `usemtl` line
/// whenever the object or material changes. Objects without triangles are not
/// written. The MTL has every material with `Ka Kd Ks Ns Ke Ni d Kr` and
/// `illum 2`, or `illum 3` for mirrors.
///
/// Fails when the scene does not [validate](Scene::validate), holds
/// non-finite numbers, or has names that OBJ cannot carry (empty, with
/// surrounding whitespace or line breaks, or the same name twice).
pub fn write_obj(scene: &Scene, dir: &Path, name: &str) -> Result<(), ObjError> {
    let obj_path = dir.join(format!("{name}.obj"));
    let mtl_path = dir.join(format!("{name}.mtl"));
    check_writable(scene).map_err(|e| invalid(&obj_path, e.to_string()))?;
    let mtl_name = mtl_path
        .file_name()
        .map(|n| n.to_string_lossy())
        .unwrap_or_default();

    let mut obj = format!("# vtfarm scene\nmtllib {mtl_name}\n");
    for p in &scene.positions {
        let _ = writeln!(obj, "v {}", format_vec3(*p));
    }
    for n in &scene.normals {
        let _ = writeln!(obj, "vn {}", format_vec3(*n));
    }
    // Texture coordinates per triangle corner: `vt` 3i + k + 1 is corner k
    // of triangle i.
    for corners in &scene.corner_uvs {
        for uv in corners {
            let _ = writeln!(obj, "vt {} {}", uv.x, uv.y);
        }
    }
    let mut current = None;
    for (i, t) in scene.triangles.iter().enumerate() {
        let object = &scene.objects[t.object.index()].name;
        let material = &scene.materials[t.material.index()].name;
        match current {
            Some((o, _)) if o == t.object => {}
            _ => {
                let _ = writeln!(obj, "o {object}");
            }
        }
        if current != Some((t.object, t.material)) {
            let _ = writeln!(obj, "usemtl {material}");
            current = Some((t.object, t.material));
        }
        let [a, b, c] = t.vertices.map(|v| v + 1);
        if scene.corner_uvs.is_empty() {
            let _ = writeln!(obj, "f {a}//{a} {b}//{b} {c}//{c}");
        } else {
            let [ta, tb, tc] = [1, 2, 3].map(|k| 3 * i + k);
            let _ = writeln!(obj, "f {a}/{ta}/{a} {b}/{tb}/{b} {c}/{tc}/{c}");
        }
    }

    let mut mtl = String::from("# vtfarm materials\n");
    for m in &scene.materials {
        let _ = writeln!(mtl, "\nnewmtl {}", m.name);
        let _ = writeln!(mtl, "Ka {}", format_vec3(m.ambient));
        let _ = writeln!(mtl, "Kd {}", format_vec3(m.diffuse));
        let _ = writeln!(mtl, "Ks {}", format_vec3(m.specular));
        let _ = writeln!(mtl, "Ns {}", m.shininess);
        let _ = writeln!(mtl, "Ke {}", format_vec3(m.emission));
        // MTL has no thin sheet: one is written as what its rays do (`Ni
        // 1`, straight through), and its Fresnel index is not kept.
        let _ = writeln!(mtl, "Ni {}", if m.thin { 1.0 } else { m.ior });
        let _ = writeln!(mtl, "d {}", 1.0 - grey(m.transmittance));
        // illum 3 tells other readers "ray-traced mirror" (5 and 7 with
        // the material's own Fresnel); Kr gives ours the exact reflectance
        // (also 0, which `Ni` with `d` < 1 would otherwise turn into
        // Fresnel reflectance).
        let illum = match (m.fresnel, m.transmittance.max_element() > 0.0) {
            (true, false) => 5,
            (true, true) => 7,
            _ if m.reflectance.max_element() > 0.0 => 3,
            _ => 2,
        };
        let _ = writeln!(mtl, "illum {illum}\nKr {}", format_vec3(m.reflectance));
        let maps = [("map_Kd", m.diffuse_texture), ("map_d", m.alpha_texture)];
        for (keyword, texture) in maps {
            if let Some(t) = texture {
                let _ = writeln!(mtl, "{keyword} {name}_texture{t}.png");
            }
        }
    }
    for (i, texture) in scene.textures.iter().enumerate() {
        let path = dir.join(format!("{name}_texture{i}.png"));
        image::save_buffer(
            &path,
            texture.rgba8(),
            texture.width(),
            texture.height(),
            image::ExtendedColorType::Rgba8,
        )
        .map_err(|e| invalid(&path, e.to_string()))?;
    }

    let write = |path: &Path, text: &str| {
        fs::write(path, text).map_err(|error| ObjError::Io {
            path: path.to_owned(),
            error,
        })
    };
    write(&mtl_path, &mtl)?;
    write(&obj_path, &obj)
}

/// A grey level for a colour: the colour's own when it is grey, so that it
/// survives a round trip exactly, otherwise the mean.
fn grey(c: Vec3) -> f32 {
    if c == Vec3::splat(c.x) {
        c.x
    } else {
        c.element_sum() / 3.0
    }
}

/// Formats a vector as three space-separated floats that parse back exactly.
fn format_vec3(v: Vec3) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

/// Checks that `scene` can be written as OBJ and read back as the same scene.
fn check_writable(scene: &Scene) -> Result<(), WriteError> {
    scene.validate()?;
    if let Some(i) = scene
        .positions
        .iter()
        .chain(&scene.normals)
        .position(|v| !v.is_finite())
    {
        return Err(WriteError::NotFinite(i % scene.positions.len().max(1)));
    }
    for m in &scene.materials {
        let vectors = [
            m.ambient,
            m.diffuse,
            m.specular,
            m.emission,
            m.reflectance,
            m.transmittance,
        ];
        if !(vectors.iter().all(|v| v.is_finite()) && m.shininess.is_finite() && m.ior.is_finite())
        {
            return Err(WriteError::MaterialNotFinite(m.name.clone()));
        }
    }
    check_names("material", scene.materials.iter().map(|m| m.name.as_str()))?;
    check_names("object", scene.objects.iter().map(|o| o.name.as_str()))
}

/// Names must survive an OBJ line: non-empty, no surrounding whitespace, no
/// line breaks, and unique (the reader finds objects and materials by name).
fn check_names<'a>(
    what: &'static str,
    names: impl Iterator<Item = &'a str>,
) -> Result<(), WriteError> {
    let mut seen = HashSet::new();
    for name in names {
        if name.is_empty() || name.trim() != name || name.contains(['\n', '\r']) {
            let name = name.to_owned();
            return Err(WriteError::Name { what, name });
        }
        if !seen.insert(name) {
            let name = name.to_owned();
            return Err(WriteError::Duplicate { what, name });
        }
    }
    Ok(())
}

fn invalid(path: &Path, message: impl Into<String>) -> ObjError {
    ObjError::Invalid {
        path: path.to_owned(),
        message: message.into(),
    }
}

fn syntax(path: &Path, line: usize, error: LineError) -> ObjError {
    ObjError::Syntax {
        path: path.to_owned(),
        line,
        error,
    }
}

/// Decodes a text file read from `path`; invalid UTF-8 is reported at its
/// line. A leading byte-order mark is dropped (tobj would take it as part of
/// the first word).
fn decode_text(path: &Path, bytes: Vec<u8>) -> Result<String, ObjError> {
    let text = String::from_utf8(bytes).map_err(|e| {
        let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let line = valid.iter().filter(|&&b| b == b'\n').count() + 1;
        syntax(path, line, LineError::NotUtf8)
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_owned(),
        None => text,
    })
}

/// Splits a trimmed line into its keyword and the trimmed rest.
fn keyword(line: &str) -> (&str, &str) {
    match line.split_once(char::is_whitespace) {
        Some((keyword, rest)) => (keyword, rest.trim()),
        None => (line, ""),
    }
}

/// Whether the rest of a line with this keyword is a name or file name, in
/// which `#` is an ordinary character (`newmtl Material #25`).
fn takes_name(keyword: &str) -> bool {
    matches!(keyword, "o" | "g" | "usemtl" | "newmtl" | "mtllib") || is_texture(keyword)
}

/// The rest of a line without its inline comment: a `#` at the start of a
/// word and everything after it.
fn strip_comment(rest: &str) -> &str {
    let mut previous = ' ';
    for (i, c) in rest.char_indices() {
        if c == '#' && previous.is_whitespace() {
            return rest[..i].trim_end();
        }
        previous = c;
    }
    rest
}

/// Splits a line into its keyword and its rest without inline comment, and
/// gives the line as tobj should see it (trimmed, comment dropped).
fn split_line(line: &str) -> (&str, &str, Cow<'_, str>) {
    let line = line.trim();
    let (keyword, rest) = keyword(line);
    if takes_name(keyword) {
        return (keyword, rest, Cow::Borrowed(line));
    }
    let stripped = strip_comment(rest);
    let clean = if stripped.len() == rest.len() {
        Cow::Borrowed(line)
    } else {
        Cow::Owned(format!("{keyword} {stripped}"))
    };
    (keyword, stripped, clean)
}

/// A file name as written in an OBJ or MTL file, with Windows separators
/// turned into `/`.
fn file_name(text: &str) -> Cow<'_, str> {
    if text.contains('\\') {
        Cow::Owned(text.replace('\\', "/"))
    } else {
        Cow::Borrowed(text)
    }
}

/// `text` quoted for a message, cut after [`QUOTE_CHARS`] characters so that
/// a huge token cannot make a huge message.
fn quote(text: &str) -> String {
    match text.char_indices().nth(QUOTE_CHARS) {
        None => format!("{text:?}"),
        Some((cut, _)) => format!("{:?}… ({} bytes)", &text[..cut], text.len()),
    }
}

/// Parses whitespace-separated finite numbers, as many as `count` allows.
fn parse_numbers(text: &str, count: RangeInclusive<usize>) -> Result<Vec<f32>, ValueError> {
    let values = text
        .split_whitespace()
        .map(|word| match word.parse::<f32>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(ValueError::NotFinite(quote(word))),
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (found, start, end) = (values.len(), *count.start(), *count.end());
    if count.contains(&found) {
        Ok(values)
    } else if end == 1 {
        Err(ValueError::OneNumber(found))
    } else if start == end {
        Err(ValueError::Numbers {
            expected: start,
            found,
        })
    } else {
        Err(ValueError::NumberRange { start, end, found })
    }
}

/// Parses one finite number.
fn parse_number(text: &str) -> Result<f32, ValueError> {
    parse_numbers(text, 1..=1).map(|v| v[0])
}

/// Parses exactly three finite numbers.
fn parse_vec3(text: &str) -> Result<Vec3, ValueError> {
    parse_numbers(text, 3..=3).map(|v| Vec3::from_slice(&v))
}

/// Parses a transmission filter: `r g b`, or one number for grey.
fn parse_filter(text: &str) -> Result<Vec3, ValueError> {
    match parse_numbers(text, 1..=3)?[..] {
        [grey] => Ok(Vec3::splat(grey)),
        [r, g, b] => Ok(Vec3::new(r, g, b)),
        _ => Err(ValueError::Filter),
    }
}

/// One library as tobj parsed it (always `Ok`: it was checked first).
type Library = tobj::MTLLoadResult;

/// An OBJ file that passed [`check_obj`].
struct CheckedObj {
    /// The normalised text to hand to tobj.
    text: String,
    /// The libraries by the name on their `mtllib` line.
    libraries: HashMap<String, Library>,
    warnings: Vec<ObjWarning>,
    textures: Vec<TextureRef>,
}

/// A texture vtfarm uses (`map_Kd`, `map_d`), where the MTL names it.
struct TextureRef {
    material: String,
    alpha: bool,
    file: PathBuf,
    mtl: PathBuf,
    line: usize,
}

/// State of the line check: what has been defined so far.
#[derive(Default)]
struct ObjCheck {
    positions: usize,
    texcoords: usize,
    normals: usize,
    /// Whether `v` lines carry colours; tobj needs all or none to.
    coloured: Option<bool>,
    /// Whether an `o` or `g` line has been seen; until then objects are
    /// named after their material.
    grouped: bool,
    /// Whether the faces so far have an object name (from `o`/`g`, or from
    /// a `usemtl` before any `o`/`g`).
    named: bool,
    materials: HashSet<String>,
    libraries: HashMap<String, Library>,
    warnings: Vec<ObjWarning>,
    textures: Vec<TextureRef>,
}

/// Checks an OBJ file line by line, reading and checking the MTL libraries it
/// names, and prepares the text for tobj.
fn check_obj(path: &Path, text: &str) -> Result<CheckedObj, ObjError> {
    let mut check = ObjCheck::default();
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        let (keyword, rest, line) = split_line(line);
        let clean = match keyword {
            "mtllib" => check.library(path, i + 1, rest)?,
            _ => check
                .line(keyword, rest, line)
                .map_err(|m| syntax(path, i + 1, m))?,
        };
        out.push_str(&clean);
        out.push('\n');
    }
    Ok(CheckedObj {
        text: out,
        libraries: check.libraries,
        warnings: check.warnings,
        textures: check.textures,
    })
}

impl ObjCheck {
    /// Checks one line other than `mtllib`; returns what tobj should see.
    fn line<'a>(
        &mut self,
        keyword: &str,
        rest: &str,
        line: Cow<'a, str>,
    ) -> Result<Cow<'a, str>, LineError> {
        let value = |keyword: &str| {
            let keyword = keyword.to_owned();
            move |error| LineError::Value { keyword, error }
        };
        match keyword {
            "v" => self.vertex(rest)?,
            "vt" => {
                parse_numbers(rest, 2..=3).map_err(value("vt"))?;
                self.texcoords += 1;
            }
            "vn" => {
                parse_numbers(rest, 3..=3).map_err(value("vn"))?;
                self.normals += 1;
            }
            "f" => {
                self.face(rest)?;
                if !self.named {
                    // Faces before any `o`, `g` or `usemtl`: their material
                    // is "default", and so is their object's name.
                    self.named = true;
                    return Ok(Cow::Owned(format!(
                        "o {}\n{line}",
                        Material::default().name
                    )));
                }
            }
            // tobj would turn a 3-vertex polyline into a triangle.
            "l" => return Ok(Cow::Borrowed("")),
            "usemtl" if rest.is_empty() => return Err(LineError::UsemtlWithoutName),
            "usemtl" if !self.materials.contains(rest) => {
                return Err(LineError::UnknownMaterial(quote(rest)));
            }
            "usemtl" if !self.grouped => {
                // No `o`/`g` yet: the object takes the material's name.
                self.named = true;
                return Ok(Cow::Owned(format!("o {rest}\nusemtl {rest}")));
            }
            // tobj splits these at the first space only.
            "usemtl" | "o" | "g" => {
                if keyword != "usemtl" {
                    self.grouped = true;
                    self.named = true;
                }
                return Ok(Cow::Owned(format!("{keyword} {rest}")));
            }
            _ => {}
        }
        Ok(line)
    }

    fn vertex(&mut self, rest: &str) -> Result<(), LineError> {
        let values = parse_numbers(rest, 3..=6).map_err(|error| LineError::Value {
            keyword: "v".to_owned(),
            error,
        })?;
        let (position, coloured) = match values[..] {
            [x, y, z] => (Vec3::new(x, y, z), false),
            [x, y, z, w] => (Vec3::new(x, y, z) / w, false),
            [x, y, z, _, _, _] => (Vec3::new(x, y, z), true),
            _ => return Err(LineError::VertexForm),
        };
        if !position.is_finite() {
            return Err(LineError::ZeroW(values[3]));
        }
        if position.abs().max_element() > MAX_COORDINATE {
            return Err(LineError::Coordinate(position.abs().max_element()));
        }
        if *self.coloured.get_or_insert(coloured) != coloured {
            return Err(LineError::MixedColours);
        }
        self.positions += 1;
        Ok(())
    }

    fn face(&self, rest: &str) -> Result<(), LineError> {
        let mut count = 0;
        for vertex in rest.split_whitespace() {
            let mut parts = vertex.split('/');
            let kinds = [
                ("vertex", self.positions),
                ("texture", self.texcoords),
                ("normal", self.normals),
            ];
            for (k, (kind, defined)) in kinds.into_iter().enumerate() {
                match parts.next() {
                    // Only the vertex index is required (`v//vn`, `v/vt`).
                    Some("") | None if k > 0 => {}
                    part => {
                        face_index(part.unwrap_or_default(), kind, defined).map_err(|error| {
                            LineError::FaceIndex {
                                vertex: quote(vertex),
                                error,
                            }
                        })?
                    }
                }
            }
            if parts.next().is_some() {
                return Err(LineError::FaceVertexParts(quote(vertex)));
            }
            count += 1;
            if count > MAX_FACE_VERTICES {
                return Err(LineError::FaceTooLarge);
            }
        }
        if count < 3 {
            return Err(LineError::FaceTooSmall(count));
        }
        Ok(())
    }

    /// Reads and checks the library on an `mtllib` line.
    fn library(
        &mut self,
        obj: &Path,
        line: usize,
        name: &str,
    ) -> Result<Cow<'static, str>, ObjError> {
        if name.is_empty() {
            return Err(syntax(obj, line, LineError::MtllibWithoutName));
        }
        let name = file_name(name);
        if self.libraries.contains_key(name.as_ref()) {
            // A second mtllib of the same file would duplicate its materials.
            return Ok(Cow::Borrowed(""));
        }
        let file = obj.parent().unwrap_or(Path::new("")).join(name.as_ref());
        let bytes = file::read_regular(&file, file::MAX_SCENE_FILE_BYTES).map_err(|error| {
            ObjError::Reference {
                path: obj.to_owned(),
                line,
                what: "material library",
                file: file.clone(),
                error,
            }
        })?;
        let text = decode_text(&file, bytes)?;
        let clean = check_mtl(&file, &text, &mut self.warnings, &mut self.textures)?;
        let (materials, names) = tobj::load_mtl_buf(&mut clean.as_bytes())
            .map_err(|e| invalid(&file, format!("tobj: {e}")))?;
        self.materials
            .extend(materials.iter().map(|m| m.name.clone()));
        self.libraries
            .insert(name.clone().into_owned(), Ok((materials, names)));
        Ok(Cow::Owned(format!("mtllib {name}")))
    }
}

/// Checks one 1-based (or negative, relative) OBJ index against the number of
/// elements defined so far.
fn face_index(text: &str, kind: &'static str, defined: usize) -> Result<(), IndexError> {
    let index: isize = text.parse().map_err(|_| IndexError::NotInteger {
        kind,
        text: quote(text),
    })?;
    if index == 0 {
        return Err(IndexError::Zero { kind });
    }
    if index.unsigned_abs() > defined {
        return Err(IndexError::OutOfRange {
            kind,
            index,
            defined,
        });
    }
    Ok(())
}

/// MTL keywords naming a texture file.
fn is_texture(keyword: &str) -> bool {
    keyword.starts_with("map_") || matches!(keyword, "bump" | "disp" | "decal" | "refl" | "norm")
}

/// Checks an MTL file line by line: numbers where tobj expects them (it panics
/// on `Kd` with fewer than three) and names; a texture that does not exist is
/// a warning. Returns the normalised text to hand to tobj.
fn check_mtl(
    path: &Path,
    text: &str,
    warnings: &mut Vec<ObjWarning>,
    textures: &mut Vec<TextureRef>,
) -> Result<String, ObjError> {
    let mut out = String::with_capacity(text.len());
    let mut material = String::new();
    for (i, line) in text.lines().enumerate() {
        let (keyword, rest, clean) = split_line(line);
        if keyword == "newmtl" {
            material = rest.to_owned();
        }
        let value = |error| LineError::Value {
            keyword: keyword.to_owned(),
            error,
        };
        let checked = match keyword {
            "newmtl" if rest.is_empty() => Err(LineError::NoMaterialName),
            "Ka" | "Kd" | "Ks" | "Ke" | "Kr" => parse_vec3(rest).map(drop).map_err(value),
            "Tf" => parse_filter(rest).map(drop).map_err(value),
            "Ns" | "Ni" | "d" | "Tr" => parse_number(rest).map(drop).map_err(value),
            "illum" => rest
                .parse::<u8>()
                .map(drop)
                .map_err(|_| LineError::Illum(quote(rest))),
            _ if is_texture(keyword) && rest.is_empty() => {
                Err(LineError::NoTextureName(keyword.to_owned()))
            }
            _ if is_texture(keyword) => {
                let name = file_name(rest);
                match keyword {
                    "map_Kd" | "map_d" => textures.push(TextureRef {
                        material: material.clone(),
                        alpha: keyword == "map_d",
                        file: texture_file(path, &name),
                        mtl: path.to_owned(),
                        line: i + 1,
                    }),
                    _ => warnings.extend(check_texture(path, i + 1, &name)),
                }
                out.push_str(&format!("{keyword} {name}\n"));
                continue;
            }
            _ => Ok(()),
        };
        checked.map_err(|e| syntax(path, i + 1, e))?;
        // tobj takes everything after `newmtl` as the name, untrimmed.
        match keyword {
            "newmtl" => out.push_str(&format!("newmtl {rest}")),
            _ => out.push_str(&clean),
        }
        out.push('\n');
    }
    Ok(out)
}

/// The file a texture line of `mtl` names: the whole argument, or its last
/// word when options (`-s 1 1 1`) come first; relative to the MTL file.
fn texture_file(mtl: &Path, rest: &str) -> PathBuf {
    let name = if rest.starts_with('-') {
        rest.split_whitespace().last().unwrap_or(rest)
    } else {
        rest
    };
    mtl.parent().unwrap_or(Path::new("")).join(name)
}

/// A warning when a texture vtfarm does not use (bump, reflection, …)
/// names a file that does not exist.
fn check_texture(mtl: &Path, line: usize, rest: &str) -> Option<ObjWarning> {
    let file = texture_file(mtl, rest);
    let problem = match fs::metadata(&file) {
        Ok(m) if m.is_file() => return None,
        Ok(_) => "not a file".to_owned(),
        Err(e) => e.to_string(),
    };
    Some(ObjWarning {
        path: mtl.to_owned(),
        line,
        message: format!(
            "texture {} ignored ({problem}); vtfarm uses map_Kd and map_d only",
            file.display()
        ),
    })
}

/// Loads the textures the materials use into `scene` (each file once) and
/// sets the materials' texture ids. A texture that cannot be read is a
/// warning at its MTL line; the material keeps its flat colour.
fn load_textures(scene: &mut Scene, textures: &[TextureRef], warnings: &mut Vec<ObjWarning>) {
    let mut loaded: HashMap<&Path, Option<TextureId>> = HashMap::new();
    for t in textures {
        let id = *loaded
            .entry(&t.file)
            .or_insert_with(|| match Texture::load(&t.file) {
                Ok(texture) => {
                    scene.textures.push(texture);
                    Some(scene.textures.len() as TextureId - 1)
                }
                Err(e) => {
                    warnings.push(ObjWarning {
                        path: t.mtl.clone(),
                        line: t.line,
                        message: format!(
                            "texture not used, the material keeps its flat colour: {e}"
                        ),
                    });
                    None
                }
            });
        let Some(id) = id else { continue };
        // Materials that share a name share the texture (tobj keeps the last).
        for m in scene.materials.iter_mut().filter(|m| m.name == t.material) {
            if t.alpha {
                m.alpha_texture = Some(id);
            } else {
                m.diffuse_texture = Some(id);
            }
        }
    }
}

/// Converts tobj's models and materials into a scene.
fn build_scene(
    path: &Path,
    models: &[tobj::Model],
    materials: &[tobj::Material],
    options: &ObjOptions,
    textures: impl FnOnce(&mut Scene),
) -> Result<Scene, ObjError> {
    let mut scene = Scene {
        materials: materials
            .iter()
            .map(convert_material)
            .collect::<Result<_, _>>()
            .map_err(|e| invalid(path, e.to_string()))?,
        ..Scene::default()
    };
    textures(&mut scene);
    // Corner texture coordinates, kept only when a material is textured.
    let textured = options.keep_uvs || scene.materials.iter().any(Material::is_textured);
    // Triangles of models without normals; they get theirs at the end, per
    // object, so that smoothing crosses material boundaries.
    let mut to_smooth = Vec::new();
    for model in models {
        let mesh = &model.mesh;
        let positions: Vec<Vec3> = mesh
            .positions
            .chunks_exact(3)
            .map(Vec3::from_slice)
            .collect();
        let triangles: Vec<[u32; 3]> = mesh
            .indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        if triangles.is_empty() {
            continue;
        }
        if mesh.indices.iter().any(|&v| v as usize >= positions.len()) {
            return Err(invalid(
                path,
                format!(
                    "tobj: model {} indexes a missing vertex",
                    quote(&model.name)
                ),
            ));
        }
        let object = object_id(&mut scene, &model.name);
        let material = match mesh.material_id {
            Some(m) if m < scene.materials.len() => MaterialId(m as u32),
            _ => default_material(&mut scene),
        };
        let has_normals = mesh.normals.len() == mesh.positions.len();
        let normals = if has_normals {
            let mut normals: Vec<Vec3> =
                mesh.normals.chunks_exact(3).map(Vec3::from_slice).collect();
            normals::repair_normals(&positions, &triangles, &mut normals);
            normals
        } else {
            // Placeholders: the smoothed triangles get new vertices.
            vec![Vec3::Y; positions.len()]
        };
        if textured {
            let uvs: Vec<Vec2> = if mesh.texcoords.len() == positions.len() * 2 {
                mesh.texcoords
                    .chunks_exact(2)
                    .map(Vec2::from_slice)
                    .collect()
            } else {
                vec![Vec2::ZERO; positions.len()]
            };
            scene
                .corner_uvs
                .resize(scene.triangles.len(), [Vec2::ZERO; 3]);
            (scene.corner_uvs).extend(triangles.iter().map(|t| t.map(|v| uvs[v as usize])));
        }
        let base = scene.positions.len() as u32;
        scene.positions.extend(positions);
        scene.normals.extend(normals);
        for t in triangles {
            to_smooth.push(!has_normals);
            scene.triangles.push(Triangle {
                vertices: t.map(|v| v + base),
                object,
                material,
            });
        }
    }
    if scene.triangles.is_empty() {
        return Err(invalid(path, "no triangles"));
    }
    normals::smooth_selected(&mut scene, &to_smooth, options.crease_angle_deg);
    normals::compact_vertices(&mut scene);
    scene
        .validate()
        .map_err(|m| invalid(path, format!("invalid scene: {m}")))?;
    Ok(scene)
}

/// The id of the object named `name`, added if new.
pub(crate) fn object_id(scene: &mut Scene, name: &str) -> ObjectId {
    scene.object_id(name).unwrap_or_else(|| {
        scene.objects.push(Object {
            name: name.to_owned(),
        });
        ObjectId(scene.objects.len() as u32 - 1)
    })
}

/// The material for faces (or glTF primitives) without one: the MTL's
/// "default" if it has one, otherwise [`Material::default`], added on
/// first use.
pub(crate) fn default_material(scene: &mut Scene) -> MaterialId {
    let default = Material::default();
    scene.material_id(&default.name).unwrap_or_else(|| {
        scene.materials.push(default);
        MaterialId(scene.materials.len() as u32 - 1)
    })
}

/// Maps one tobj material; see the module documentation for the table.
fn convert_material(m: &tobj::Material) -> Result<Material, MaterialError> {
    // Keys tobj does not know end up as text in `unknown_param`; the MTL check
    // has already parsed them once, so errors here are not expected.
    fn extension<T>(
        m: &tobj::Material,
        key: &'static str,
        parse: fn(&str) -> Result<T, ValueError>,
    ) -> Result<Option<T>, MaterialError> {
        let parsed = m.unknown_param.get(key).map(|text| parse(text)).transpose();
        parsed.map_err(|error| MaterialError {
            material: quote(&m.name),
            key,
            error,
        })
    }
    let base = Material::default();
    let diffuse = m.diffuse.map_or(base.diffuse, Vec3::from);
    let specular = m.specular.map_or(Vec3::ZERO, Vec3::from);
    // tobj 4.0.5 parses Ke; earlier 4.x releases left it an unknown key.
    let emission = match m.emissive {
        Some(ke) => Vec3::from(ke),
        None => extension(m, "Ke", parse_vec3)?.unwrap_or(Vec3::ZERO),
    };
    // Glass models: transparency with ray-traced reflection.
    let glass = matches!(m.illumination_model, Some(4 | 6 | 7));
    let amount = match (m.dissolve, extension(m, "Tr", parse_number)?) {
        (Some(d), _) => Some(1.0 - d),
        (None, tr) => tr,
    };
    let transmittance = match (amount, extension(m, "Tf", parse_filter)?) {
        (Some(amount), Some(filter)) => filter * amount,
        (Some(amount), None) => Vec3::splat(amount),
        (None, Some(filter)) if glass => filter,
        (None, _) => Vec3::ZERO,
    }
    .clamp(Vec3::ZERO, Vec3::ONE);
    let terms = mtl_reflectance(&MtlOptics {
        kr: extension(m, "Kr", parse_vec3)?,
        illum: m.illumination_model,
        ks: m.specular.map(Vec3::from),
        ni: m.optical_density,
        transmittance,
    });
    Ok(Material {
        name: m.name.clone(),
        ambient: m.ambient.map_or(diffuse, Vec3::from),
        diffuse,
        specular,
        shininess: m.shininess.unwrap_or(base.shininess),
        emission,
        reflectance: terms.kr,
        transmittance: terms.kt,
        ior: m.optical_density.unwrap_or(base.ior),
        thin: false,
        fresnel: terms.fresnel,
        diffuse_texture: None,
        alpha_texture: None,
    })
}
