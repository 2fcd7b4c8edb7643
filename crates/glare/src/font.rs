//! A tiny built-in 3x5 bitmap font (digits, upper-case letters and a few
//! symbols) for legends; lower-case letters are drawn upper-case and unknown
//! characters as `?`.

use glam::Vec3;
use vtfarm_imaging::Image;

/// Glyph width in font pixels (before scaling).
pub const GLYPH_WIDTH: u32 = 3;
/// Glyph height in font pixels (before scaling).
pub const GLYPH_HEIGHT: u32 = 5;
/// Horizontal advance per character in font pixels (glyph + 1 blank column).
const ADVANCE: u32 = GLYPH_WIDTH + 1;

/// Five rows of three bits, the most significant of the three on the left.
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        ' ' => [0, 0, 0, 0, 0],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        '_' => [0, 0, 0, 0, 7],
        '=' => [0, 7, 0, 7, 0],
        '/' => [1, 1, 2, 4, 4],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        '<' => [1, 2, 4, 2, 1],
        '>' => [4, 2, 1, 2, 4],
        '#' => [5, 7, 5, 7, 5],
        '%' => [5, 1, 2, 4, 5],
        _ => [7, 1, 3, 0, 2],
    }
}

/// The width in image pixels of `text` drawn at `scale` (0 for no text).
pub fn text_width(text: &str, scale: u32) -> u32 {
    let n = text.chars().count() as u32;
    if n == 0 { 0 } else { (n * ADVANCE - 1) * scale }
}

/// Draws `text` with its top-left corner at (`x`, `y`), each font pixel a
/// `scale` × `scale` block of `color`; whatever falls outside the image is
/// clipped.
pub fn draw_text(image: &mut Image, x: i64, y: i64, text: &str, scale: u32, color: Vec3) {
    let s = scale.max(1) as i64;
    for (k, c) in text.chars().enumerate() {
        let gx = x + k as i64 * ADVANCE as i64 * s;
        for (row, bits) in glyph(c).iter().enumerate() {
            for col in 0..GLYPH_WIDTH as i64 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for dy in 0..s {
                    for dx in 0..s {
                        let px = gx + col * s + dx;
                        let py = y + row as i64 * s + dy;
                        if px >= 0 && py >= 0 && px < image.width as i64 && py < image.height as i64
                        {
                            image.set(px as u32, py as u32, color);
                        }
                    }
                }
            }
        }
    }
}
