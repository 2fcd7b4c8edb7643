//! glTF 2.0 import (`.gltf` and `.glb`, through the `gltf` crate) and GLB
//! export.
//!
//! # Import
//!
//! The default scene's nodes (or every root node when the file names no
//! scene) are walked with their transforms, so a mesh used by several nodes
//! is instanced once per node. Each node with a mesh becomes an [`Object`](crate::Object)
//! named after the node, or after its mesh when the node has no name (nodes
//! that share a name share the object, as OBJ groups do); the mesh's name
//! hidden by a node's stays a second name of the object
//! ([`ImportedGltf::mesh_objects`]), so a job can pick it by either.
//! Before anything is read, the node tree is walked once to count what it
//! instances: deeper than [`MAX_NODE_DEPTH`] levels, more than
//! [`MAX_NODE_VISITS`] node instances or [`MAX_IMPORTED_VERTICES`]
//! vertices is an error, so a small file that instances without end costs
//! neither time nor memory. Triangles (lists,
//! strips and fans; points and lines are skipped with a warning), indexed or
//! not, with their normals (or, without, normals computed per object with
//! the crease angle of [`ObjOptions`]) and the first set of texture
//! coordinates. The file's cameras (perspective) come back as
//! [`GltfCamera`]s, named after the camera or its node.
//!
//! # Material mapping
//!
//! | glTF                                   | [`Material`]                                  |
//! |----------------------------------------|-----------------------------------------------|
//! | `baseColorFactor` × (1 − `metallic`) × (1 − transmission) | `diffuse` and `ambient`     |
//! | `baseColorTexture`                     | `diffuse_texture` (texture coordinates 0)     |
//! | F0 = Fresnel(`ior`) × `specularFactor` × `specularColorFactor` (`KHR_materials_specular`) | |
//! | mix(F0, base colour, `metallic`)       | `specular` (the Phong highlight)              |
//! | `roughness` r                          | `shininess` = 2 / r⁴ − 2, within 1 to 10,000  |
//! | `KHR_materials_ior`                    | `ior` (1.5 without)                           |
//! | `KHR_materials_transmission` t > 0     | `thin` glass: `reflectance` = F0, `transmittance` = t × base colour × (1 − F0), rays pass straight, `ior` for the Fresnel weights |
//! | `alphaMode` `BLEND`                    | `transmittance` 1 − alpha; the base-colour texture also the `alpha_texture` |
//! | `emissiveFactor` × `KHR_materials_emissive_strength` | `emission` (render units: 1 is 10,000 cd/m²) |
//! | `extras.vtfarm`                        | vtfarm's own exact values (what [`write_glb`] writes) |
//!
//! An opaque material has no mirror reflectance of its own; named as a
//! reflector by a job, its `ior` gives it Fresnel reflectance
//! (`vtfarm_job`). Files that need Draco, meshopt or KTX2/Basis textures are
//! refused, naming the extension. A texture that cannot be read (missing
//! file, unsupported format) is a [`GltfWarning`] and the material keeps
//! its flat colour.
//!
//! # Export
//!
//! [`write_glb`] writes one node and mesh per run of triangles with one
//! object and material, positions, normals and indices in one buffer, and
//! each material in PBR terms plus `extras.vtfarm` with its exact values, so
//! [`import_gltf`] gives back the scene that [`crate::obj::load_obj`] gives
//! for the same scene's OBJ export.

use std::collections::{BTreeMap, HashMap};
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use glam::{Mat3, Mat4, Vec2, Vec3};
use serde_json::{Value, json};

use crate::file::{self, MAX_IMAGE_FILE_BYTES, MAX_SCENE_FILE_BYTES};
use crate::normals;
use crate::obj::{ObjOptions, default_material, object_id};
use crate::{
    GLASS_IOR, Material, MaterialId, ObjectId, Scene, Texture, TextureId, Triangle,
    fresnel_reflectance,
};

/// Extensions vtfarm cannot read; a file that uses one is refused.
const UNSUPPORTED_EXTENSIONS: [&str; 4] = [
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_texture_basisu",
    "KHR_mesh_quantization",
];

/// Why a glTF file could not be read or written. Every message names the file.
#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    #[error("{}: {error}", .path.display())]
    Io { path: PathBuf, error: io::Error },
    /// The `gltf` crate refused the file (JSON, structure, buffers).
    #[error("{}: {error}", .path.display())]
    Parse { path: PathBuf, error: gltf::Error },
    #[error(
        "{}: needs the glTF extension {extension}, which vtfarm does not read (export without it)",
        .path.display()
    )]
    UnsupportedExtension { path: PathBuf, extension: String },
    /// The file as a whole is unusable (no triangles, an invalid scene).
    #[error("{}: {message}", .path.display())]
    Invalid { path: PathBuf, message: String },
}

/// Something in a glTF file that vtfarm skips but a user may want to know.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct GltfWarning {
    pub path: PathBuf,
    pub message: String,
}

/// A perspective camera of the file, placed by its node.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfCamera {
    /// The camera's name, or its node's.
    pub name: String,
    pub eye: Vec3,
    /// One metre in front of the eye.
    pub target: Vec3,
    pub up: Vec3,
    pub fov_y_deg: f32,
}

/// A loaded glTF scene, its cameras and the warnings found on the way.
#[derive(Clone, Debug)]
pub struct ImportedGltf {
    pub scene: Scene,
    pub cameras: Vec<GltfCamera>,
    pub warnings: Vec<GltfWarning>,
    /// Each mesh name that differs from the name of an object instancing
    /// it (a named node hides its mesh's name), with those objects in
    /// order: the objects' second names.
    pub mesh_objects: BTreeMap<String, Vec<ObjectId>>,
}

/// Loads a `.gltf` or `.glb` file; see the [module documentation](self).
pub fn import_gltf(path: &Path, options: &ObjOptions) -> Result<ImportedGltf, GltfError> {
    let bytes = file::read_regular(path, MAX_SCENE_FILE_BYTES).map_err(|error| GltfError::Io {
        path: path.to_owned(),
        error,
    })?;
    let parse = |error| GltfError::Parse {
        path: path.to_owned(),
        error,
    };
    // Name an unsupported extension before validation reports it less clearly.
    let unchecked = gltf::Gltf::from_slice_without_validation(&bytes).map_err(parse)?;
    let used = unchecked
        .extensions_used()
        .chain(unchecked.extensions_required());
    if let Some(extension) = used
        .into_iter()
        .find(|e| UNSUPPORTED_EXTENSIONS.contains(e))
    {
        return Err(GltfError::UnsupportedExtension {
            path: path.to_owned(),
            extension: extension.to_owned(),
        });
    }
    let gltf = gltf::Gltf::from_slice(&bytes).map_err(parse)?;
    let base = path.parent().unwrap_or(Path::new(""));
    let buffers = load_buffers(path, base, &gltf)?;
    let mut import = Import {
        path,
        base,
        buffers: &buffers,
        scene: Scene::default(),
        textures: HashMap::new(),
        warnings: Vec::new(),
        cameras: Vec::new(),
        to_smooth: Vec::new(),
        mesh_objects: BTreeMap::new(),
    };
    import.scene.materials = (gltf.document.materials())
        .map(|m| import.material(&m))
        .collect();
    let roots: Vec<gltf::Node> = match gltf
        .document
        .default_scene()
        .or_else(|| gltf.document.scenes().next())
    {
        Some(scene) => scene.nodes().collect(),
        None => {
            let children: std::collections::HashSet<usize> = (gltf.document.nodes())
                .flat_map(|n| n.children().map(|c| c.index()).collect::<Vec<_>>())
                .collect();
            (gltf.document.nodes())
                .filter(|n| !children.contains(&n.index()))
                .collect()
        }
    };
    let mut instanced = Instanced::default();
    for node in &roots {
        instanced
            .count(node, 0)
            .map_err(|bound| invalid(path, bound))?;
    }
    for node in roots {
        import
            .node(&node, Mat4::IDENTITY)
            .map_err(|message| invalid(path, message))?;
    }
    let Import {
        mut scene,
        warnings,
        cameras,
        to_smooth,
        mesh_objects,
        ..
    } = import;
    if scene.triangles.is_empty() {
        return Err(invalid(path, "no triangles"));
    }
    let textured = options.keep_uvs || scene.materials.iter().any(Material::is_textured);
    if !textured {
        scene.corner_uvs.clear();
    }
    normals::smooth_selected(&mut scene, &to_smooth, options.crease_angle_deg);
    normals::compact_vertices(&mut scene);
    scene
        .validate()
        .map_err(|e| invalid(path, format!("invalid scene: {e}")))?;
    Ok(ImportedGltf {
        scene,
        cameras,
        warnings,
        mesh_objects,
    })
}

/// Loads a glTF file, logging each warning with `tracing`.
pub fn load_gltf(path: &Path, options: &ObjOptions) -> Result<ImportedGltf, GltfError> {
    let imported = import_gltf(path, options)?;
    for warning in &imported.warnings {
        tracing::warn!("{warning}");
    }
    Ok(imported)
}

/// Node trees deeper than this are refused (a cycle would never end).
pub const MAX_NODE_DEPTH: usize = 256;

/// Instancing lets a small file name a huge scene (nodes that share their
/// children, at every level): the node instances and the vertices they
/// emit are bounded, so the work and memory of a load are.
pub const MAX_NODE_VISITS: usize = 1 << 20;
/// See [`MAX_NODE_VISITS`].
pub const MAX_IMPORTED_VERTICES: usize = 1 << 24;

/// What a node tree instances, counted before anything is read.
#[derive(Default)]
struct Instanced {
    visits: usize,
    vertices: usize,
}

impl Instanced {
    /// Counts `node` at `depth` and everything under it; the bound it breaks.
    fn count(&mut self, node: &gltf::Node, depth: usize) -> Result<(), String> {
        if depth >= MAX_NODE_DEPTH {
            return Err(format!(
                "nodes nested deeper than {MAX_NODE_DEPTH} levels (a node that contains itself?)"
            ));
        }
        self.visits += 1;
        if let Some(mesh) = node.mesh() {
            let vertices = mesh.primitives().map(|p| {
                p.get(&gltf::Semantic::Positions)
                    .map_or(0, |positions| positions.count())
            });
            self.vertices = vertices.fold(self.vertices, usize::saturating_add);
        }
        if self.visits > MAX_NODE_VISITS {
            return Err(format!(
                "the node tree instances more than {MAX_NODE_VISITS} nodes"
            ));
        }
        if self.vertices > MAX_IMPORTED_VERTICES {
            return Err(format!(
                "the node tree instances more than {MAX_IMPORTED_VERTICES} vertices"
            ));
        }
        node.children()
            .try_for_each(|child| self.count(&child, depth + 1))
    }
}

struct Import<'a> {
    path: &'a Path,
    base: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    scene: Scene,
    /// Image index → texture id (`None`: could not be read).
    textures: HashMap<usize, Option<TextureId>>,
    warnings: Vec<GltfWarning>,
    cameras: Vec<GltfCamera>,
    /// Per triangle, whether its normals are to be computed.
    to_smooth: Vec<bool>,
    mesh_objects: BTreeMap<String, Vec<ObjectId>>,
}

impl Import<'_> {
    fn warn(&mut self, message: String) {
        self.warnings.push(GltfWarning {
            path: self.path.to_owned(),
            message,
        });
    }

    /// Imports `node` and its children (within the bounds
    /// [`Instanced::count`] checked); an inconsistent primitive is an
    /// error naming it and its accessor.
    fn node(&mut self, node: &gltf::Node, parent: Mat4) -> Result<(), String> {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(camera) = node.camera() {
            self.camera(node, &camera, world);
        }
        if let Some(mesh) = node.mesh() {
            let name = (node.name().or(mesh.name()))
                .map_or_else(|| format!("node {}", node.index()), str::to_owned);
            let object = object_id(&mut self.scene, &name);
            if let Some(mesh_name) = mesh.name().filter(|&m| m != name) {
                let objects = self.mesh_objects.entry(mesh_name.to_owned()).or_default();
                if !objects.contains(&object) {
                    objects.push(object);
                }
            }
            for primitive in mesh.primitives() {
                let label = format!("mesh {} primitive {}", mesh.index(), primitive.index());
                self.primitive(&primitive, &label, world, object)
                    .map_err(|e| format!("{label}: {e}"))?;
            }
        }
        for child in node.children() {
            self.node(&child, world)?;
        }
        Ok(())
    }

    fn camera(&mut self, node: &gltf::Node, camera: &gltf::Camera, world: Mat4) {
        let name = (camera.name().or(node.name()))
            .map_or_else(|| format!("camera {}", camera.index()), str::to_owned);
        let gltf::camera::Projection::Perspective(perspective) = camera.projection() else {
            self.warn(format!(
                "camera {name:?} is orthographic; vtfarm renders perspective only"
            ));
            return;
        };
        // A glTF camera looks along its local −Z with +Y up.
        let eye = world.transform_point3(Vec3::ZERO);
        let forward = world.transform_vector3(-Vec3::Z).normalize_or(-Vec3::Z);
        self.cameras.push(GltfCamera {
            name,
            eye,
            target: eye + forward,
            up: world.transform_vector3(Vec3::Y).normalize_or(Vec3::Y),
            fov_y_deg: perspective.yfov().to_degrees(),
        });
    }

    fn primitive(
        &mut self,
        primitive: &gltf::Primitive,
        label: &str,
        world: Mat4,
        object: ObjectId,
    ) -> Result<(), String> {
        use gltf::mesh::Mode;
        let Some(position_accessor) = primitive.get(&gltf::Semantic::Positions) else {
            return Ok(());
        };
        let count = position_accessor.count();
        for (semantic, accessor) in primitive.attributes() {
            self.check_accessor(&accessor)?;
            if accessor.count() != count {
                return Err(format!(
                    "accessor {} ({semantic:?}) has {} elements, the POSITION accessor {} has {count}",
                    accessor.index(),
                    accessor.count(),
                    position_accessor.index()
                ));
            }
        }
        if let Some(indices) = primitive.indices() {
            self.check_accessor(&indices)?;
            if primitive.mode() == Mode::Triangles && indices.count() % 3 != 0 {
                return Err(format!(
                    "accessor {} (indices) has {} elements, not a whole number of triangles",
                    indices.index(),
                    indices.count()
                ));
            }
        }
        let reader = primitive.reader(|b| self.buffers.get(b.index()).map(|d| &d.0[..]));
        let unreadable =
            |accessor: &gltf::Accessor| format!("accessor {} cannot be read", accessor.index());
        let positions: Vec<Vec3> = (reader.read_positions())
            .ok_or_else(|| unreadable(&position_accessor))?
            .map(|p| world.transform_point3(Vec3::from(p)))
            .collect();
        let count = positions.len() as u32;
        let indices: Vec<u32> = match primitive.indices() {
            Some(accessor) => (reader.read_indices())
                .ok_or_else(|| unreadable(&accessor))?
                .into_u32()
                .collect(),
            None => (0..count).collect(),
        };
        let mut triangles: Vec<[u32; 3]> = match primitive.mode() {
            Mode::Triangles => indices
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect(),
            Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
                .map(|i| {
                    let t = [indices[i], indices[i + 1], indices[i + 2]];
                    if i % 2 == 0 { t } else { [t[1], t[0], t[2]] }
                })
                .collect(),
            Mode::TriangleFan => (1..indices.len().saturating_sub(1))
                .map(|i| [indices[0], indices[i], indices[i + 1]])
                .collect(),
            mode => {
                self.warn(format!(
                    "{label}: a primitive of {mode:?} skipped: vtfarm renders triangles"
                ));
                return Ok(());
            }
        };
        if let Some(&v) = triangles.iter().flatten().find(|&&v| v >= count) {
            let accessor = primitive.indices().map_or(0, |a| a.index());
            return Err(format!(
                "accessor {accessor} (indices) names vertex {v}, the POSITION accessor {} has {count}",
                position_accessor.index()
            ));
        }
        // A mirroring transform turns the winding around.
        if world.determinant() < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let normal_matrix = Mat3::from_mat4(world).inverse().transpose();
        let normals: Option<Vec<Vec3>> = reader.read_normals().map(|normals| {
            normals
                .map(|n| (normal_matrix * Vec3::from(n)).normalize_or_zero())
                .collect()
        });
        let has_normals = normals.is_some();
        let mut normals = match normals {
            Some(n) if has_normals => n,
            _ => vec![Vec3::Y; positions.len()],
        };
        if has_normals {
            normals::repair_normals(&positions, &triangles, &mut normals);
        }
        let uvs: Vec<Vec2> = match reader.read_tex_coords(0) {
            // glTF's v points down the image; the scene's up (as OBJ's).
            Some(uvs) => uvs.into_f32().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect(),
            None => Vec::new(),
        };
        let uv = |v: u32| uvs.get(v as usize).copied().unwrap_or(Vec2::ZERO);
        let material = match primitive.material().index() {
            Some(m) if m < self.scene.materials.len() => MaterialId(m as u32),
            _ => default_material(&mut self.scene),
        };
        let base = self.scene.positions.len() as u32;
        self.scene.positions.extend(positions);
        self.scene.normals.extend(normals);
        for t in triangles {
            self.to_smooth.push(!has_normals);
            self.scene.corner_uvs.push(t.map(uv));
            self.scene.triangles.push(Triangle {
                vertices: t.map(|v| v + base),
                object,
                material,
            });
        }
        Ok(())
    }

    /// Checks that `accessor`'s elements lie within its buffer view and
    /// the view within its buffer: the `gltf` crate's reader reads one
    /// that does not as absent, and the mesh would be drawn otherwise.
    fn check_accessor(&self, accessor: &gltf::Accessor) -> Result<(), String> {
        let index = accessor.index();
        let Some(view) = accessor.view() else {
            return match accessor.sparse() {
                Some(_) => Ok(()),
                None => Err(format!("accessor {index} has no buffer view")),
            };
        };
        let buffer = view.buffer().index();
        let held = self.buffers.get(buffer).map_or(0, |d| d.0.len());
        let view_end = view.offset().saturating_add(view.length());
        if view_end > held {
            return Err(format!(
                "accessor {index}: its buffer view {} ends at byte {view_end} of buffer {buffer}, which holds {held}",
                view.index()
            ));
        }
        let count = accessor.count();
        if count == 0 {
            return Ok(());
        }
        let element = accessor.size();
        let stride = view.stride().unwrap_or(element);
        let end = (stride.saturating_mul(count - 1))
            .saturating_add(element)
            .saturating_add(accessor.offset());
        if end > view.length() {
            return Err(format!(
                "accessor {index} ({count} elements of {element} bytes from byte {}) needs {end} bytes of buffer view {}, which holds {}",
                accessor.offset(),
                view.index(),
                view.length()
            ));
        }
        Ok(())
    }

    fn material(&mut self, m: &gltf::Material) -> Material {
        let name = m.name().map_or_else(
            || format!("material {}", m.index().unwrap_or(0)),
            str::to_owned,
        );
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, alpha] = pbr.base_color_factor();
        let base = Vec3::new(r, g, b);
        let metallic = pbr.metallic_factor().clamp(0.0, 1.0);
        let roughness = pbr.roughness_factor().clamp(0.0, 1.0);
        let ior = m.ior().unwrap_or(GLASS_IOR);
        let (specular_factor, specular_color) = m.specular().map_or((1.0, Vec3::ONE), |s| {
            (s.specular_factor(), Vec3::from(s.specular_color_factor()))
        });
        let f0 = Vec3::splat(fresnel_reflectance(ior)) * specular_factor * specular_color;
        let transmission = m
            .transmission()
            .map_or(0.0, |t| t.transmission_factor())
            .clamp(0.0, 1.0);
        let diffuse = base * (1.0 - metallic) * (1.0 - transmission);
        let emission = Vec3::from(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0);
        let mut material = Material {
            name: name.clone(),
            ambient: diffuse,
            diffuse,
            specular: f0.lerp(base, metallic),
            shininess: (2.0 / roughness.powi(4).max(1e-4) - 2.0).clamp(1.0, 10_000.0),
            emission,
            reflectance: Vec3::ZERO,
            transmittance: Vec3::ZERO,
            ior,
            thin: false,
            fresnel: false,
            diffuse_texture: None,
            alpha_texture: None,
        };
        if transmission > 0.0 {
            // KHR_materials_transmission's surfaces are infinitely thin
            // (its specification): rays pass straight, the ior gives F0
            // and, under Fresnel, the rise towards grazing angles.
            material.reflectance = f0;
            material.transmittance = base * transmission * (Vec3::ONE - f0);
            material.thin = true;
        }
        let blend = m.alpha_mode() == gltf::material::AlphaMode::Blend;
        if blend {
            let opacity = 1.0 - material.transmittance.max_element();
            material.transmittance = Vec3::ONE - Vec3::splat(opacity * alpha);
        }
        if let Some(info) = pbr.base_color_texture() {
            if info.tex_coord() != 0 {
                self.warn(format!(
                    "material {name:?}: base colour texture on texture coordinates {}; vtfarm reads set 0 only",
                    info.tex_coord()
                ));
            } else if let Some(id) = self.texture(&info.texture()) {
                material.diffuse_texture = Some(id);
                if blend {
                    material.alpha_texture = Some(id);
                }
            }
        }
        if m.emissive_texture().is_some() || m.normal_texture().is_some() {
            self.warn(format!(
                "material {name:?}: emissive and normal textures are not used"
            ));
        }
        if let Some(exact) = m.extras().as_ref().and_then(|raw| vtfarm_extras(raw.get())) {
            exact.apply(&mut material);
        }
        material
    }

    /// The texture of an image, read once; a warning and `None` when it
    /// cannot be read.
    fn texture(&mut self, texture: &gltf::Texture) -> Option<TextureId> {
        let image = texture.source();
        if let Some(&id) = self.textures.get(&image.index()) {
            return id;
        }
        let loaded = self.read_image(&image);
        let id = match loaded {
            Ok(texture) => {
                self.scene.textures.push(texture);
                Some(self.scene.textures.len() as TextureId - 1)
            }
            Err(message) => {
                self.warn(format!(
                    "image {}: {message}; the material keeps its flat colour",
                    image.index()
                ));
                None
            }
        };
        self.textures.insert(image.index(), id);
        id
    }

    fn read_image(&self, image: &gltf::Image) -> Result<Texture, String> {
        let (name, bytes) = match image.source() {
            gltf::image::Source::View { view, .. } => {
                let data = &self
                    .buffers
                    .get(view.buffer().index())
                    .ok_or("no buffer")?
                    .0;
                let bytes = data
                    .get(view.offset()..view.offset() + view.length())
                    .ok_or("buffer view out of range")?;
                (format!("image {}", image.index()), bytes.to_vec())
            }
            gltf::image::Source::Uri { uri, .. } => {
                if uri.starts_with("data:") {
                    return Err("data URIs for images are not read".to_owned());
                }
                let file = uri_file(self.base, uri)?;
                let bytes = file::read_regular(&file, MAX_IMAGE_FILE_BYTES)
                    .map_err(|e| format!("{}: {e}", file.display()))?;
                (uri.to_owned(), bytes)
            }
        };
        Texture::decode(&name, &bytes).map_err(|e| e.to_string())
    }
}

/// The buffers of a parsed file: the GLB's binary chunk, data URIs, and
/// the files it names, each read as a regular file within
/// [`MAX_SCENE_FILE_BYTES`] (the `gltf` crate's own import reads any file
/// without bound).
fn load_buffers(
    path: &Path,
    base: &Path,
    gltf: &gltf::Gltf,
) -> Result<Vec<gltf::buffer::Data>, GltfError> {
    let mut blob = gltf.blob.clone();
    let mut buffers = Vec::new();
    for buffer in gltf.document.buffers() {
        let index = buffer.index();
        let mut bytes = match buffer.source() {
            gltf::buffer::Source::Bin => blob
                .take()
                .ok_or_else(|| invalid(path, format!("buffer {index}: no binary chunk")))?,
            source @ gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let data = gltf::buffer::Data::from_source(source, None);
                data.map_err(|error| invalid(path, format!("buffer {index}: {error}")))?
                    .0
            }
            gltf::buffer::Source::Uri(uri) => {
                let file = uri_file(base, uri)
                    .map_err(|message| invalid(path, format!("buffer {index}: {message}")))?;
                file::read_regular(&file, MAX_SCENE_FILE_BYTES)
                    .map_err(|error| GltfError::Io { path: file, error })?
            }
        };
        if bytes.len() < buffer.length() {
            return Err(invalid(
                path,
                format!(
                    "buffer {index}: {} bytes, {} declared",
                    bytes.len(),
                    buffer.length()
                ),
            ));
        }
        // The reader expects the padding to 4 bytes that a GLB chunk has.
        bytes.resize(bytes.len().next_multiple_of(4), 0);
        buffers.push(gltf::buffer::Data(bytes));
    }
    Ok(buffers)
}

/// The file a (non-data) URI names: `file:` paths as they are, relative
/// ones beside the glTF file; other schemes are not read.
fn uri_file(base: &Path, uri: &str) -> Result<PathBuf, String> {
    if let Some(path) = (uri.strip_prefix("file://")).or_else(|| uri.strip_prefix("file:")) {
        return Ok(PathBuf::from(percent_decode(path)));
    }
    if uri.contains(':') {
        return Err(format!("URI {uri:?}: only files and data URIs are read"));
    }
    Ok(base.join(percent_decode(uri)))
}

/// `%20` and friends in a URI turned back into bytes.
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match (
            bytes[i],
            bytes.get(i + 1).copied().and_then(hex),
            bytes.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (b, _, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// vtfarm's exact material values in `extras.vtfarm`.
#[derive(serde::Deserialize)]
struct ExactMaterial {
    ambient: [f32; 3],
    diffuse: [f32; 3],
    specular: [f32; 3],
    shininess: f32,
    emission: [f32; 3],
    reflectance: [f32; 3],
    transmittance: [f32; 3],
    ior: f32,
    #[serde(default)]
    thin: bool,
    #[serde(default)]
    fresnel: bool,
}

impl ExactMaterial {
    fn apply(&self, m: &mut Material) {
        m.ambient = self.ambient.into();
        m.diffuse = self.diffuse.into();
        m.specular = self.specular.into();
        m.shininess = self.shininess;
        m.emission = self.emission.into();
        m.reflectance = self.reflectance.into();
        m.transmittance = self.transmittance.into();
        m.ior = self.ior;
        m.thin = self.thin;
        m.fresnel = self.fresnel;
    }
}

fn vtfarm_extras(raw: &str) -> Option<ExactMaterial> {
    let value: Value = serde_json::from_str(raw).ok()?;
    let exact: ExactMaterial = serde_json::from_value(value.get("vtfarm")?.clone()).ok()?;
    let finite = [exact.shininess, exact.ior]
        .into_iter()
        .chain(
            [exact.ambient, exact.diffuse, exact.specular, exact.emission]
                .into_iter()
                .flatten(),
        )
        .chain(
            [exact.reflectance, exact.transmittance]
                .into_iter()
                .flatten(),
        )
        .all(f32::is_finite);
    finite.then_some(exact)
}

fn invalid(path: &Path, message: impl Into<String>) -> GltfError {
    GltfError::Invalid {
        path: path.to_owned(),
        message: message.into(),
    }
}

/// Writes `scene` as a binary glTF file at `path` (see the [module
/// documentation](self)). Textures are not written.
pub fn write_glb(scene: &Scene, path: &Path) -> Result<(), GltfError> {
    let glb = encode_glb(scene).map_err(|e| invalid(path, format!("invalid scene: {e}")))?;
    fs::write(path, glb).map_err(|error| GltfError::Io {
        path: path.to_owned(),
        error,
    })
}

/// `scene` as the bytes of a binary glTF file ([`write_glb`] writes them;
/// the master serves them to the dashboard's view).
pub fn encode_glb(scene: &Scene) -> Result<Vec<u8>, crate::SceneError> {
    scene.validate()?;
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes, mut nodes) = (vec![], vec![], vec![], vec![]);
    let mut push_view = |bin: &mut Vec<u8>, bytes: &[u8], target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        views.push(
            json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len(), "target": target}),
        );
        views.len() - 1
    };
    let mut start = 0;
    while start < scene.triangles.len() {
        let run = (
            scene.triangles[start].object,
            scene.triangles[start].material,
        );
        let end = (start..scene.triangles.len())
            .find(|&i| (scene.triangles[i].object, scene.triangles[i].material) != run)
            .unwrap_or(scene.triangles.len());
        let mut local: HashMap<u32, u32> = HashMap::new();
        let mut order = Vec::new();
        let indices: Vec<u32> = scene.triangles[start..end]
            .iter()
            .flat_map(|t| t.vertices)
            .map(|v| {
                *local.entry(v).or_insert_with(|| {
                    order.push(v);
                    order.len() as u32 - 1
                })
            })
            .collect();
        let floats = |values: &mut dyn Iterator<Item = Vec3>| -> Vec<u8> {
            values
                .flat_map(|v| v.to_array())
                .flat_map(f32::to_le_bytes)
                .collect()
        };
        let positions: Vec<Vec3> = order.iter().map(|&v| scene.positions[v as usize]).collect();
        let (lo, hi) = positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        let p = push_view(&mut bin, &floats(&mut positions.iter().copied()), 34962);
        let n = push_view(
            &mut bin,
            &floats(&mut order.iter().map(|&v| scene.normals[v as usize])),
            34962,
        );
        let i = push_view(
            &mut bin,
            &indices
                .iter()
                .flat_map(|i| i.to_le_bytes())
                .collect::<Vec<u8>>(),
            34963,
        );
        let a = accessors.len();
        accessors.push(json!({"bufferView": p, "componentType": 5126, "count": order.len(), "type": "VEC3", "min": lo.to_array(), "max": hi.to_array()}));
        accessors.push(
            json!({"bufferView": n, "componentType": 5126, "count": order.len(), "type": "VEC3"}),
        );
        accessors.push(json!({"bufferView": i, "componentType": 5125, "count": indices.len(), "type": "SCALAR"}));
        meshes.push(json!({"primitives": [{"attributes": {"POSITION": a, "NORMAL": a + 1}, "indices": a + 2, "material": run.1.raw(), "mode": 4}]}));
        nodes.push(json!({"name": scene.objects[run.0.index()].name, "mesh": meshes.len() - 1}));
        start = end;
    }
    let materials: Vec<Value> = scene.materials.iter().map(material_json).collect();
    let document = json!({
        "asset": {"version": "2.0", "generator": "vtfarm"},
        "extensionsUsed": ["KHR_materials_ior", "KHR_materials_transmission", "KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    let mut text = serde_json::to_vec(&document).expect("JSON of plain values");
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut glb = Vec::with_capacity(total);
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(total as u32).to_le_bytes());
    glb.extend_from_slice(&(text.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&text);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    Ok(glb)
}

/// A material in PBR terms (for other readers) and exactly (`extras.vtfarm`).
fn material_json(m: &Material) -> Value {
    let opacity = 1.0 - m.transmittance.max_element();
    let roughness = (2.0 / (m.shininess.max(0.0) + 2.0))
        .powf(0.25)
        .clamp(0.0, 1.0);
    let strength = m.emission.max_element().max(1.0);
    let mut extensions =
        json!({"KHR_materials_ior": {"ior": if m.ior >= 1.0 { m.ior } else { 1.0 }}});
    if m.transmittance.max_element() > 0.0 {
        extensions["KHR_materials_transmission"] =
            json!({"transmissionFactor": m.transmittance.max_element().min(1.0)});
    }
    if strength > 1.0 {
        extensions["KHR_materials_emissive_strength"] = json!({"emissiveStrength": strength});
    }
    json!({
        "name": m.name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [m.diffuse.x.min(1.0), m.diffuse.y.min(1.0), m.diffuse.z.min(1.0), opacity.clamp(0.0, 1.0)],
            "metallicFactor": 0.0,
            "roughnessFactor": roughness,
        },
        "emissiveFactor": (m.emission / strength).to_array(),
        "doubleSided": true,
        "extensions": extensions,
        "extras": {"vtfarm": {
            "ambient": m.ambient.to_array(),
            "diffuse": m.diffuse.to_array(),
            "specular": m.specular.to_array(),
            "shininess": m.shininess,
            "emission": m.emission.to_array(),
            "reflectance": m.reflectance.to_array(),
            "transmittance": m.transmittance.to_array(),
            "ior": m.ior,
            "thin": m.thin,
            "fresnel": m.fresnel,
        }},
    })
}
