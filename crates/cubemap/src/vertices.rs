//! Virtual vertices of the reflected meshes: one search per mesh vertex, or
//! (paper §5) one per vertex of a bounding grid around each mesh with the
//! mesh vertices interpolated from their cell's virtual corners.
//!
//! A reflected mesh is one scene object. Searches run on rayon; each result
//! depends only on its own vertex, so the output does not depend on the
//! thread count.

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use crate::maps::ReflectorMaps;
use crate::mesh::ReflectedMesh;
use crate::search::{Region, SearchSettings, VirtualVertex, search};

/// The interpolation grid's size (§5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridSettings {
    /// Grid cells per mesh vertex (the paper uses 0.04 to 0.14); meshes
    /// whose grid would have as many corners as vertices are searched
    /// directly.
    pub fraction: f32,
}

impl Default for GridSettings {
    fn default() -> Self {
        GridSettings { fraction: 0.1 }
    }
}

/// The virtual vertex of every vertex of `mesh` and the number of
/// searches run. Once `stopped` says so, the objects not yet searched are
/// left `FAILED` (the package is being cancelled).
pub(crate) fn virtual_vertices(
    mesh: &ReflectedMesh,
    maps: &ReflectorMaps,
    eye: Vec3,
    search_settings: &SearchSettings,
    grid: Option<&GridSettings>,
    stopped: &dyn Fn() -> bool,
) -> (Vec<VirtualVertex>, u64) {
    let mut out = vec![VirtualVertex::FAILED; mesh.positions.len()];
    let mut searches = 0;
    for vertices in objects_vertices(mesh) {
        if stopped() {
            break;
        }
        let points: Vec<Vec3> = vertices
            .iter()
            .map(|&v| mesh.positions[v as usize])
            .collect();
        let grid = grid.and_then(|g| Grid::new(&points, g.fraction));
        let results: Vec<VirtualVertex> = match grid {
            Some(grid) => {
                let corners: Vec<VirtualVertex> = grid
                    .corners
                    .par_iter()
                    .map(|&c| search(maps, eye, grid.corner_position(c), search_settings))
                    .collect();
                searches += corners.len() as u64;
                points
                    .par_iter()
                    .map(|&p| grid.interpolate(p, &corners))
                    .collect()
            }
            None => {
                searches += points.len() as u64;
                points
                    .par_iter()
                    .map(|&p| search(maps, eye, p, search_settings))
                    .collect()
            }
        };
        for (&v, result) in vertices.iter().zip(results) {
            out[v as usize] = result;
        }
    }
    (out, searches)
}

/// The mesh's vertex indices per object (objects in id order, vertices in
/// index order), leaving out objects without vertices.
fn objects_vertices(mesh: &ReflectedMesh) -> Vec<Vec<u32>> {
    let count = mesh
        .objects
        .iter()
        .map(|&o| o.index() + 1)
        .max()
        .unwrap_or(0);
    let mut objects = vec![Vec::new(); count];
    for (v, &object) in mesh.objects.iter().enumerate() {
        objects[object.index()].push(v as u32);
    }
    objects.retain(|v| !v.is_empty());
    objects
}

/// A regular bounding grid of one mesh, keeping only the corners of the
/// cells that hold a vertex.
struct Grid {
    origin: Vec3,
    cell: Vec3,
    cells: UVec3,
    /// Sorted keys of the corners in use.
    corners: Vec<u64>,
}

impl Grid {
    /// `None` when the grid would need at least as many searches as the mesh.
    fn new(points: &[Vec3], fraction: f32) -> Option<Grid> {
        let (lo, hi) = points.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        let extent = hi - lo;
        let target = (points.len() as f32 * fraction).max(1.0);
        // Near-cubic cells: flat axes get one cell and leave the cell
        // count to the others.
        let floor = extent.max_element() * 1e-3;
        let mut size = 0.0f32;
        for _ in 0..3 {
            let active: Vec<usize> = (0..3).filter(|&k| extent[k] > size.max(floor)).collect();
            if active.is_empty() {
                break;
            }
            let volume: f32 = active.iter().map(|&k| extent[k]).product();
            size = (volume / target).powf(1.0 / active.len() as f32);
        }
        let mut cells = UVec3::ONE;
        for k in 0..3 {
            cells[k] = ((extent[k] / size.max(1e-9)).round() as u32).clamp(1, 1 << 10);
        }
        let cell = (extent / cells.as_vec3()).max(Vec3::splat(1e-9));
        let mut grid = Grid {
            origin: lo,
            cell,
            cells,
            corners: Vec::new(),
        };
        let mut corners: Vec<u64> = points
            .iter()
            .flat_map(|&p| {
                let (c, _) = grid.locate(p);
                CORNERS.map(|o| grid.key(c + o))
            })
            .collect();
        corners.sort_unstable();
        corners.dedup();
        grid.corners = corners;
        (grid.corners.len() < points.len()).then_some(grid)
    }

    /// The cell holding `p` and `p`'s coordinates in it.
    fn locate(&self, p: Vec3) -> (UVec3, Vec3) {
        let f = (p - self.origin) / self.cell;
        let c = f
            .floor()
            .max(Vec3::ZERO)
            .as_uvec3()
            .min(self.cells - UVec3::ONE);
        (c, (f - c.as_vec3()).clamp(Vec3::ZERO, Vec3::ONE))
    }

    fn key(&self, corner: UVec3) -> u64 {
        let n = u64::from(self.cells.x + 1);
        let m = u64::from(self.cells.y + 1);
        (u64::from(corner.z) * m + u64::from(corner.y)) * n + u64::from(corner.x)
    }

    fn corner_position(&self, key: u64) -> Vec3 {
        let n = u64::from(self.cells.x + 1);
        let m = u64::from(self.cells.y + 1);
        let corner = Vec3::new(
            (key % n) as f32,
            ((key / n) % m) as f32,
            (key / (n * m)) as f32,
        );
        self.origin + corner * self.cell
    }

    /// Trilinear interpolation of the cell's virtual corners (§5). Failed
    /// corners (their reflection lies beyond the maps) are left out and the
    /// others' weights renormalised, as long as they carry most of the
    /// weight; the region is the "most visible" one among them.
    fn interpolate(&self, p: Vec3, corners: &[VirtualVertex]) -> VirtualVertex {
        let (c, w) = self.locate(p);
        let mut out = VirtualVertex {
            region: Region::Hidden,
            error: 0.0,
            ..VirtualVertex::FAILED
        };
        let mut total = 0.0;
        for o in CORNERS {
            let key = self.key(c + o);
            let index = self
                .corners
                .binary_search(&key)
                .expect("every occupied cell's corners were searched");
            let corner = &corners[index];
            if corner.region == Region::Failed {
                continue;
            }
            let weight = [o.x, o.y, o.z]
                .iter()
                .zip(w.to_array())
                .map(|(&bit, t)| if bit == 1 { t } else { 1.0 - t })
                .product::<f32>();
            total += weight;
            out.reflection_point += corner.reflection_point * weight;
            out.virtual_position += corner.virtual_position * weight;
            out.in_front |= corner.in_front;
            out.error = out.error.max(corner.error);
            out.iterations = out.iterations.max(corner.iterations);
            out.region = most_visible(out.region, corner.region);
        }
        if total < MIN_WEIGHT {
            return VirtualVertex::FAILED;
        }
        out.reflection_point /= total;
        out.virtual_position /= total;
        out
    }
}

/// Interpolated vertices need this much weight on successful corners.
const MIN_WEIGHT: f32 = 0.5;

const CORNERS: [UVec3; 8] = [
    UVec3::new(0, 0, 0),
    UVec3::new(1, 0, 0),
    UVec3::new(0, 1, 0),
    UVec3::new(1, 1, 0),
    UVec3::new(0, 0, 1),
    UVec3::new(1, 0, 1),
    UVec3::new(0, 1, 1),
    UVec3::new(1, 1, 1),
];

/// Reflected over unreflected over hidden.
fn most_visible(a: Region, b: Region) -> Region {
    let rank = |r: Region| match r {
        Region::Failed => 3,
        Region::Reflected => 2,
        Region::Unreflected => 1,
        Region::Hidden => 0,
    };
    if rank(a) >= rank(b) { a } else { b }
}
