//! Planes of dropped ID buffers, kept for the next buffers. A plane in fresh
//! memory pays a page fault per 4 KiB on its first pass, and a worker makes
//! new buffers every frame: at a worker's set-up sizes the faults cost as
//! much as a third of the rasterizing. A few planes' allocations (at most
//! [`MAX_KEPT`] of each type and [`MAX_KEPT_BYTES`] in all) are kept here
//! and handed to the next buffers that need that much. A kept plane's old
//! values carry over ([`reshape`] fills only beyond them), so every user
//! writes or fills what it reads.

use std::sync::Mutex;

/// The most planes of one element type kept.
const MAX_KEPT: usize = 12;
/// The most bytes kept in all: about five full 1080p buffers.
const MAX_KEPT_BYTES: usize = 128 << 20;

/// The kept planes, per element type.
pub(crate) struct Kept {
    words: Vec<Vec<u32>>,
    floats: Vec<Vec<f32>>,
}

static KEPT: Mutex<Kept> = Mutex::new(Kept {
    words: Vec::new(),
    floats: Vec::new(),
});

/// The element types whose planes are kept.
pub(crate) trait Plane: Copy + Sized {
    fn kept(kept: &mut Kept) -> &mut Vec<Vec<Self>>;
}

impl Plane for u32 {
    fn kept(kept: &mut Kept) -> &mut Vec<Vec<u32>> {
        &mut kept.words
    }
}

impl Plane for f32 {
    fn kept(kept: &mut Kept) -> &mut Vec<Vec<f32>> {
        &mut kept.floats
    }
}

/// Makes `plane` `n` long, with `fill` where it grows beyond what it (or
/// the kept plane it takes) held before, whatever values it holds
/// elsewhere: in its own allocation where that is large enough, else in the
/// smallest kept one that is.
pub(crate) fn reshape<T: Plane>(plane: &mut Vec<T>, n: usize, fill: T) {
    if plane.capacity() < n
        && let Some(larger) = take(n)
    {
        keep(std::mem::replace(plane, larger));
    }
    plane.truncate(n);
    plane.resize(n, fill);
}

/// A copy of `source` in the smallest kept plane that holds it, else in a
/// fresh allocation.
pub(crate) fn copied<T: Plane>(source: &[T]) -> Vec<T> {
    let mut plane = take(source.len()).unwrap_or_default();
    plane.clear();
    plane.extend_from_slice(source);
    plane
}

/// Takes the smallest kept plane of at least `n` elements' capacity.
fn take<T: Plane>(n: usize) -> Option<Vec<T>> {
    let mut kept = KEPT.lock().unwrap_or_else(|e| e.into_inner());
    let list = T::kept(&mut kept);
    let best = (list.iter().enumerate())
        .filter(|(_, p)| p.capacity() >= n)
        .min_by_key(|(_, p)| p.capacity())
        .map(|(i, _)| i)?;
    Some(list.swap_remove(best))
}

/// Keeps `plane`'s allocation for a later [`reshape`], while there is room.
pub(crate) fn keep<T: Plane>(plane: Vec<T>) {
    if plane.capacity() == 0 {
        return;
    }
    // Kept with its values: a later `reshape` fills only beyond them, as
    // its callers overwrite what they use.
    let mut kept = KEPT.lock().unwrap_or_else(|e| e.into_inner());
    let bytes = |k: &Kept| {
        let words: usize = k.words.iter().map(Vec::capacity).sum();
        let floats: usize = k.floats.iter().map(Vec::capacity).sum();
        (words + floats) * 4
    };
    if bytes(&kept) + plane.capacity() * size_of::<T>() > MAX_KEPT_BYTES {
        return;
    }
    let list = T::kept(&mut kept);
    if list.len() < MAX_KEPT {
        list.push(plane);
    }
}
