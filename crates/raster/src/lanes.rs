//! Lane-wise `f32` arithmetic for shading several pixels at once. Every lane
//! performs exactly the scalar operations glam performs, in the same order
//! (no fused multiply-add, no reciprocal estimates), so a lane's result is
//! bit-identical to the scalar code's.
//!
//! The arithmetic is written once against a [`Backend`] of [`LANES`]-wide
//! registers: [`Portable`] (arrays, which LLVM vectorizes as it can) and, on
//! x86-64, [`Avx2`] (one AVX instruction per operation). IEEE addition,
//! subtraction, multiplication, division and square root are correctly
//! rounded in both, so the backends give the same bits; a caller picks
//! `Avx2` only inside a function compiled for AVX2 on a CPU that has it.

use std::ops::{Add, Div, Mul, Neg, Sub};

use glam::Vec3;

/// Pixels shaded together.
pub(crate) const LANES: usize = 8;

/// One register of [`LANES`] `f32` lanes and its lane masks.
pub(crate) trait Backend: Copy {
    type Reg: Copy;
    type Mask: Copy;
    fn splat(v: f32) -> Self::Reg;
    fn from_array(a: [f32; LANES]) -> Self::Reg;
    /// The first [`LANES`] values of `s` (which must hold as many).
    fn load(s: &[f32]) -> Self::Reg;
    fn to_array(r: Self::Reg) -> [f32; LANES];
    fn add(a: Self::Reg, b: Self::Reg) -> Self::Reg;
    fn sub(a: Self::Reg, b: Self::Reg) -> Self::Reg;
    fn mul(a: Self::Reg, b: Self::Reg) -> Self::Reg;
    fn div(a: Self::Reg, b: Self::Reg) -> Self::Reg;
    fn sqrt(a: Self::Reg) -> Self::Reg;
    /// `-v` (the sign bit flipped, NaN included).
    fn neg(a: Self::Reg) -> Self::Reg;
    /// `if v > 0.0 { v } else { 0.0 }`: NaN and -0.0 give +0.0.
    fn positive_part(a: Self::Reg) -> Self::Reg;
    /// `a < b`, false where either is NaN.
    fn lt(a: Self::Reg, b: Self::Reg) -> Self::Mask;
    /// `!(a <= b)`: true where either is NaN.
    fn not_le(a: Self::Reg, b: Self::Reg) -> Self::Mask;
    /// `a > b`, false where either is NaN.
    fn gt(a: Self::Reg, b: Self::Reg) -> Self::Mask;
    /// `v.is_finite()`.
    fn is_finite(a: Self::Reg) -> Self::Mask;
    fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    fn all(m: Self::Mask) -> bool;
    fn mask_to_array(m: Self::Mask) -> [bool; LANES];
    /// `a` where `mask` holds, else `b`.
    fn select(m: Self::Mask, a: Self::Reg, b: Self::Reg) -> Self::Reg;
}

/// Arrays of lanes: the arithmetic LLVM vectorizes on any CPU.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Portable;

impl Portable {
    #[inline(always)]
    fn zip(a: [f32; LANES], b: [f32; LANES], f: impl Fn(f32, f32) -> f32) -> [f32; LANES] {
        std::array::from_fn(|i| f(a[i], b[i]))
    }

    #[inline(always)]
    fn test(a: [f32; LANES], b: [f32; LANES], f: impl Fn(f32, f32) -> bool) -> [bool; LANES] {
        std::array::from_fn(|i| f(a[i], b[i]))
    }
}

impl Backend for Portable {
    type Reg = [f32; LANES];
    type Mask = [bool; LANES];

    #[inline(always)]
    fn splat(v: f32) -> Self::Reg {
        [v; LANES]
    }
    #[inline(always)]
    fn from_array(a: [f32; LANES]) -> Self::Reg {
        a
    }
    #[inline(always)]
    fn load(s: &[f32]) -> Self::Reg {
        std::array::from_fn(|i| s[i])
    }
    #[inline(always)]
    fn to_array(r: Self::Reg) -> [f32; LANES] {
        r
    }
    #[inline(always)]
    fn add(a: Self::Reg, b: Self::Reg) -> Self::Reg {
        Self::zip(a, b, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(a: Self::Reg, b: Self::Reg) -> Self::Reg {
        Self::zip(a, b, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(a: Self::Reg, b: Self::Reg) -> Self::Reg {
        Self::zip(a, b, |a, b| a * b)
    }
    #[inline(always)]
    fn div(a: Self::Reg, b: Self::Reg) -> Self::Reg {
        Self::zip(a, b, |a, b| a / b)
    }
    #[inline(always)]
    fn sqrt(a: Self::Reg) -> Self::Reg {
        a.map(f32::sqrt)
    }
    #[inline(always)]
    fn neg(a: Self::Reg) -> Self::Reg {
        a.map(|v| -v)
    }
    #[inline(always)]
    fn positive_part(a: Self::Reg) -> Self::Reg {
        a.map(|v| if v > 0.0 { v } else { 0.0 })
    }
    #[inline(always)]
    fn lt(a: Self::Reg, b: Self::Reg) -> Self::Mask {
        Self::test(a, b, |a, b| a < b)
    }
    #[inline(always)]
    fn not_le(a: Self::Reg, b: Self::Reg) -> Self::Mask {
        Self::test(a, b, |a, b| a > b || a.is_nan() || b.is_nan())
    }
    #[inline(always)]
    fn gt(a: Self::Reg, b: Self::Reg) -> Self::Mask {
        Self::test(a, b, |a, b| a > b)
    }
    #[inline(always)]
    fn is_finite(a: Self::Reg) -> Self::Mask {
        a.map(f32::is_finite)
    }
    #[inline(always)]
    fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask {
        std::array::from_fn(|i| a[i] && b[i])
    }
    #[inline(always)]
    fn all(m: Self::Mask) -> bool {
        m.iter().all(|&m| m)
    }
    #[inline(always)]
    fn mask_to_array(m: Self::Mask) -> [bool; LANES] {
        m
    }
    #[inline(always)]
    fn select(m: Self::Mask, a: Self::Reg, b: Self::Reg) -> Self::Reg {
        std::array::from_fn(|i| if m[i] { a[i] } else { b[i] })
    }
}

/// AVX registers, eight lanes each. Its operations compile to AVX
/// instructions only once inlined into a function compiled for AVX2 (the
/// intrinsics are inlined there), so it must be used only from one, on a
/// CPU that has AVX2: it has no value to construct, the caller's promise.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use super::{Avx2, Backend, LANES};

    // SAFETY (every block below): `Avx2` is used only inside functions
    // compiled with AVX2 enabled, called after the CPU's AVX2 was detected
    // (see the type's documentation).
    impl Backend for Avx2 {
        type Reg = __m256;
        type Mask = __m256;

        #[inline(always)]
        fn splat(v: f32) -> Self::Reg {
            unsafe { _mm256_set1_ps(v) }
        }
        #[inline(always)]
        fn from_array(a: [f32; LANES]) -> Self::Reg {
            unsafe { _mm256_loadu_ps(a.as_ptr()) }
        }
        #[inline(always)]
        fn load(s: &[f32]) -> Self::Reg {
            assert!(s.len() >= LANES);
            unsafe { _mm256_loadu_ps(s.as_ptr()) }
        }
        #[inline(always)]
        fn to_array(r: Self::Reg) -> [f32; LANES] {
            let mut out = [0.0; LANES];
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), r) };
            out
        }
        #[inline(always)]
        fn add(a: Self::Reg, b: Self::Reg) -> Self::Reg {
            unsafe { _mm256_add_ps(a, b) }
        }
        #[inline(always)]
        fn sub(a: Self::Reg, b: Self::Reg) -> Self::Reg {
            unsafe { _mm256_sub_ps(a, b) }
        }
        #[inline(always)]
        fn mul(a: Self::Reg, b: Self::Reg) -> Self::Reg {
            unsafe { _mm256_mul_ps(a, b) }
        }
        #[inline(always)]
        fn div(a: Self::Reg, b: Self::Reg) -> Self::Reg {
            unsafe { _mm256_div_ps(a, b) }
        }
        #[inline(always)]
        fn sqrt(a: Self::Reg) -> Self::Reg {
            unsafe { _mm256_sqrt_ps(a) }
        }
        #[inline(always)]
        fn neg(a: Self::Reg) -> Self::Reg {
            unsafe { _mm256_xor_ps(a, _mm256_set1_ps(-0.0)) }
        }
        #[inline(always)]
        fn positive_part(a: Self::Reg) -> Self::Reg {
            // `v > 0` is false for NaN and -0.0: both keep the zero.
            unsafe {
                let zero = _mm256_setzero_ps();
                _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(a, zero), a)
            }
        }
        #[inline(always)]
        fn lt(a: Self::Reg, b: Self::Reg) -> Self::Mask {
            unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(a, b) }
        }
        #[inline(always)]
        fn not_le(a: Self::Reg, b: Self::Reg) -> Self::Mask {
            unsafe { _mm256_cmp_ps::<_CMP_NLE_UQ>(a, b) }
        }
        #[inline(always)]
        fn gt(a: Self::Reg, b: Self::Reg) -> Self::Mask {
            unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(a, b) }
        }
        #[inline(always)]
        fn is_finite(a: Self::Reg) -> Self::Mask {
            // |v| < infinity: false for infinities and NaN.
            unsafe {
                let magnitude = _mm256_andnot_ps(_mm256_set1_ps(-0.0), a);
                _mm256_cmp_ps::<_CMP_LT_OQ>(magnitude, _mm256_set1_ps(f32::INFINITY))
            }
        }
        #[inline(always)]
        fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask {
            unsafe { _mm256_and_ps(a, b) }
        }
        #[inline(always)]
        fn all(m: Self::Mask) -> bool {
            unsafe { _mm256_movemask_ps(m) == 0xff }
        }
        #[inline(always)]
        fn mask_to_array(m: Self::Mask) -> [bool; LANES] {
            let bits = unsafe { _mm256_movemask_ps(m) };
            std::array::from_fn(|i| bits & (1 << i) != 0)
        }
        #[inline(always)]
        fn select(m: Self::Mask, a: Self::Reg, b: Self::Reg) -> Self::Reg {
            unsafe { _mm256_blendv_ps(b, a, m) }
        }
    }
}

/// One `f32` per lane.
#[derive(Clone, Copy)]
pub(crate) struct F<B: Backend>(pub(crate) B::Reg);

impl<B: Backend> F<B> {
    #[inline(always)]
    pub(crate) fn splat(v: f32) -> Self {
        F(B::splat(v))
    }

    #[inline(always)]
    pub(crate) fn load(s: &[f32]) -> Self {
        F(B::load(s))
    }

    #[inline(always)]
    pub(crate) fn to_array(self) -> [f32; LANES] {
        B::to_array(self.0)
    }

    #[inline(always)]
    pub(crate) fn sqrt(self) -> Self {
        F(B::sqrt(self.0))
    }

    /// `if v > 0.0 { v } else { 0.0 }` per lane.
    #[inline(always)]
    pub(crate) fn positive_part(self) -> Self {
        F(B::positive_part(self.0))
    }

    #[inline(always)]
    pub(crate) fn lt(self, o: Self) -> B::Mask {
        B::lt(self.0, o.0)
    }

    #[inline(always)]
    pub(crate) fn gt(self, o: Self) -> B::Mask {
        B::gt(self.0, o.0)
    }

    /// `!(self <= o)`: true where either is NaN.
    #[inline(always)]
    pub(crate) fn not_le(self, o: Self) -> B::Mask {
        B::not_le(self.0, o.0)
    }

    #[inline(always)]
    pub(crate) fn is_finite(self) -> B::Mask {
        B::is_finite(self.0)
    }

    /// `a` where `mask` holds, else `b`.
    #[inline(always)]
    pub(crate) fn select(mask: B::Mask, a: Self, b: Self) -> Self {
        F(B::select(mask, a.0, b.0))
    }
}

impl<B: Backend> Add for F<B> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        F(B::add(self.0, o.0))
    }
}

impl<B: Backend> Sub for F<B> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        F(B::sub(self.0, o.0))
    }
}

impl<B: Backend> Mul for F<B> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        F(B::mul(self.0, o.0))
    }
}

impl<B: Backend> Div for F<B> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        F(B::div(self.0, o.0))
    }
}

impl<B: Backend> Neg for F<B> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        F(B::neg(self.0))
    }
}

/// One `Vec3` per lane, stored by component.
#[derive(Clone, Copy)]
pub(crate) struct V3<B: Backend> {
    pub(crate) x: F<B>,
    pub(crate) y: F<B>,
    pub(crate) z: F<B>,
}

impl<B: Backend> V3<B> {
    #[inline(always)]
    pub(crate) fn splat(v: Vec3) -> Self {
        V3 {
            x: F::splat(v.x),
            y: F::splat(v.y),
            z: F::splat(v.z),
        }
    }

    /// Lane `i`'s vector is `f(i)`.
    #[inline(always)]
    pub(crate) fn from_fn(f: impl Fn(usize) -> Vec3) -> Self {
        let lanes: [Vec3; LANES] = std::array::from_fn(f);
        V3 {
            x: F(B::from_array(lanes.map(|v| v.x))),
            y: F(B::from_array(lanes.map(|v| v.y))),
            z: F(B::from_array(lanes.map(|v| v.z))),
        }
    }

    /// The lanes' vectors.
    #[inline(always)]
    pub(crate) fn to_array(self) -> [Vec3; LANES] {
        let [x, y, z] = [self.x, self.y, self.z].map(F::to_array);
        std::array::from_fn(|i| Vec3::new(x[i], y[i], z[i]))
    }

    /// As `Vec3::dot`.
    #[inline(always)]
    pub(crate) fn dot(self, o: Self) -> F<B> {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// As `Vec3::length_recip`.
    #[inline(always)]
    pub(crate) fn length_recip(self) -> F<B> {
        F::splat(1.0) / self.dot(self).sqrt()
    }

    /// As `Vec3::normalize` (without its debug assertion).
    #[inline(always)]
    pub(crate) fn normalize(self) -> Self {
        self * self.length_recip()
    }

    /// Where `Vec3::normalize_or` takes the normal path: a finite,
    /// positive reciprocal length `rcp`.
    #[inline(always)]
    fn normalizable(rcp: F<B>) -> B::Mask {
        B::and(rcp.is_finite(), rcp.gt(F::splat(0.0)))
    }

    /// As `Vec3::normalize_or`, lane by lane, with the fallback made only
    /// when a lane needs it.
    #[inline(always)]
    pub(crate) fn normalize_or_else(self, fallback: impl FnOnce() -> Self) -> Self {
        let rcp = self.length_recip();
        let ok = Self::normalizable(rcp);
        if B::all(ok) {
            self * rcp
        } else {
            V3::select(ok, self * rcp, fallback())
        }
    }

    /// As `Vec3::normalize_or`, lane by lane.
    #[inline(always)]
    pub(crate) fn normalize_or(self, fallback: Self) -> Self {
        let rcp = self.length_recip();
        V3::select(Self::normalizable(rcp), self * rcp, fallback)
    }

    /// `a` where `mask` holds, else `b`.
    #[inline(always)]
    pub(crate) fn select(mask: B::Mask, a: Self, b: Self) -> Self {
        V3 {
            x: F::select(mask, a.x, b.x),
            y: F::select(mask, a.y, b.y),
            z: F::select(mask, a.z, b.z),
        }
    }
}

impl<B: Backend> Add for V3<B> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        V3 {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl<B: Backend> Sub for V3<B> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        V3 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

impl<B: Backend> Neg for V3<B> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        V3 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// As `Vec3 * f32`, lane by lane.
impl<B: Backend> Mul<F<B>> for V3<B> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, k: F<B>) -> Self {
        V3 {
            x: self.x * k,
            y: self.y * k,
            z: self.z * k,
        }
    }
}

/// As `Vec3 * Vec3` (component-wise), lane by lane.
impl<B: Backend> Mul<V3<B>> for V3<B> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        V3 {
            x: self.x * o.x,
            y: self.y * o.y,
            z: self.z * o.z,
        }
    }
}

/// As `Vec3 / f32`, lane by lane.
impl<B: Backend> Div<F<B>> for V3<B> {
    type Output = Self;
    #[inline(always)]
    fn div(self, k: F<B>) -> Self {
        V3 {
            x: self.x / k,
            y: self.y / k,
            z: self.z / k,
        }
    }
}
