//! The surface an open reflector's maps continue on beyond its rim: the
//! least-squares quadric height field z = q(x, y) over the reflector's mean
//! plane. The paper asks for a closed companion object to fill the maps
//! (§6.2) and leaves making it automatically to future work; a quadric
//! continues a gently curved patch (the cover-glass designs: flat, tilted,
//! cylindrical, ellipsoidal) with its curvature, so vertices reflected just
//! beyond the rim still find a reflection point with the right normal.

use glam::{DVec3, Vec3};

/// z = c0 x² + c1 xy + c2 y² + c3 x + c4 y + c5 in a frame on the mean plane.
#[derive(Clone, Copy, Debug)]
pub(crate) struct QuadricPatch {
    origin: Vec3,
    x: Vec3,
    y: Vec3,
    z: Vec3,
    c: [f64; 6],
}

impl QuadricPatch {
    /// Fits the patch to `points` with `z` the unit mean normal (the side
    /// the reflector faces). `None` when the points do not determine it.
    pub(crate) fn fit(points: &[Vec3], origin: Vec3, normal: Vec3) -> Option<QuadricPatch> {
        let z = normal.try_normalize()?;
        let (x, y) = z.any_orthonormal_pair();
        let mut ata = [[0.0f64; 6]; 6];
        let mut atb = [0.0f64; 6];
        for &p in points {
            let d = p - origin;
            let (u, v, w) = (
                f64::from(d.dot(x)),
                f64::from(d.dot(y)),
                f64::from(d.dot(z)),
            );
            let row = [u * u, u * v, v * v, u, v, 1.0];
            for i in 0..6 {
                for j in 0..6 {
                    ata[i][j] += row[i] * row[j];
                }
                atb[i] += row[i] * w;
            }
        }
        let c = solve(ata, atb)?;
        Some(QuadricPatch { origin, x, y, z, c })
    }

    /// The nearest point where the ray `origin + t direction` (t > 0) meets
    /// the patch, with the patch's unit normal there (facing +z).
    pub(crate) fn intersect(&self, origin: Vec3, direction: Vec3) -> Option<(Vec3, Vec3)> {
        let o = origin - self.origin;
        let local = |v: Vec3| {
            DVec3::new(
                v.dot(self.x).into(),
                v.dot(self.y).into(),
                v.dot(self.z).into(),
            )
        };
        let (o, d) = (local(o), local(direction));
        let c = &self.c;
        let a = c[0] * d.x * d.x + c[1] * d.x * d.y + c[2] * d.y * d.y;
        let b = 2.0 * c[0] * o.x * d.x
            + c[1] * (o.x * d.y + o.y * d.x)
            + 2.0 * c[2] * o.y * d.y
            + c[3] * d.x
            + c[4] * d.y
            - d.z;
        let k =
            c[0] * o.x * o.x + c[1] * o.x * o.y + c[2] * o.y * o.y + c[3] * o.x + c[4] * o.y + c[5]
                - o.z;
        let t = smallest_positive_root(a, b, k)?;
        let p = o + d * t;
        let gradient_x = 2.0 * c[0] * p.x + c[1] * p.y + c[3];
        let gradient_y = c[1] * p.x + 2.0 * c[2] * p.y + c[4];
        let n = DVec3::new(-gradient_x, -gradient_y, 1.0).normalize();
        let world = |v: DVec3| {
            let v = v.as_vec3();
            self.x * v.x + self.y * v.y + self.z * v.z
        };
        Some((self.origin + world(p), world(n).normalize()))
    }
}

/// The smallest t > 0 with a t² + b t + k = 0.
fn smallest_positive_root(a: f64, b: f64, k: f64) -> Option<f64> {
    let scale = a.abs().max(b.abs()).max(k.abs()).max(f64::MIN_POSITIVE);
    if a.abs() < 1e-12 * scale {
        let t = -k / b;
        return (b != 0.0 && t > 0.0).then_some(t);
    }
    let disc = b * b - 4.0 * a * k;
    if disc < 0.0 {
        return None;
    }
    // The numerically stable pair of roots.
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r1, r2) = (q / a, if q != 0.0 { k / q } else { q / a });
    [r1.min(r2), r1.max(r2)].into_iter().find(|&t| t > 0.0)
}

/// Gaussian elimination with partial pivoting; `None` if singular.
fn solve(mut m: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = m.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
    for col in 0..6 {
        let pivot = (col..6).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if m[pivot][col].abs() <= 1e-14 * scale {
            return None;
        }
        m.swap(col, pivot);
        b.swap(col, pivot);
        let (above, below) = m.split_at_mut(col + 1);
        let pivot_row = &above[col];
        for (offset, row) in below.iter_mut().enumerate() {
            let f = row[col] / pivot_row[col];
            for (value, &p) in row.iter_mut().zip(pivot_row).skip(col) {
                *value -= f * p;
            }
            b[col + 1 + offset] -= f * b[col];
        }
    }
    let mut x = [0.0; 6];
    for row in (0..6).rev() {
        let tail: f64 = (row + 1..6).map(|k| m[row][k] * x[k]).sum();
        x[row] = (b[row] - tail) / m[row][row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fitted_paraboloid_is_met_where_it_lies() {
        let f = |x: f32, y: f32| 0.3 * x * x - 0.1 * x * y + 0.8 * y * y + 0.05 * x;
        let points: Vec<Vec3> = (0..49)
            .map(|k| {
                let (x, y) = ((k % 7) as f32 * 0.1 - 0.3, (k / 7) as f32 * 0.1 - 0.3);
                Vec3::new(x, y, f(x, y))
            })
            .collect();
        let patch = QuadricPatch::fit(&points, Vec3::ZERO, Vec3::Z).expect("well posed");
        let origin = Vec3::new(0.0, 0.0, -1.0);
        let target = Vec3::new(0.7, -0.5, f(0.7, -0.5));
        let (p, n) = patch
            .intersect(origin, (target - origin).normalize())
            .expect("hits");
        assert!((p - target).length() < 1e-4, "{p} vs {target}");
        let expected = Vec3::new(-(0.6 * 0.7 + 0.05 + 0.05), -(-0.07 - 0.8), 1.0).normalize();
        assert!((n - expected).length() < 1e-4, "{n} vs {expected}");
    }
}
