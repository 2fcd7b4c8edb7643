//! Lane-wise `f32` arithmetic for shading several pixels at once. Every lane
//! performs exactly the scalar operations glam performs, in the same order
//! (no fused multiply-add, no reciprocal estimates), so a lane's result is
//! bit-identical to the scalar code's while LLVM turns each operation into
//! one vector instruction across the lanes.

use std::ops::{Add, Div, Mul, Neg, Sub};

use glam::Vec3;

/// Pixels shaded together.
pub(crate) const LANES: usize = 8;

/// One `f32` per lane.
#[derive(Clone, Copy, Debug)]
pub(crate) struct F(pub(crate) [f32; LANES]);

/// One `bool` per lane.
pub(crate) type Mask = [bool; LANES];

impl F {
    #[inline(always)]
    pub(crate) fn splat(v: f32) -> F {
        F([v; LANES])
    }

    #[inline(always)]
    fn zip(self, other: F, f: impl Fn(f32, f32) -> f32) -> F {
        let mut out = self.0;
        for (o, &b) in out.iter_mut().zip(&other.0) {
            *o = f(*o, b);
        }
        F(out)
    }

    #[inline(always)]
    pub(crate) fn map(self, f: impl Fn(f32) -> f32) -> F {
        let mut out = self.0;
        for o in &mut out {
            *o = f(*o);
        }
        F(out)
    }

    #[inline(always)]
    pub(crate) fn test(self, f: impl Fn(f32) -> bool) -> Mask {
        let mut out = [false; LANES];
        for (o, &v) in out.iter_mut().zip(&self.0) {
            *o = f(v);
        }
        out
    }

    /// `a` where `mask` holds, else `b`.
    #[inline(always)]
    pub(crate) fn select(mask: Mask, a: F, b: F) -> F {
        let mut out = b.0;
        for i in 0..LANES {
            if mask[i] {
                out[i] = a.0[i];
            }
        }
        F(out)
    }
}

impl Add for F {
    type Output = F;
    #[inline(always)]
    fn add(self, o: F) -> F {
        self.zip(o, |a, b| a + b)
    }
}

impl Sub for F {
    type Output = F;
    #[inline(always)]
    fn sub(self, o: F) -> F {
        self.zip(o, |a, b| a - b)
    }
}

impl Mul for F {
    type Output = F;
    #[inline(always)]
    fn mul(self, o: F) -> F {
        self.zip(o, |a, b| a * b)
    }
}

impl Div for F {
    type Output = F;
    #[inline(always)]
    fn div(self, o: F) -> F {
        self.zip(o, |a, b| a / b)
    }
}

/// One `Vec3` per lane, stored by component.
#[derive(Clone, Copy, Debug)]
pub(crate) struct V3 {
    pub(crate) x: F,
    pub(crate) y: F,
    pub(crate) z: F,
}

impl V3 {
    #[inline(always)]
    pub(crate) fn splat(v: Vec3) -> V3 {
        V3 {
            x: F::splat(v.x),
            y: F::splat(v.y),
            z: F::splat(v.z),
        }
    }

    /// Lane `i`'s vector is `f(i)`.
    #[inline(always)]
    pub(crate) fn from_fn(f: impl Fn(usize) -> Vec3) -> V3 {
        let mut v = V3::splat(Vec3::ZERO);
        for i in 0..LANES {
            let lane = f(i);
            (v.x.0[i], v.y.0[i], v.z.0[i]) = (lane.x, lane.y, lane.z);
        }
        v
    }

    #[inline(always)]
    pub(crate) fn lane(&self, i: usize) -> Vec3 {
        Vec3::new(self.x.0[i], self.y.0[i], self.z.0[i])
    }

    /// As `Vec3::dot`.
    #[inline(always)]
    pub(crate) fn dot(self, o: V3) -> F {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// As `Vec3::length_recip`.
    #[inline(always)]
    pub(crate) fn length_recip(self) -> F {
        F::splat(1.0) / self.dot(self).map(f32::sqrt)
    }

    /// As `Vec3::normalize` (without its debug assertion).
    #[inline(always)]
    pub(crate) fn normalize(self) -> V3 {
        self * self.length_recip()
    }

    /// As `Vec3::normalize_or`, lane by lane, with the fallback made only
    /// when a lane needs it.
    #[inline(always)]
    pub(crate) fn normalize_or_else(self, fallback: impl FnOnce() -> V3) -> V3 {
        let rcp = self.length_recip();
        let ok = rcp.test(|r| r.is_finite() && r > 0.0);
        if ok.iter().all(|&ok| ok) {
            self * rcp
        } else {
            V3::select(ok, self * rcp, fallback())
        }
    }

    /// As `Vec3::normalize_or`, lane by lane.
    #[inline(always)]
    pub(crate) fn normalize_or(self, fallback: V3) -> V3 {
        let rcp = self.length_recip();
        let ok = rcp.test(|r| r.is_finite() && r > 0.0);
        V3::select(ok, self * rcp, fallback)
    }

    /// `a` where `mask` holds, else `b`.
    #[inline(always)]
    pub(crate) fn select(mask: Mask, a: V3, b: V3) -> V3 {
        V3 {
            x: F::select(mask, a.x, b.x),
            y: F::select(mask, a.y, b.y),
            z: F::select(mask, a.z, b.z),
        }
    }
}

impl Add for V3 {
    type Output = V3;
    #[inline(always)]
    fn add(self, o: V3) -> V3 {
        V3 {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl Sub for V3 {
    type Output = V3;
    #[inline(always)]
    fn sub(self, o: V3) -> V3 {
        V3 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

impl Neg for V3 {
    type Output = V3;
    #[inline(always)]
    fn neg(self) -> V3 {
        V3 {
            x: self.x.map(|v| -v),
            y: self.y.map(|v| -v),
            z: self.z.map(|v| -v),
        }
    }
}

/// As `Vec3 * f32`, lane by lane.
impl Mul<F> for V3 {
    type Output = V3;
    #[inline(always)]
    fn mul(self, k: F) -> V3 {
        V3 {
            x: self.x * k,
            y: self.y * k,
            z: self.z * k,
        }
    }
}

/// As `Vec3 * Vec3` (component-wise), lane by lane.
impl Mul<V3> for V3 {
    type Output = V3;
    #[inline(always)]
    fn mul(self, o: V3) -> V3 {
        V3 {
            x: self.x * o.x,
            y: self.y * o.y,
            z: self.z * o.z,
        }
    }
}

/// As `Vec3 / f32`, lane by lane.
impl Div<F> for V3 {
    type Output = V3;
    #[inline(always)]
    fn div(self, k: F) -> V3 {
        V3 {
            x: self.x / k,
            y: self.y / k,
            z: self.z / k,
        }
    }
}
