//! Image metrics.

/// Intersection over union of two silhouettes thresholded at half of `max`
/// (`a`, `b`: same length, row-major). Two empty silhouettes have IoU 1.
pub fn silhouette_iou(a: &[u8], b: &[u8]) -> f64 {
    iou_where(a, b, |v| v >= 128)
}

/// Intersection over union of two images where `on(pixel)` marks foreground (same length,
/// row-major). Two empty silhouettes have IoU 1.
pub fn iou_where<T: Copy>(a: &[T], b: &[T], on: impl Fn(T) -> bool) -> f64 {
    assert_eq!(a.len(), b.len(), "silhouettes must have the same size");
    let (mut inter, mut union) = (0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (on(x), on(y));
        inter += (x && y) as usize;
        union += (x || y) as usize;
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// Shift an image by `rows` rows (positive: down), filling with zeros; used to compare with
/// renderers whose pixel centres differ by whole pixels (PyBullet's row 49 against our 50).
pub fn shift_rows(img: &[u8], width: usize, rows: isize) -> Vec<u8> {
    let height = img.len() / width;
    let mut out = vec![0u8; img.len()];
    for r in 0..height as isize {
        let src = r - rows;
        if (0..height as isize).contains(&src) {
            let (d, s) = (r as usize * width, src as usize * width);
            out[d..d + width].copy_from_slice(&img[s..s + width]);
        }
    }
    out
}
