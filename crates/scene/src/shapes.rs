//! Simple analytic meshes for test scenes and examples.

use std::collections::BTreeMap;

use glam::Vec3;

/// OBJ text of the unit disc in the y = 0 plane as a single polygon face
/// with `vertices` corners (counter-clockwise seen from +y): a stress test
/// for triangulation and normals.
pub fn disc_polygon_obj(vertices: usize) -> String {
    let mut obj = String::new();
    for i in 0..vertices {
        let a = std::f64::consts::TAU * i as f64 / vertices as f64;
        obj.push_str(&format!("v {} 0 {}\n", a.cos(), -a.sin()));
    }
    obj.push('f');
    for i in 1..=vertices {
        obj.push_str(&format!(" {i}"));
    }
    obj.push('\n');
    obj
}

/// The unit icosphere: the icosahedron's 12 points on the unit sphere and
/// its 20 faces (counter-clockwise seen from outside), each face split in
/// four `levels` times with the new points pushed onto the sphere.
/// Deterministic: the same `levels` gives the same points in the same order.
pub fn icosphere(levels: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let p = (1.0 + 5f32.sqrt()) / 2.0;
    let mut points: Vec<Vec3> = [
        [-1.0, p, 0.0],
        [1.0, p, 0.0],
        [-1.0, -p, 0.0],
        [1.0, -p, 0.0],
        [0.0, -1.0, p],
        [0.0, 1.0, p],
        [0.0, -1.0, -p],
        [0.0, 1.0, -p],
        [p, 0.0, -1.0],
        [p, 0.0, 1.0],
        [-p, 0.0, -1.0],
        [-p, 0.0, 1.0],
    ]
    .iter()
    .map(|&c| Vec3::from_array(c).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut midpoints = BTreeMap::new();
        let mut midpoint = |a: u32, b: u32, points: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                points.push(((points[a as usize] + points[b as usize]) * 0.5).normalize());
                points.len() as u32 - 1
            })
        };
        faces = faces
            .iter()
            .flat_map(|&[a, b, c]| {
                let ab = midpoint(a, b, &mut points);
                let bc = midpoint(b, c, &mut points);
                let ca = midpoint(c, a, &mut points);
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    (points, faces)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_points_lie_on_the_unit_sphere_and_faces_point_outwards() {
        for levels in 0..3 {
            let (points, faces) = icosphere(levels);
            assert_eq!(faces.len(), 20 * 4usize.pow(levels));
            assert_eq!(points.len(), 10 * 4usize.pow(levels) + 2);
            assert!(points.iter().all(|p| (p.length() - 1.0).abs() < 1e-6));
            for [a, b, c] in faces {
                let [a, b, c] = [a, b, c].map(|i| points[i as usize]);
                assert!((b - a).cross(c - a).dot(a + b + c) > 0.0);
            }
        }
    }
}
