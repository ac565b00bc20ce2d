//! A horizontal colour bar drawn into an 8-bit RGB strip, labelled with whole numbers.
//!
//! The strip is [`height`] pixels tall and as wide as the image above it: the gradient from
//! 0 (left) to `max` (right), then ticks and the values 0, max/4, max/2, 3max/4 and max
//! beneath, written with a 3×5-pixel digit font drawn at twice its size (no font files, so
//! it draws the same on a machine without fonts).

/// Margin around the bar, pixels.
const MARGIN: usize = 6;
/// Height of the gradient, pixels.
const BAR: usize = 10;
/// Digit scale (each font pixel is `SCALE × SCALE` image pixels).
const SCALE: usize = 2;
/// Digits 0–9, 5 rows of 3 bits each (bit 2 is the left column).
const DIGITS: [[u8; 5]; 10] = [
    [0b111, 0b101, 0b101, 0b101, 0b111],
    [0b010, 0b110, 0b010, 0b010, 0b111],
    [0b111, 0b001, 0b111, 0b100, 0b111],
    [0b111, 0b001, 0b111, 0b001, 0b111],
    [0b101, 0b101, 0b111, 0b001, 0b001],
    [0b111, 0b100, 0b111, 0b001, 0b111],
    [0b111, 0b100, 0b111, 0b101, 0b111],
    [0b111, 0b001, 0b010, 0b010, 0b010],
    [0b111, 0b101, 0b111, 0b101, 0b111],
    [0b111, 0b101, 0b111, 0b001, 0b111],
];

/// Height of the strip in pixels.
pub fn height() -> usize {
    MARGIN + BAR + 3 + 5 * SCALE + MARGIN
}

/// Width in pixels of `text` (digits) as drawn.
fn text_width(text: &str) -> usize {
    text.len() * 4 * SCALE - SCALE
}

/// Draws the bar for counts `0..=max` into `strip` (`width × height()` RGB pixels, white
/// background expected), colouring fraction `f ∈ [0, 1]` with `colour(f)`.
pub fn draw(strip: &mut [u8], width: usize, max: u32, colour: impl Fn(f64) -> [u8; 3]) {
    debug_assert_eq!(strip.len(), width * height() * 3);
    if width <= 2 * MARGIN + 1 {
        return;
    }
    let (x0, x1) = (MARGIN, width - MARGIN);
    let span = (x1 - x0 - 1) as f64;
    let mut put = |x: usize, y: usize, c: [u8; 3]| {
        if x < width && y < height() {
            strip[(y * width + x) * 3..(y * width + x) * 3 + 3].copy_from_slice(&c);
        }
    };
    for x in x0..x1 {
        let c = colour((x - x0) as f64 / span);
        for y in MARGIN..MARGIN + BAR {
            put(x, y, c);
        }
    }
    let black = [0, 0, 0];
    let text_y = MARGIN + BAR + 3;
    let mut last_end = 0usize;
    for q in 0..=4u64 {
        let value = (max as u64 * q / 4) as u32;
        let tick_x = x0 + (span * q as f64 / 4.0).round() as usize;
        for y in MARGIN + BAR..MARGIN + BAR + 2 {
            put(tick_x, y, black);
        }
        let text = value.to_string();
        let w = text_width(&text);
        // Centred on the tick, kept inside the strip, skipped where it would overlap.
        let left = tick_x.saturating_sub(w / 2).min(width.saturating_sub(w));
        if q > 0 && left < last_end + 2 * SCALE {
            continue;
        }
        last_end = left + w;
        for (i, ch) in text.bytes().enumerate() {
            let glyph = DIGITS[(ch - b'0') as usize];
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..3 {
                    if bits >> (2 - col) & 1 == 1 {
                        for dy in 0..SCALE {
                            for dx in 0..SCALE {
                                put(left + (i * 4 + col) * SCALE + dx, text_y + row * SCALE + dy, black);
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_runs_left_to_right_and_labels_are_black() {
        let w = 200;
        let mut strip = vec![255u8; w * height() * 3];
        draw(&mut strip, w, 1234, |f| [(f * 255.0) as u8, 0, 0]);
        let px = |x: usize, y: usize| &strip[(y * w + x) * 3..(y * w + x) * 3 + 3];
        assert_eq!(px(MARGIN, MARGIN), &[0, 0, 0]);
        assert_eq!(px(w - MARGIN - 1, MARGIN), &[255, 0, 0]);
        // Some label pixels are drawn in black below the bar.
        let label_rows = MARGIN + BAR + 3..height() - MARGIN;
        let black = label_rows.flat_map(|y| (0..w).map(move |x| (x, y))).filter(|&(x, y)| px(x, y) == [0, 0, 0]);
        assert!(black.count() > 20);
    }
}
