//! Wavefront OBJ/MTL import (through `tobj`) and export.
//!
//! # Import
//!
//! [`load_obj`] first checks the OBJ file and every MTL library it names line
//! by line, because `tobj` reports errors without line numbers and panics or
//! overflows on some malformed input (`Kd 1 2`, face index 0 with texture
//! coordinates). Only text that passed the check reaches `tobj`, as a
//! normalised copy (lines trimmed, `l` polylines dropped), so every
//! error message names the file and, for a bad line, its number.
//!
//! Each OBJ object or group (`o`/`g`) becomes an [`Object`]; groups that share
//! a name share the object. Points and lines are ignored; polygons are
//! triangulated as fans. Faces before any `usemtl` get the material named
//! "default" (the MTL's, or [`Material::default`]). A model whose faces all
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
//! | `illum 3`, `5`, `7`| `reflectance = Ks` (ray-traced mirror)                 |
//! | `Kr r g b`         | `reflectance`, overriding `illum` (vtfarm extension)   |
//! | `d a`              | `transmittance = 1 - a` (clamped to 0..=1)             |
//! | `Tr t`             | `transmittance = t` when there is no `d`               |
//! | `Ni n`             | `ior` (default: 1)                                     |
//! | `map_*`, `bump`, … | only checked to exist; textures are not used           |
//!
//! # Export
//!
//! [`write_obj`] writes `name.obj` and `name.mtl` so that [`load_obj`] gives
//! the same scene back: floats are printed with Rust's shortest round-trip
//! formatting, and a scene that came from [`load_obj`] reloads bit for bit.
//! MTL's `d` is a single number, so a transmittance that is not grey is
//! written (and read back) as its mean.

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;
use std::fs;
use std::io;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::normals::{self, DEFAULT_CREASE_ANGLE_DEG};
use crate::{Material, MaterialId, Object, ObjectId, Scene, Triangle};

/// Options for [`load_obj`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjOptions {
    /// Crease angle in degrees for normals computed for models that have no
    /// `vn` normals; see [`normals::compute_normals`].
    pub crease_angle_deg: f32,
}

impl Default for ObjOptions {
    fn default() -> Self {
        ObjOptions {
            crease_angle_deg: DEFAULT_CREASE_ANGLE_DEG,
        }
    }
}

/// Why an OBJ or MTL file could not be read or written. Every message starts
/// with the file concerned and, for a bad line, `:line`.
#[derive(Debug, thiserror::Error)]
pub enum ObjError {
    /// A file could not be read or written.
    #[error("{}: {source}", .path.display())]
    Io { path: PathBuf, source: io::Error },
    /// A line of an OBJ or MTL file is malformed.
    #[error("{}:{line}: {message}", .path.display())]
    Syntax {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A file named on a line (`mtllib`, `map_Kd`, …) cannot be read.
    #[error("{}:{line}: cannot read {what} {}: {source}", .path.display(), .file.display())]
    Reference {
        path: PathBuf,
        line: usize,
        what: &'static str,
        file: PathBuf,
        source: io::Error,
    },
    /// The file as a whole is unusable (no triangles, a scene that cannot be
    /// written, an error `tobj` found that the line check did not).
    #[error("{}: {message}", .path.display())]
    Invalid { path: PathBuf, message: String },
}

/// Loads an OBJ file and the MTL libraries it names into a [`Scene`].
///
/// See the [module documentation](self) for the mapping. Never panics; any
/// problem is an [`ObjError`] naming the file and, where there is one, the
/// line.
pub fn load_obj(path: &Path, options: &ObjOptions) -> Result<Scene, ObjError> {
    let bytes = fs::read(path).map_err(|source| ObjError::Io {
        path: path.to_owned(),
        source,
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
    let scene = build_scene(path, &models, &materials, options)?;
    tracing::debug!(
        path = %path.display(),
        vertices = scene.positions.len(),
        triangles = scene.triangles.len(),
        objects = scene.objects.len(),
        materials = scene.materials.len(),
        "loaded OBJ"
    );
    Ok(scene)
}

/// Writes `scene` as `dir/name.obj` and `dir/name.mtl`.
///
/// The OBJ has one `mtllib` line, all vertices as `v` and `vn` (index `i` of
/// both is scene vertex `i - 1`), then the triangles in scene order as
/// `f v//vn`, with an `o` line whenever the object changes and a `usemtl` line
/// whenever the object or material changes. Objects without triangles are not
/// written. The MTL has every material with `Ka Kd Ks Ns Ke Ni d` and
/// `illum 2`, or `illum 3` plus `Kr` for mirrors.
///
/// Fails when the scene does not [validate](Scene::validate), holds
/// non-finite numbers, or has names that OBJ cannot carry (empty, with
/// surrounding whitespace or line breaks, or the same name twice).
pub fn write_obj(scene: &Scene, dir: &Path, name: &str) -> Result<(), ObjError> {
    let obj_path = dir.join(format!("{name}.obj"));
    let mtl_path = dir.join(format!("{name}.mtl"));
    check_writable(scene).map_err(|message| invalid(&obj_path, message))?;
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
    let mut current = None;
    for t in &scene.triangles {
        let object = &scene.objects[t.object as usize].name;
        let material = &scene.materials[t.material as usize].name;
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
        let _ = writeln!(obj, "f {a}//{a} {b}//{b} {c}//{c}");
    }

    let mut mtl = String::from("# vtfarm materials\n");
    for m in &scene.materials {
        let _ = writeln!(mtl, "\nnewmtl {}", m.name);
        let _ = writeln!(mtl, "Ka {}", format_vec3(m.ambient));
        let _ = writeln!(mtl, "Kd {}", format_vec3(m.diffuse));
        let _ = writeln!(mtl, "Ks {}", format_vec3(m.specular));
        let _ = writeln!(mtl, "Ns {}", m.shininess);
        let _ = writeln!(mtl, "Ke {}", format_vec3(m.emission));
        let _ = writeln!(mtl, "Ni {}", m.ior);
        let _ = writeln!(mtl, "d {}", 1.0 - grey(m.transmittance));
        if m.reflectance.max_element() > 0.0 {
            // illum 3 tells other readers "ray-traced mirror"; Kr gives ours
            // the exact reflectance, which need not equal Ks.
            let _ = writeln!(mtl, "illum 3\nKr {}", format_vec3(m.reflectance));
        } else {
            let _ = writeln!(mtl, "illum 2");
        }
    }

    let write = |path: &Path, text: &str| {
        fs::write(path, text).map_err(|source| ObjError::Io {
            path: path.to_owned(),
            source,
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
fn check_writable(scene: &Scene) -> Result<(), String> {
    scene.validate()?;
    if let Some(i) = scene
        .positions
        .iter()
        .chain(&scene.normals)
        .position(|v| !v.is_finite())
    {
        return Err(format!(
            "vertex {} is not finite",
            i % scene.positions.len().max(1)
        ));
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
            return Err(format!("material {:?} has a non-finite value", m.name));
        }
    }
    check_names("material", scene.materials.iter().map(|m| m.name.as_str()))?;
    check_names("object", scene.objects.iter().map(|o| o.name.as_str()))
}

/// Names must survive an OBJ line: non-empty, no surrounding whitespace, no
/// line breaks, and unique (the reader finds objects and materials by name).
fn check_names<'a>(what: &str, names: impl Iterator<Item = &'a str>) -> Result<(), String> {
    let mut seen = HashSet::new();
    for name in names {
        if name.is_empty() || name.trim() != name || name.contains(['\n', '\r']) {
            return Err(format!("{what} name {name:?} cannot be written to OBJ"));
        }
        if !seen.insert(name) {
            return Err(format!("two {what}s are named {name:?}"));
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

fn syntax(path: &Path, line: usize, message: impl Into<String>) -> ObjError {
    ObjError::Syntax {
        path: path.to_owned(),
        line,
        message: message.into(),
    }
}

/// Decodes a text file read from `path`; invalid UTF-8 is reported at its
/// line. A leading byte-order mark is dropped (tobj would take it as part of
/// the first word).
fn decode_text(path: &Path, bytes: Vec<u8>) -> Result<String, ObjError> {
    let text = String::from_utf8(bytes).map_err(|e| {
        let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let line = valid.iter().filter(|&&b| b == b'\n').count() + 1;
        syntax(path, line, "not valid UTF-8")
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

/// Parses whitespace-separated finite numbers, as many as `count` allows.
fn parse_numbers(text: &str, count: RangeInclusive<usize>) -> Result<Vec<f32>, String> {
    let values = text
        .split_whitespace()
        .map(|word| match word.parse::<f32>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(format!("{word:?} is not a finite number")),
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (found, start, end) = (values.len(), *count.start(), *count.end());
    if count.contains(&found) {
        Ok(values)
    } else if end == 1 {
        Err(format!("expected a number, found {found}"))
    } else if start == end {
        Err(format!("expected {start} numbers, found {found}"))
    } else {
        Err(format!("expected {start} to {end} numbers, found {found}"))
    }
}

/// Parses one finite number.
fn parse_number(text: &str) -> Result<f32, String> {
    parse_numbers(text, 1..=1).map(|v| v[0])
}

/// Parses exactly three finite numbers.
fn parse_vec3(text: &str) -> Result<Vec3, String> {
    parse_numbers(text, 3..=3).map(|v| Vec3::from_slice(&v))
}

/// One library as tobj parsed it (always `Ok`: it was checked first).
type Library = tobj::MTLLoadResult;

/// An OBJ file that passed [`check_obj`].
struct CheckedObj {
    /// The normalised text to hand to tobj, line for line.
    text: String,
    /// The libraries by the name on their `mtllib` line.
    libraries: HashMap<String, Library>,
}

/// State of the line check: what has been defined so far.
#[derive(Default)]
struct ObjCheck {
    positions: usize,
    texcoords: usize,
    normals: usize,
    /// Whether `v` lines carry colours; tobj needs all or none to.
    coloured: Option<bool>,
    materials: HashSet<String>,
    libraries: HashMap<String, Library>,
}

/// Checks an OBJ file line by line, reading and checking the MTL libraries it
/// names, and prepares the text for tobj.
fn check_obj(path: &Path, text: &str) -> Result<CheckedObj, ObjError> {
    let mut check = ObjCheck::default();
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        let (keyword, rest) = keyword(line);
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
    })
}

impl ObjCheck {
    /// Checks one line other than `mtllib`; returns what tobj should see.
    fn line<'a>(
        &mut self,
        keyword: &str,
        rest: &str,
        line: &'a str,
    ) -> Result<Cow<'a, str>, String> {
        match keyword {
            "v" => self.vertex(rest)?,
            "vt" => {
                parse_numbers(rest, 2..=3).map_err(|e| format!("vt: {e}"))?;
                self.texcoords += 1;
            }
            "vn" => {
                parse_numbers(rest, 3..=3).map_err(|e| format!("vn: {e}"))?;
                self.normals += 1;
            }
            "f" => self.face(rest)?,
            // tobj would turn a 3-vertex polyline into a triangle.
            "l" => return Ok(Cow::Borrowed("")),
            "usemtl" if rest.is_empty() => return Err("usemtl without a material name".into()),
            "usemtl" if !self.materials.contains(rest) => {
                return Err(format!(
                    "usemtl names material {rest:?}, which no mtllib defines"
                ));
            }
            // tobj splits these at the first space only.
            "usemtl" | "o" | "g" => return Ok(Cow::Owned(format!("{keyword} {rest}"))),
            _ => {}
        }
        Ok(Cow::Borrowed(line))
    }

    fn vertex(&mut self, rest: &str) -> Result<(), String> {
        let values = parse_numbers(rest, 3..=6).map_err(|e| format!("v: {e}"))?;
        let coloured = match values[..] {
            [_, _, _] => false,
            [x, y, z, w] => {
                if !(Vec3::new(x, y, z) / w).is_finite() {
                    return Err(format!("v: cannot divide by w = {w}"));
                }
                false
            }
            [_, _, _, _, _, _] => true,
            _ => return Err("v: expected x y z, x y z w or x y z r g b".into()),
        };
        if *self.coloured.get_or_insert(coloured) != coloured {
            return Err("v: vertex colours must be given for all vertices or none".into());
        }
        self.positions += 1;
        Ok(())
    }

    fn face(&self, rest: &str) -> Result<(), String> {
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
                    part => face_index(part.unwrap_or_default(), kind, defined)
                        .map_err(|e| format!("f: {vertex:?}: {e}"))?,
                }
            }
            if parts.next().is_some() {
                return Err(format!("f: {vertex:?} has more than v/vt/vn"));
            }
            count += 1;
        }
        if count < 3 {
            return Err(format!(
                "f: a face needs at least 3 vertices, found {count}"
            ));
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
            return Err(syntax(obj, line, "mtllib without a file name"));
        }
        if self.libraries.contains_key(name) {
            // A second mtllib of the same file would duplicate its materials.
            return Ok(Cow::Borrowed(""));
        }
        let file = obj.parent().unwrap_or(Path::new("")).join(name);
        let bytes = fs::read(&file).map_err(|source| ObjError::Reference {
            path: obj.to_owned(),
            line,
            what: "material library",
            file: file.clone(),
            source,
        })?;
        let text = decode_text(&file, bytes)?;
        check_mtl(&file, &text)?;
        let (materials, names) = tobj::load_mtl_buf(&mut text.as_bytes())
            .map_err(|e| invalid(&file, format!("tobj: {e}")))?;
        self.materials
            .extend(materials.iter().map(|m| m.name.clone()));
        self.libraries
            .insert(name.to_owned(), Ok((materials, names)));
        Ok(Cow::Owned(format!("mtllib {name}")))
    }
}

/// Checks one 1-based (or negative, relative) OBJ index against the number of
/// elements defined so far.
fn face_index(text: &str, kind: &str, defined: usize) -> Result<(), String> {
    let index: isize = text
        .parse()
        .map_err(|_| format!("{kind} index {text:?} is not an integer"))?;
    if index == 0 {
        return Err(format!("{kind} index 0 (OBJ indices start at 1)"));
    }
    if index.unsigned_abs() > defined {
        return Err(format!(
            "{kind} index {index} is out of range: {defined} defined so far"
        ));
    }
    Ok(())
}

/// MTL keywords naming a texture file.
fn is_texture(keyword: &str) -> bool {
    keyword.starts_with("map_") || matches!(keyword, "bump" | "disp" | "decal" | "refl" | "norm")
}

/// Checks an MTL file line by line: numbers where tobj expects them (it panics
/// on `Kd` with fewer than three), names, and that textures exist.
fn check_mtl(path: &Path, text: &str) -> Result<(), ObjError> {
    for (i, line) in text.lines().enumerate() {
        let (keyword, rest) = keyword(line.trim());
        let checked = match keyword {
            "newmtl" if rest.is_empty() => Err("no material name".to_owned()),
            "Ka" | "Kd" | "Ks" | "Ke" | "Kr" => parse_vec3(rest).map(drop),
            "Ns" | "Ni" | "d" | "Tr" => parse_number(rest).map(drop),
            "illum" => rest
                .parse::<u8>()
                .map(drop)
                .map_err(|_| format!("{rest:?} is not a model number")),
            _ if is_texture(keyword) && rest.is_empty() => Err("no texture file name".to_owned()),
            _ if is_texture(keyword) => {
                check_texture(path, i + 1, rest)?;
                Ok(())
            }
            _ => Ok(()),
        };
        checked.map_err(|m| syntax(path, i + 1, format!("{keyword}: {m}")))?;
    }
    Ok(())
}

/// Checks that a texture named by an MTL line exists. The file name is the
/// whole argument, or its last word when options (`-s 1 1 1`) come first.
fn check_texture(mtl: &Path, line: usize, rest: &str) -> Result<(), ObjError> {
    let name = if rest.starts_with('-') {
        rest.split_whitespace().last().unwrap_or(rest)
    } else {
        rest
    };
    let file = mtl.parent().unwrap_or(Path::new("")).join(name);
    let found = fs::metadata(&file).and_then(|m| {
        if m.is_file() {
            Ok(())
        } else {
            Err(io::Error::new(io::ErrorKind::InvalidInput, "not a file"))
        }
    });
    found.map_err(|source| ObjError::Reference {
        path: mtl.to_owned(),
        line,
        what: "texture",
        file,
        source,
    })
}

/// Converts tobj's models and materials into a scene.
fn build_scene(
    path: &Path,
    models: &[tobj::Model],
    materials: &[tobj::Material],
    options: &ObjOptions,
) -> Result<Scene, ObjError> {
    let mut scene = Scene {
        materials: materials
            .iter()
            .map(convert_material)
            .collect::<Result<_, _>>()
            .map_err(|m| invalid(path, m))?,
        ..Scene::default()
    };
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
                format!("tobj: model {:?} indexes a missing vertex", model.name),
            ));
        }
        let object = object_id(&mut scene, &model.name);
        let material = match mesh.material_id {
            Some(m) if m < scene.materials.len() => m as MaterialId,
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
fn object_id(scene: &mut Scene, name: &str) -> ObjectId {
    scene.object_id(name).unwrap_or_else(|| {
        scene.objects.push(Object {
            name: name.to_owned(),
        });
        scene.objects.len() as ObjectId - 1
    })
}

/// The material for faces without one: the MTL's "default" if it has one,
/// otherwise [`Material::default`], added on first use.
fn default_material(scene: &mut Scene) -> MaterialId {
    let default = Material::default();
    scene.material_id(&default.name).unwrap_or_else(|| {
        scene.materials.push(default);
        scene.materials.len() as MaterialId - 1
    })
}

/// Maps one tobj material; see the module documentation for the table.
fn convert_material(m: &tobj::Material) -> Result<Material, String> {
    // Keys tobj does not know end up as text in `unknown_param`; the MTL check
    // has already parsed them once, so errors here are not expected.
    fn extension<T>(
        m: &tobj::Material,
        key: &str,
        parse: fn(&str) -> Result<T, String>,
    ) -> Result<Option<T>, String> {
        let parsed = m.unknown_param.get(key).map(|text| parse(text)).transpose();
        parsed.map_err(|e| format!("material {:?}: {key}: {e}", m.name))
    }
    let base = Material::default();
    let diffuse = m.diffuse.map_or(base.diffuse, Vec3::from);
    let specular = m.specular.map_or(Vec3::ZERO, Vec3::from);
    // tobj 4.0.5 parses Ke; earlier 4.x releases left it an unknown key.
    let emission = match m.emissive {
        Some(ke) => Vec3::from(ke),
        None => extension(m, "Ke", parse_vec3)?.unwrap_or(Vec3::ZERO),
    };
    let reflectance = match (extension(m, "Kr", parse_vec3)?, m.illumination_model) {
        (Some(kr), _) => kr,
        (None, Some(3 | 5 | 7)) => specular,
        (None, _) => Vec3::ZERO,
    };
    let transmittance = match (m.dissolve, extension(m, "Tr", parse_number)?) {
        (Some(d), _) => 1.0 - d,
        (None, Some(tr)) => tr,
        (None, None) => 0.0,
    };
    Ok(Material {
        name: m.name.clone(),
        ambient: m.ambient.map_or(diffuse, Vec3::from),
        diffuse,
        specular,
        shininess: m.shininess.unwrap_or(base.shininess),
        emission,
        reflectance,
        transmittance: Vec3::splat(transmittance.clamp(0.0, 1.0)),
        ior: m.optical_density.unwrap_or(base.ior),
    })
}
