//! Resampling a grey image at sub-pixel placement and any scale: the one filter the normalised
//! face ([`crate::locate::filters::NormalizedFace`]) and the landmark network's crop
//! ([`crate::locate::network::CropFrame`]) are both cut with, so that what the network was trained on
//! and what it sees at run time come from the same code.

use std::ops::Range;

use image::GrayImage;

/// Separable triangle-filter resampling of a window of `gray`: output pixel `(i, j)` is centred
/// on image point `(x0 + i * scale, y0 + j * scale)`; the filter radius is `max(scale, 1)`, which
/// is bilinear when enlarging and an area-weighted average when shrinking (no aliasing).
/// Hand-written because `image::imageops::resize` only takes integer crops and sizes, and the
/// face geometry needs sub-pixel placement.
pub(crate) fn resample(
    gray: &GrayImage,
    x0: f64,
    y0: f64,
    scale: f64,
    width: usize,
    height: usize,
) -> Vec<f32> {
    resample_rows(gray, x0, y0, scale, width, height, 0..height)
}

/// Only the output rows `rows` (clipped to `0..height`) of [`resample`]'s `width x height`
/// window, row-major: the same values as those rows of the whole window, bit for bit (each
/// output row is computed from its own filter taps alone), for callers that read a band of it.
pub(crate) fn resample_rows(
    gray: &GrayImage,
    x0: f64,
    y0: f64,
    scale: f64,
    width: usize,
    height: usize,
    rows: Range<usize>,
) -> Vec<f32> {
    let rows = rows.start.min(height)..rows.end.min(height);
    let (iw, ih) = (gray.width() as usize, gray.height() as usize);
    if scale == 1.0 && x0.fract() == 0.0 && y0.fract() == 0.0 && iw > 0 && ih > 0 {
        // Whole pixels at unit scale: the taps are 0, 1, 0, so the filter is a copy (with the
        // edge replicated), and copying gives exactly the same values several times faster (the
        // landmark network's crops of faces up to five times its size read the image so).
        return copy_clamped(gray, x0, y0, width, rows);
    }
    let xs = taps(x0, scale, 0..width, iw);
    // Only the band's rows: a row's taps depend on its own index from the window's top alone.
    let ys = taps(y0, scale, rows.clone(), ih);
    // Only the image columns some output column reads.
    let col_lo = xs.spans.iter().map(|t| t.first).min().unwrap_or(0);
    let col_hi = xs.spans.iter().map(|t| t.first + t.len).max().unwrap_or(0);
    let span = col_hi.saturating_sub(col_lo);
    let raw = gray.as_raw();
    // Room for the fixed-length horizontal reads past the last column read.
    let mut column_pass = vec![0f32; span + HORIZONTAL_TAPS_WIDE];
    let mut out = vec![0f32; width * rows.len()];
    let horizontal = Horizontal::new(&xs, col_lo);
    for (j, ty) in ys.spans.iter().enumerate() {
        let sums = &mut column_pass[..span];
        sums.fill(0.0);
        for (k, &w) in ys.weights(ty).iter().enumerate() {
            let row = &raw[(ty.first + k) * iw + col_lo..][..span];
            for (v, &p) in sums.iter_mut().zip(row) {
                *v += w * f32::from(p);
            }
        }
        horizontal.filter(
            &xs,
            col_lo,
            &column_pass,
            &mut out[j * width..(j + 1) * width],
        );
    }
    out
}

/// The horizontal pass, chosen once per window by its widest span of taps.
enum Horizontal {
    Narrow(PaddedTaps<HORIZONTAL_TAPS_NARROW>),
    Wide(PaddedTaps<HORIZONTAL_TAPS_WIDE>),
    /// Each output sample the sum over its own span (spans wider than the wide padding).
    General,
}

impl Horizontal {
    fn new(xs: &Taps, col_lo: usize) -> Self {
        match xs.spans.iter().map(|t| t.len).max().unwrap_or(0) {
            w if w <= HORIZONTAL_TAPS_NARROW => Self::Narrow(PaddedTaps::new(xs, col_lo)),
            w if w <= HORIZONTAL_TAPS_WIDE => Self::Wide(PaddedTaps::new(xs, col_lo)),
            _ => Self::General,
        }
    }

    /// One output row from its column pass (which holds [`HORIZONTAL_TAPS_WIDE`] values past
    /// the last column read), `xs` the taps this pass was chosen for.
    fn filter(&self, xs: &Taps, col_lo: usize, column_pass: &[f32], out_row: &mut [f32]) {
        match self {
            Self::Narrow(taps) => taps.filter(column_pass, out_row),
            Self::Wide(taps) => taps.filter(column_pass, out_row),
            Self::General => {
                for (o, tx) in out_row.iter_mut().zip(&xs.spans) {
                    let start = tx.first - col_lo;
                    *o = xs
                        .weights(tx)
                        .iter()
                        .zip(&column_pass[start..])
                        .map(|(w, v)| w * v)
                        .sum();
                }
            }
        }
    }
}

/// Horizontal spans of up to this many taps (enlarging, or shrinking by up to 1.5) are read by
/// [`PaddedTaps`] with this fixed length.
const HORIZONTAL_TAPS_NARROW: usize = 4;
/// The same for spans of up to 8 taps (shrinking by up to 3.5); wider ones take the general loop.
const HORIZONTAL_TAPS_WIDE: usize = 8;

/// The horizontal taps with every span padded with zero weights to `L`, so that each output
/// sample is a loop of known length with no per-sample slice (the variable-length loop took
/// most of the resampler's time). The same value comes out bit for bit: the products are summed
/// in the same order, and the padding adds `0 * v = +0` (every value is a weighted sum of pixels
/// with weights of at least +0, so finite and at least +0) to a sum that is itself at least +0,
/// which leaves it unchanged (`Iterator::sum` starts from -0, and `-0 + p = p`).
struct PaddedTaps<const L: usize> {
    starts: Vec<usize>,
    weights: Vec<[f32; L]>,
}

impl<const L: usize> PaddedTaps<L> {
    fn new(taps: &Taps, col_lo: usize) -> Self {
        let starts = taps.spans.iter().map(|t| t.first - col_lo).collect();
        let weights = taps
            .spans
            .iter()
            .map(|t| {
                let mut w = [0f32; L];
                w[..t.len].copy_from_slice(taps.weights(t));
                w
            })
            .collect();
        Self { starts, weights }
    }

    /// One output row from its column pass (which holds `L` values past the last start).
    fn filter(&self, column_pass: &[f32], out_row: &mut [f32]) {
        for ((o, &start), w) in out_row.iter_mut().zip(&self.starts).zip(&self.weights) {
            let v = &column_pass[start..start + L];
            let mut sum = w[0] * v[0];
            for t in 1..L {
                sum += w[t] * v[t];
            }
            *o = sum;
        }
    }
}

/// Rows `rows` of the window of `gray` whose top-left pixel is `(x0, y0)` (whole numbers), `width`
/// wide, as `f32`, with pixels outside the image replaced by the nearest edge pixel.
fn copy_clamped(gray: &GrayImage, x0: f64, y0: f64, width: usize, rows: Range<usize>) -> Vec<f32> {
    let (iw, ih) = (gray.width() as i64, gray.height() as i64);
    let clamp = |v: i64, len: i64| v.clamp(0, len - 1) as usize;
    let (x0, y0) = (x0 as i64, y0 as i64);
    let raw = gray.as_raw();
    let mut out = Vec::with_capacity(width * rows.len());
    let row_of = |j: usize| {
        // Saturating casts: windows far outside the image simply repeat its edge.
        let y = clamp(y0.saturating_add(j as i64), ih);
        &raw[y * iw as usize..(y + 1) * iw as usize]
    };
    if x0 >= 0 && x0.saturating_add(width as i64) <= iw {
        // Every column inside: each row is one run of the image's row (a loop the compiler
        // vectorises; the landmark network's crops of most faces read the image so).
        let columns = x0 as usize..x0 as usize + width;
        for j in rows {
            out.extend(row_of(j)[columns.clone()].iter().map(|&v| f32::from(v)));
        }
        return out;
    }
    let columns: Vec<usize> = (0..width as i64)
        .map(|i| clamp(x0.saturating_add(i), iw))
        .collect();
    for j in rows {
        let row = row_of(j);
        out.extend(columns.iter().map(|&x| f32::from(row[x])));
    }
    out
}

/// `gray` shrunk to `width x height` by averaging each output pixel's block of source pixels:
/// the same pixels as [`image::imageops::thumbnail`], bit for bit (the detector's pyramid and
/// training windows are made with that filter), several times faster. Hand-written because
/// `thumbnail` reads every pixel through `get_pixel` with four-channel sums, slow enough to
/// weigh on a whole frame's estimate; here each block's rows are summed once per output row with
/// a loop the compiler vectorises. Sizes that enlarge either way go to `thumbnail` itself.
pub(crate) fn shrink_by_area(gray: &GrayImage, width: u32, height: u32) -> GrayImage {
    let (w, h) = gray.dimensions();
    if w == 0 || h == 0 || width == 0 || height == 0 || width > w || height > h {
        return image::imageops::thumbnail(gray, width, height);
    }
    let (xs, ys) = (area_blocks(w, width), area_blocks(h, height));
    // `thumbnail` interpolates where a block would be empty (never when shrinking, but the
    // rounding of its `f32` boundaries is its own): leave such sizes to it.
    if xs.iter().chain(&ys).any(|b| b.is_empty()) {
        return image::imageops::thumbnail(gray, width, height);
    }
    let raw = gray.as_raw();
    let w = w as usize;
    let mut column_sums = vec![0u32; w];
    let mut out = Vec::with_capacity(width as usize * height as usize);
    for rows in &ys {
        column_sums.fill(0);
        for y in rows.clone() {
            add_row(&mut column_sums, &raw[y * w..(y + 1) * w]);
        }
        let block_rows = rows.len() as u64;
        out.extend(xs.iter().map(|cols| {
            let sum: u64 = column_sums[cols.clone()]
                .iter()
                .map(|&v| u64::from(v))
                .sum();
            let n = cols.len() as u64 * block_rows;
            ((sum + n / 2) / n) as u8
        }));
    }
    GrayImage::from_raw(width, height, out).unwrap_or_else(|| GrayImage::new(width, height))
}

/// `sums[i] += row[i]`, compiled also for AVX2 and chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn add_row(sums: &mut [u32], row: &[u8]) {
    for (s, &v) in sums.iter_mut().zip(row) {
        *s += u32::from(v);
    }
}

/// The source index range of each of `new_len` output samples over `len` source samples, as
/// [`image::imageops::thumbnail`] computes them (in `f32`, boundaries rounded up).
fn area_blocks(len: u32, new_len: u32) -> Vec<Range<usize>> {
    let ratio = len as f32 / new_len as f32;
    (0..new_len)
        .map(|o| {
            let lo_f = o as f32 * ratio;
            let hi_f = lo_f + ratio;
            let lo = (lo_f.ceil() as u32).min(len - 1);
            let hi = (hi_f.ceil() as u32).clamp(lo, len);
            lo as usize..hi as usize
        })
        .collect()
}

/// Bilinear sample of a `w x h` raster at `(x, y)`, coordinates clamped to the raster.
pub(crate) fn bilinear_clamped(src: &[f32], w: usize, h: usize, x: f64, y: f64) -> f32 {
    let x = x.clamp(0.0, (w - 1) as f64);
    let y = y.clamp(0.0, (h - 1) as f64);
    // Truncation is the floor here (both are at least 0), without a call to libm's `floor`.
    let (x0, y0) = (x as usize, y as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let top = src[y0 * w + x0] + (src[y0 * w + x1] - src[y0 * w + x0]) * fx;
    let bottom = src[y1 * w + x0] + (src[y1 * w + x1] - src[y1 * w + x0]) * fx;
    top + (bottom - top) * fy
}

/// Where one output sample's source samples and weights are: a run of consecutive source
/// indices from `first`, its `len` weights at `offset` in [`Taps::all`].
struct Span {
    first: usize,
    offset: usize,
    len: usize,
}

/// The taps of a run of output samples: one [`Span`] per sample, all weights in one buffer (one
/// allocation instead of one per output sample).
struct Taps {
    spans: Vec<Span>,
    all: Vec<f32>,
}

impl Taps {
    /// The weights of `span`.
    fn weights(&self, span: &Span) -> &[f32] {
        &self.all[span.offset..span.offset + span.len]
    }
}

/// Triangle-filter taps for the output samples `i in indices` at `origin + i * scale` over `len`
/// source samples; indices outside `[0, len)` are clamped to the edge (edge replication) and
/// their weights merged.
fn taps(origin: f64, scale: f64, indices: Range<usize>, len: usize) -> Taps {
    let radius = scale.max(1.0);
    let last = len.saturating_sub(1) as isize;
    let mut taps = Taps {
        spans: Vec::with_capacity(indices.len()),
        all: Vec::new(),
    };
    for i in indices {
        let c = origin + i as f64 * scale;
        let lo = (c - radius).ceil() as isize;
        let hi = (c + radius).floor() as isize;
        let (first, end) = (lo.clamp(0, last) as usize, hi.clamp(0, last) as usize);
        let offset = taps.all.len();
        taps.all.resize(offset + end - first + 1, 0.0);
        let weights = &mut taps.all[offset..];
        let mut total = 0.0;
        for s in lo..=hi {
            let w = (1.0 - ((s as f64 - c) / radius).abs()).max(0.0);
            weights[(s.clamp(0, last) as usize) - first] += w as f32;
            total += w;
        }
        if total > 0.0 {
            weights.iter_mut().for_each(|w| *w /= total as f32);
        }
        taps.spans.push(Span {
            first,
            offset,
            len: weights.len(),
        });
    }
    taps
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`shrink_by_area`] gives `thumbnail`'s pixels exactly, for shrinking by whole and
    /// fractional factors, to one pixel, to the same size, and (through `thumbnail`) enlarging.
    #[test]
    fn shrink_by_area_is_thumbnail_bit_for_bit() {
        let mut state = 0x9e37_79b9_u32;
        let noise = GrayImage::from_fn(397, 251, |_, _| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            image::Luma([(state >> 24) as u8])
        });
        for (w, h) in [
            (397, 251),
            (396, 250),
            (200, 125),
            (131, 97),
            (64, 36),
            (33, 250),
            (397, 7),
            (1, 1),
            (500, 300),
        ] {
            let ours = shrink_by_area(&noise, w, h);
            let theirs = image::imageops::thumbnail(&noise, w, h);
            assert_eq!(ours.dimensions(), (w, h));
            assert!(ours == theirs, "{w}x{h} differs from thumbnail");
        }
    }

    fn ramp(w: u32, h: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| image::Luma([((x * 2 + y) % 256) as u8]))
    }

    /// The resampler's filter path as it was before [`PaddedTaps`]: each output sample the sum
    /// of its own span's products.
    fn resample_span_by_span(
        gray: &GrayImage,
        (x0, y0, scale): (f64, f64, f64),
        width: usize,
        height: usize,
    ) -> Vec<f32> {
        let (iw, ih) = (gray.width() as usize, gray.height() as usize);
        let xs = taps(x0, scale, 0..width, iw);
        let ys = taps(y0, scale, 0..height, ih);
        let raw = gray.as_raw();
        let mut out = Vec::new();
        for ty in &ys.spans {
            let mut column_pass = vec![0f32; iw];
            for (k, &w) in ys.weights(ty).iter().enumerate() {
                for (c, v) in column_pass.iter_mut().enumerate() {
                    *v += w * f32::from(raw[(ty.first + k) * iw + c]);
                }
            }
            for tx in &xs.spans {
                out.push(
                    xs.weights(tx)
                        .iter()
                        .zip(&column_pass[tx.first..])
                        .map(|(w, v)| w * v)
                        .sum(),
                );
            }
        }
        out
    }

    #[test]
    fn fixed_length_taps_give_the_span_by_span_sums_bit_for_bit() {
        // Black areas too, where sums of zeros must stay +0.
        let img = GrayImage::from_fn(83, 61, |x, y| {
            let v = (x * 37 + y * 91 + x * y) % 251;
            image::Luma([if (x / 9 + y / 7) % 3 == 0 { 0 } else { v as u8 }])
        });
        // Enlarging (2-3 taps), shrinking into the 4-tap, the 8-tap and the general loop, at
        // whole and fractional origins, inside and hanging over the edges.
        let mut checked = 0;
        for scale in [0.37, 0.8, 1.0 + 1e-9, 1.3, 1.5, 2.2, 3.5, 4.7] {
            for (x0, y0) in [(0.0, 0.0), (2.3, 1.7), (-6.5, -3.25), (40.1, 30.9)] {
                let (width, height) = (37, 23);
                let fast = resample(&img, x0, y0, scale, width, height);
                let reference = resample_span_by_span(&img, (x0, y0, scale), width, height);
                assert_eq!(fast.len(), reference.len());
                let same = crate::testing::same_bits(&fast, &reference);
                assert!(same, "scale {scale}, origin ({x0}, {y0})");
                checked += 1;
            }
        }
        assert_eq!(checked, 32);
    }

    #[test]
    fn a_band_of_rows_is_those_rows_of_the_whole_window_bit_for_bit() {
        let img = GrayImage::from_fn(61, 47, |x, y| {
            image::Luma([((x * 37 + y * 91 + x * y) % 251) as u8])
        });
        let (width, height) = (40, 33);
        // The copy path (unit scale, whole pixels), enlarging, shrinking, and windows reaching
        // past the image.
        for (x0, y0, scale) in [
            (3.0, 4.0, 1.0),
            (-5.0, -7.0, 1.0),
            (2.3, 1.7, 0.6),
            (-4.2, 10.9, 1.9),
            (30.5, 25.25, 2.7),
        ] {
            let whole = resample(&img, x0, y0, scale, width, height);
            for rows in [0..height, 0..1, 5..17, 32..33, 20..50, 40..45, 7..7] {
                let band = resample_rows(&img, x0, y0, scale, width, height, rows.clone());
                let (lo, hi) = (rows.start.min(height), rows.end.min(height));
                let want = &whole[lo * width..hi * width];
                assert_eq!(band.len(), want.len(), "{x0} {y0} {scale} {rows:?}");
                assert!(
                    crate::testing::same_bits(&band, want),
                    "{x0} {y0} {scale} {rows:?}"
                );
            }
        }
    }

    #[test]
    fn resample_at_unit_scale_reproduces_pixels() {
        let img = ramp(40, 30);
        let out = resample(&img, 5.0, 7.0, 1.0, 10, 8);
        for j in 0..8 {
            for i in 0..10 {
                let expected = f32::from(img.get_pixel(5 + i as u32, 7 + j as u32)[0]);
                assert!((out[j * 10 + i] - expected).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn unit_scale_copy_equals_the_filter_including_the_edges() {
        // The copy path against the filter path, on a window that hangs over every edge: a
        // scale a hair above 1 takes the filter path and must give the same pixels within
        // the interpolation that hair causes.
        let img = ramp(13, 9);
        let copied = resample(&img, -3.0, -2.0, 1.0, 20, 14);
        let filtered = resample(&img, -3.0, -2.0, 1.0 + 1e-9, 20, 14);
        assert_eq!(copied.len(), filtered.len());
        for (a, b) in copied.iter().zip(&filtered) {
            assert!((a - b).abs() < 1e-3, "{a} vs {b}");
        }
        assert_eq!(copied[0], f32::from(img.get_pixel(0, 0)[0]));
        assert_eq!(copied[20 * 14 - 1], f32::from(img.get_pixel(12, 8)[0]));
        // A window whose columns all lie inside (the row-run path), hanging over the top and
        // bottom edges: each pixel is the image's, the rows outside repeat the edge rows.
        let inside = resample(&img, 2.0, -2.0, 1.0, 11, 14);
        for (j, row) in inside.chunks_exact(11).enumerate() {
            let y = (j as i64 - 2).clamp(0, 8) as u32;
            for (i, &v) in row.iter().enumerate() {
                assert_eq!(
                    v,
                    f32::from(img.get_pixel(2 + i as u32, y)[0]),
                    "({i}, {j})"
                );
            }
        }
    }

    #[test]
    fn resample_shrinking_averages_and_preserves_mean() {
        // A fine checkerboard shrunk 4x must come out flat grey, not aliased.
        let img = GrayImage::from_fn(64, 64, |x, y| {
            image::Luma([if (x + y) % 2 == 0 { 0 } else { 200 }])
        });
        let out = resample(&img, 8.0, 8.0, 4.0, 10, 10);
        for v in out {
            assert!((v - 100.0).abs() < 8.0, "{v}");
        }
    }
}
