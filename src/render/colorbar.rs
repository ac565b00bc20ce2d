//! Labelled strips drawn into 8-bit RGB images without font files: a colour bar with round
//! tick values and a mark at the mean, and title lines, written with a 3×5-pixel font of
//! digits, capital letters and a little punctuation drawn at twice its size (so it draws the
//! same on a machine without fonts).
//!
//! The bar maps counts to `[0, 1]` by a [`Scale`]: linear from 0 to the largest count, log
//! (`ln(1 + c) / ln(1 + max)`, so that a few costly pixels do not flatten the rest), or linear
//! up to a percentile of the counts with everything above it drawn in the top colour.

/// Margin around the bar and text, pixels.
const MARGIN: usize = 6;
/// Height of the gradient, pixels.
const BAR: usize = 10;
/// Font scale (each font pixel is `SCALE × SCALE` image pixels).
const SCALE: usize = 2;
/// Height of a line of text, pixels.
const TEXT: usize = 5 * SCALE;

/// The glyph of `c`: 5 rows of 3 bits (bit 2 is the left column); lower case is drawn as
/// upper case, anything else as a blank.
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b111, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b010, 0b010, 0b010],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        'A' => [0b010, 0b101, 0b111, 0b101, 0b101],
        'B' => [0b110, 0b101, 0b110, 0b101, 0b110],
        'C' => [0b011, 0b100, 0b100, 0b100, 0b011],
        'D' => [0b110, 0b101, 0b101, 0b101, 0b110],
        'E' => [0b111, 0b100, 0b110, 0b100, 0b111],
        'F' => [0b111, 0b100, 0b110, 0b100, 0b100],
        'G' => [0b011, 0b100, 0b101, 0b101, 0b011],
        'H' => [0b101, 0b101, 0b111, 0b101, 0b101],
        'I' => [0b111, 0b010, 0b010, 0b010, 0b111],
        'J' => [0b001, 0b001, 0b001, 0b101, 0b010],
        'K' => [0b101, 0b101, 0b110, 0b101, 0b101],
        'L' => [0b100, 0b100, 0b100, 0b100, 0b111],
        'M' => [0b101, 0b111, 0b111, 0b101, 0b101],
        'N' => [0b110, 0b101, 0b101, 0b101, 0b101],
        'O' => [0b010, 0b101, 0b101, 0b101, 0b010],
        'P' => [0b110, 0b101, 0b110, 0b100, 0b100],
        'Q' => [0b010, 0b101, 0b101, 0b111, 0b011],
        'R' => [0b110, 0b101, 0b110, 0b101, 0b101],
        'S' => [0b011, 0b100, 0b010, 0b001, 0b110],
        'T' => [0b111, 0b010, 0b010, 0b010, 0b010],
        'U' => [0b101, 0b101, 0b101, 0b101, 0b111],
        'V' => [0b101, 0b101, 0b101, 0b101, 0b010],
        'W' => [0b101, 0b101, 0b111, 0b111, 0b101],
        'X' => [0b101, 0b101, 0b010, 0b101, 0b101],
        'Y' => [0b101, 0b101, 0b010, 0b010, 0b010],
        'Z' => [0b111, 0b001, 0b010, 0b100, 0b111],
        '-' => [0b000, 0b000, 0b111, 0b000, 0b000],
        '.' => [0b000, 0b000, 0b000, 0b000, 0b010],
        ',' => [0b000, 0b000, 0b000, 0b010, 0b100],
        ':' => [0b000, 0b010, 0b000, 0b010, 0b000],
        '=' => [0b000, 0b111, 0b000, 0b111, 0b000],
        '(' => [0b001, 0b010, 0b010, 0b010, 0b001],
        ')' => [0b100, 0b010, 0b010, 0b010, 0b100],
        '/' => [0b001, 0b001, 0b010, 0b100, 0b100],
        '%' => [0b101, 0b001, 0b010, 0b100, 0b101],
        '>' => [0b100, 0b010, 0b001, 0b010, 0b100],
        _ => [0; 5],
    }
}

/// How counts map to the bar's `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scale {
    /// `c / max`.
    Linear {
        /// The largest count.
        max: f64,
    },
    /// `ln(1 + c) / ln(1 + max)`.
    Log {
        /// The largest count.
        max: f64,
    },
    /// `min(c, top) / top`: linear up to `top` (a percentile of the counts), the counts above
    /// it in the top colour.
    Clipped {
        /// The count drawn in the top colour.
        top: f64,
        /// Which percentile `top` is, for the bar's label.
        percentile: f64,
    },
}

impl Scale {
    /// Where `v` falls on the bar, in `[0, 1]`.
    pub fn fraction(&self, v: f64) -> f64 {
        let f = match *self {
            Scale::Linear { max } if max > 0.0 => v / max,
            Scale::Log { max } if max > 0.0 => (1.0 + v.max(0.0)).ln() / (1.0 + max).ln(),
            Scale::Clipped { top, .. } if top > 0.0 => v / top,
            _ => 0.0,
        };
        f.clamp(0.0, 1.0)
    }

    /// The largest value the bar shows.
    fn end(&self) -> f64 {
        match *self {
            Scale::Linear { max } | Scale::Log { max } => max,
            Scale::Clipped { top, .. } => top,
        }
    }

    /// Round tick values within the bar: 0 and multiples of 1, 2 or 5 × 10^k on a linear
    /// bar (the smallest such step that gives at most five intervals), 0, 1, 2, 5, 10, 20,
    /// 50, ... on a log bar.
    pub fn ticks(&self) -> Vec<u64> {
        let end = self.end();
        if !(end >= 1.0) {
            return vec![0];
        }
        match self {
            Scale::Log { .. } => {
                let mut t = vec![0];
                let mut p = 1u64;
                'outer: loop {
                    for m in [1, 2, 5] {
                        let v = p * m;
                        if v as f64 > end {
                            break 'outer;
                        }
                        t.push(v);
                    }
                    p = p.saturating_mul(10);
                }
                t
            }
            _ => {
                let step = nice_step(end);
                (0..).map(|i| i * step).take_while(|&v| v as f64 <= end).collect()
            }
        }
    }

    /// The words under the bar's title: which scale.
    fn words(&self) -> String {
        match *self {
            Scale::Linear { .. } => String::new(),
            Scale::Log { .. } => " (LOG SCALE)".into(),
            Scale::Clipped { percentile, .. } => format!(" (LINEAR TO THE {}TH PERCENTILE)", percentile),
        }
    }
}

/// A whole tick step of 1, 2 or 5 × 10^k giving at most five intervals up to `end`.
fn nice_step(end: f64) -> u64 {
    let raw = (end / 5.0).max(1.0);
    let p = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p);
    step.round().max(1.0) as u64
}

/// Height of the colour bar strip in pixels: the bar, its tick labels, the mean's line.
pub fn height() -> usize {
    MARGIN + BAR + 3 + TEXT + 4 + TEXT + MARGIN
}

/// Height of a title strip in pixels.
pub fn title_height() -> usize {
    MARGIN + TEXT + MARGIN
}

/// Width in pixels of `text` as drawn.
pub fn text_width(text: &str) -> usize {
    (text.chars().count() * 4 * SCALE).saturating_sub(SCALE)
}

/// An RGB strip being drawn into, `width × height` pixels.
struct Strip<'a> {
    rgb: &'a mut [u8],
    width: usize,
    height: usize,
}

impl Strip<'_> {
    fn put(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.width && y < self.height {
            let i = (y * self.width + x) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// `text` in black with its top left corner at `(x, y)`; what falls outside is clipped.
    fn text(&mut self, x: usize, y: usize, text: &str) {
        for (i, ch) in text.chars().enumerate() {
            for (row, bits) in glyph(ch).iter().enumerate() {
                for col in 0..3 {
                    if bits >> (2 - col) & 1 == 1 {
                        for dy in 0..SCALE {
                            for dx in 0..SCALE {
                                self.put(x + (i * 4 + col) * SCALE + dx, y + row * SCALE + dy, [0, 0, 0]);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Draws the title strip (`width × title_height()` RGB pixels, white background expected):
/// `title` and the scale's words at the left.
pub fn draw_title(strip: &mut [u8], width: usize, title: &str, scale: &Scale) {
    debug_assert_eq!(strip.len(), width * title_height() * 3);
    let mut s = Strip { rgb: strip, width, height: title_height() };
    s.text(MARGIN, MARGIN, &format!("{title}{}", scale.words()));
}

/// A value as the bar's labels show it: whole numbers as they are, others with two decimals.
fn number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 { format!("{v:.0}") } else { format!("{v:.2}") }
}

/// Draws the bar for `scale` into `strip` (`width × height()` RGB pixels, white background
/// expected), colouring fraction `f ∈ [0, 1]` with `colour(f)`: the gradient, ticks and their
/// round values beneath (skipped where they would overlap), and, when `mean` is given, a
/// mark on the bar at the mean and its value on the line below.
pub fn draw(strip: &mut [u8], width: usize, scale: &Scale, mean: Option<f64>, colour: impl Fn(f64) -> [u8; 3]) {
    debug_assert_eq!(strip.len(), width * height() * 3);
    if width <= 2 * MARGIN + 1 {
        return;
    }
    let mut s = Strip { rgb: strip, width, height: height() };
    let (x0, x1) = (MARGIN, width - MARGIN);
    let span = (x1 - x0 - 1) as f64;
    for x in x0..x1 {
        let c = colour((x - x0) as f64 / span);
        for y in MARGIN..MARGIN + BAR {
            s.put(x, y, c);
        }
    }
    let black = [0, 0, 0];
    let text_y = MARGIN + BAR + 3;
    let mut last_end = 0usize;
    for (i, value) in scale.ticks().into_iter().enumerate() {
        let tick_x = x0 + (span * scale.fraction(value as f64)).round() as usize;
        for y in MARGIN + BAR..MARGIN + BAR + 2 {
            s.put(tick_x, y, black);
        }
        let text = value.to_string();
        let w = text_width(&text);
        // Centred on the tick, kept inside the strip, skipped where it would overlap.
        let left = tick_x.saturating_sub(w / 2).min(width.saturating_sub(w));
        if i > 0 && left < last_end + 2 * SCALE {
            continue;
        }
        last_end = left + w;
        s.text(left, text_y, &text);
    }
    let line_y = text_y + TEXT + 4;
    let mut words = String::new();
    if let Some(mean) = mean {
        // A black and white mark across the bar at the mean, visible on any colour.
        let mx = x0 + (span * scale.fraction(mean)).round() as usize;
        for y in MARGIN - 3..MARGIN + BAR + 3 {
            s.put(mx, y, black);
            for x in [mx.wrapping_sub(1), mx + 1] {
                if (MARGIN..MARGIN + BAR).contains(&y) {
                    s.put(x, y, [255, 255, 255]);
                }
            }
        }
        words = format!("MEAN {}", number((mean * 100.0).round() / 100.0));
    }
    if let Scale::Clipped { top, .. } = *scale {
        let sep = if words.is_empty() { "" } else { ", " };
        words = format!("{words}{sep}>= {} IN THE TOP COLOUR", number(top));
    } else if !words.is_empty() {
        words = format!("{words}, MAX {}", number(scale.end()));
    }
    s.text(MARGIN, line_y, &words);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_runs_left_to_right_and_labels_are_black() {
        let w = 200;
        let mut strip = vec![255u8; w * height() * 3];
        draw(&mut strip, w, &Scale::Linear { max: 1234.0 }, None, |f| [(f * 255.0) as u8, 0, 0]);
        let px = |x: usize, y: usize| &strip[(y * w + x) * 3..(y * w + x) * 3 + 3];
        assert_eq!(px(MARGIN, MARGIN), &[0, 0, 0]);
        assert_eq!(px(w - MARGIN - 1, MARGIN), &[255, 0, 0]);
        // Some label pixels are drawn in black below the bar.
        let label_rows = MARGIN + BAR + 3..MARGIN + BAR + 3 + TEXT;
        let black = label_rows.flat_map(|y| (0..w).map(move |x| (x, y))).filter(|&(x, y)| px(x, y) == [0, 0, 0]);
        assert!(black.count() > 20);
    }

    #[test]
    fn ticks_are_round() {
        assert_eq!(Scale::Linear { max: 1234.0 }.ticks(), [0, 500, 1000]);
        assert_eq!(Scale::Linear { max: 512.0 }.ticks(), [0, 200, 400]);
        assert_eq!(Scale::Linear { max: 37.0 }.ticks(), [0, 10, 20, 30]);
        assert_eq!(Scale::Linear { max: 3.0 }.ticks(), [0, 1, 2, 3]);
        assert_eq!(Scale::Log { max: 700.0 }.ticks(), [0, 1, 2, 5, 10, 20, 50, 100, 200, 500]);
        assert_eq!(Scale::Clipped { top: 48.0, percentile: 99.0 }.ticks(), [0, 10, 20, 30, 40]);
        assert_eq!(Scale::Linear { max: 0.0 }.ticks(), [0]);
    }

    #[test]
    fn scales_map_counts_into_the_bar() {
        assert_eq!(Scale::Linear { max: 10.0 }.fraction(5.0), 0.5);
        assert_eq!(Scale::Log { max: 99.0 }.fraction(9.0), 0.5);
        assert_eq!(Scale::Clipped { top: 10.0, percentile: 99.0 }.fraction(50.0), 1.0);
        assert_eq!(Scale::Linear { max: 0.0 }.fraction(3.0), 0.0);
    }

    #[test]
    fn the_mean_is_marked_and_written() {
        let w = 300;
        let mut strip = vec![255u8; w * height() * 3];
        draw(&mut strip, w, &Scale::Linear { max: 100.0 }, Some(50.0), |_| [0, 128, 0]);
        let px = |x: usize, y: usize| strip[(y * w + x) * 3..(y * w + x) * 3 + 3].to_vec();
        let mx = MARGIN + ((w - 2 * MARGIN - 1) as f64 * 0.5).round() as usize;
        assert_eq!(px(mx, MARGIN + 2), [0, 0, 0], "the mark crosses the bar");
        assert_eq!(px(mx + 1, MARGIN + 2), [255, 255, 255]);
        let line = MARGIN + BAR + 3 + TEXT + 4..height() - MARGIN;
        assert!(line.flat_map(|y| (0..w).map(move |x| (x, y))).any(|(x, y)| px(x, y) == [0, 0, 0]));
    }
}
