//! The bounds that keep work and memory finite, and the error every domain
//! type's `validate` returns when a value lies outside its bound. The job
//! parser and the wire conversion both call those `validate` methods, so each
//! bound is written once, next to its type.

use std::fmt;

/// The largest absolute coordinate, in metres, of a scene vertex, an eye or a
/// light: 1,000 km. f32 still resolves 6 cm there, and the BVH's surface-area
/// costs stay finite (a vertex at 1e22 overflowed them and panicked obvhs).
pub const MAX_COORDINATE: f32 = 1.0e6;

/// A value outside the bound its type documents: `field = value: must be rule`.
/// `field` is the domain field's name; callers prefix their own context
/// (`quality.` in a job file, `vertex ` on the wire).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutOfBounds {
    pub field: &'static str,
    pub value: String,
    pub rule: String,
}

impl OutOfBounds {
    pub fn new(field: &'static str, value: impl fmt::Display, rule: impl Into<String>) -> Self {
        OutOfBounds {
            field,
            value: value.to_string(),
            rule: rule.into(),
        }
    }

    /// The message with `key` standing for the field (a job file's key name).
    pub fn message_for(&self, key: &str) -> String {
        format!("{key} = {}: must be {}", self.value, self.rule)
    }
}

impl fmt::Display for OutOfBounds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message_for(self.field))
    }
}

impl std::error::Error for OutOfBounds {}

/// Checks `ok(value)`, else the error for `field`.
pub fn check<T: fmt::Display + Copy>(
    field: &'static str,
    value: T,
    rule: impl Into<String>,
    ok: impl FnOnce(T) -> bool,
) -> Result<T, OutOfBounds> {
    if ok(value) {
        Ok(value)
    } else {
        Err(OutOfBounds::new(field, value, rule))
    }
}

/// A finite, non-negative number.
pub fn non_negative(field: &'static str, value: f32) -> Result<f32, OutOfBounds> {
    check(field, value, "finite and not negative", |v| {
        v.is_finite() && v >= 0.0
    })
}

/// A point whose coordinates are finite and within [`MAX_COORDINATE`].
pub fn point(field: &'static str, p: glam::Vec3) -> Result<glam::Vec3, OutOfBounds> {
    if p.is_finite() && p.abs().max_element() <= MAX_COORDINATE {
        Ok(p)
    } else {
        Err(OutOfBounds::new(
            field,
            p,
            format!("finite and within ±{MAX_COORDINATE:e} m"),
        ))
    }
}

/// A colour (or other vector) with finite, non-negative components.
pub fn non_negative3(field: &'static str, v: glam::Vec3) -> Result<glam::Vec3, OutOfBounds> {
    if v.is_finite() && v.min_element() >= 0.0 {
        Ok(v)
    } else {
        Err(OutOfBounds::new(field, v, "finite and not negative"))
    }
}
