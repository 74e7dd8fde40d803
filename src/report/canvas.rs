//! The one drawing surface of every figure: plotters' bitmap backend, with text drawn glyph by
//! glyph at each glyph's own outline bounds.
//!
//! plotters 0.3.7 (its `ab_glyph` font path) draws every glyph at its pen position and drops
//! the glyph's left side bearing, so narrow glyphs sit at the left of their cell: "26.6 dB"
//! reads "26. 6 dB" and "depth" reads "dep th". Layout (advances, kerning, the text box
//! plotters measures for placing labels) stays plotters'; only where each glyph's pixels land
//! changes. Text uses the one embedded font, DejaVu Sans Mono (assets/fonts, with its
//! licence), so figures render the same on any machine without system fonts.

use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, ScaleFont};
use plotters::prelude::*;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};

/// The embedded font's bytes (plotters registers the same bytes for its own layout).
pub(crate) const FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSansMono.ttf");

fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_BYTES).expect("embedded font is valid"))
}

/// A figure's pixels: an RGB buffer drawn through plotters.
pub struct Canvas<'a>(BitMapBackend<'a>);

impl<'a> Canvas<'a> {
    /// Draws into `buf` (RGB, `size.0 * size.1 * 3` bytes).
    pub fn with_buffer(buf: &'a mut [u8], size: (u32, u32)) -> Self {
        Self(BitMapBackend::with_buffer(buf, size))
    }
}

/// Every glyph of `text` at `size` px as (pixel x, pixel y, coverage) relative to the text
/// box's top left, with plotters' vertical convention (baseline half the size below the top),
/// and the box's width (the sum of advances and kerning, as plotters measures it).
fn glyph_pixels(text: &str, size: f32) -> (Vec<(i32, i32, f32)>, i32) {
    let font = font().as_scaled(size);
    let mut pixels = Vec::new();
    let mut pen = 0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(p) = prev {
            pen += font.kern(p, id);
        }
        prev = Some(id);
        let glyph = id.with_scale_and_position(size, ab_glyph::point(pen, 0.0));
        if let Some(outline) = font.outline_glyph(glyph) {
            let b = outline.px_bounds();
            let (x0, y0) = (b.min.x as i32, (size / 2.0 + b.min.y) as i32);
            outline.draw(|x, y, a| pixels.push((x0 + x as i32, y0 + y as i32, a)));
        }
        pen += font.h_advance(id);
    }
    (pixels, pen as i32)
}

impl DrawingBackend for Canvas<'_> {
    type ErrorType = <BitMapBackend<'static> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }
    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.ensure_prepared()
    }
    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.present()
    }
    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_pixel(point, color)
    }
    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_line(from, to, style)
    }
    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_rect(upper_left, bottom_right, style, fill)
    }
    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_path(path, style)
    }
    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_circle(center, radius, style, fill)
    }
    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.fill_polygon(vert, style)
    }
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.blit_bitmap(pos, size, src)
    }

    /// plotters' own placement (anchor, rotation, the text box it measures), glyphs at their
    /// outline bounds.
    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let size = style.size();
        let (pixels, width) = glyph_pixels(text, size as f32);
        let height = (size / 1.24) as i32;
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let transform = style.transform();
        let (w, h) = self.get_size();
        for (x, y, a) in pixels {
            let (x, y) = transform.transform(x + dx, y + dy);
            let (x, y) = (pos.0 + x, pos.1 + y);
            if x >= 0 && x < w as i32 && y >= 0 && y < h as i32 {
                self.0.draw_pixel((x, y), color.mix(a as f64))?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ink columns of `text`: the pixel columns any glyph covers.
    fn ink_columns(text: &str) -> Vec<bool> {
        let (pixels, width) = glyph_pixels(text, 20.0);
        let mut ink = vec![false; width.max(1) as usize + 20];
        for (x, _, a) in pixels {
            if a > 0.3 && x >= 0 {
                ink[x as usize] = true;
            }
        }
        ink
    }

    /// The runs of blank columns between the first and the last inked column.
    fn gaps(ink: &[bool]) -> Vec<usize> {
        let first = ink.iter().position(|&i| i).unwrap();
        let last = ink.iter().rposition(|&i| i).unwrap();
        ink[first..=last]
            .split(|&i| i)
            .map(<[bool]>::len)
            .filter(|&n| n > 0)
            .collect()
    }

    #[test]
    fn a_narrow_glyph_sits_in_the_middle_of_its_cell() {
        // In a monospace font "1.5" has the point centred between the digits: the gaps on
        // either side of it differ by at most a pixel. Without the side bearing the point
        // hugs the "1" and leaves a gap of most of a cell before the "5".
        let runs = gaps(&ink_columns("1.5"));
        assert_eq!(runs.len(), 2, "two gaps around the point: {runs:?}");
        assert!(runs[0].abs_diff(runs[1]) <= 1, "gaps {runs:?}");
        // And a word has no blank column wider than its letters' own spacing.
        assert!(
            gaps(&ink_columns("depth")).into_iter().max().unwrap_or(0) <= 3,
            "{:?}",
            ink_columns("depth")
        );
    }
}
