//! Image preparation that must match OpenCV bit for bit for the detector to agree with it:
//! the bilinear pyramid resize (`INTER_LINEAR_EXACT`) and the RGB → grey conversion.
//!
//! OpenCV's cascade detector shrinks the image for every scale with
//! `resize(img, dst, size, 1/scale, 1/scale, INTER_LINEAR_EXACT)`. That mode is a two-pass
//! fixed-point filter: horizontal taps with 8 fractional bits (`ufixedpoint16`), then vertical
//! taps multiplying two such values (16 fractional bits) and rounding half up. Coordinates are
//! pixel-centre aligned, `src = (dst + 0.5) · (src_size / dst_size) − 0.5`, computed in IEEE double
//! (OpenCV uses soft-float for portability; plain `f64` gives the same correctly rounded results).
//! Outside the image the nearest edge pixel is repeated. Haar features are thresholded sums of
//! these pixels, so a one-level difference can flip a weak classifier; hence the exact copy.

use std::borrow::Cow;

use image::{DynamicImage, GrayImage};

/// Per-output-coordinate source offset and the two 8.8 fixed-point weights.
struct Taps {
    offset: Vec<usize>,
    coeff: Vec<[u32; 2]>,
    /// Outputs `< min` copy the first source sample.
    min: usize,
    /// Outputs `>= max` copy the last source sample.
    max: usize,
}

fn taps(src: usize, dst: usize) -> Taps {
    // OpenCV: inv_scale = dst / src (given the destination size), scale = 1 / inv_scale.
    let inv_scale = dst as f64 / src as f64;
    let scale = 1.0 / inv_scale;
    let mut t = Taps {
        offset: vec![0; dst],
        coeff: vec![[256, 0]; dst],
        min: 0,
        max: dst,
    };
    for d in 0..dst {
        let f = scale * (d as f64 + 0.5) - 0.5;
        let i = f.floor();
        if i >= 0.0 && src > 1 {
            let i = i as usize;
            if i < src - 1 {
                t.offset[d] = i;
                // cvRound of a softdouble: round half to even.
                let c1 = ((f - i as f64) * 256.0).round_ties_even() as u32;
                t.coeff[d] = [256 - c1, c1];
            } else {
                t.offset[d] = src - 1;
                t.max = t.max.min(d);
            }
        } else {
            t.min = t.min.max(d + 1);
        }
    }
    // `min` can exceed `max` only for degenerate one-pixel sources; keep the loops well formed.
    t.max = t.max.max(t.min.min(dst));
    t
}

/// One horizontally filtered source row, in 8.8 fixed point.
fn hline(src: &[u8], tx: &Taps, out: &mut [u32]) {
    let first = u32::from(src[0]) << 8;
    let last = u32::from(src[src.len() - 1]) << 8;
    let dst = out.len();
    for v in &mut out[..tx.min.min(dst)] {
        *v = first;
    }
    let mid = tx.min.min(dst)..tx.max.min(dst);
    for ((v, &o), &[c0, c1]) in out[mid.clone()]
        .iter_mut()
        .zip(&tx.offset[mid.clone()])
        .zip(&tx.coeff[mid])
    {
        // `taps` guarantees o + 1 < src.len() for outputs in min..max.
        *v = c0 * u32::from(src[o]) + c1 * u32::from(src[o + 1]);
    }
    for v in &mut out[tx.max.max(tx.min).min(dst)..] {
        *v = last;
    }
}

/// Resize an 8-bit grey image like OpenCV's `resize(.., INTER_LINEAR_EXACT)` with an explicit
/// destination size. Both sizes must be non-zero.
pub(crate) fn resize_linear_exact(
    src: &[u8],
    sw: usize,
    sh: usize,
    dw: usize,
    dh: usize,
) -> Vec<u8> {
    debug_assert!(sw > 0 && sh > 0 && dw > 0 && dh > 0 && src.len() == sw * sh);
    if (sw, sh) == (dw, dh) {
        // cv::resize copies when the size does not change.
        return src.to_vec();
    }
    let tx = taps(sw, dw);
    let ty = taps(sh, dh);
    let row = |y: usize| &src[y * sw..(y + 1) * sw];
    let mut out = vec![0u8; dw * dh];
    // Two cached horizontal passes: consecutive output rows mostly reuse source rows.
    let mut cache: [(usize, Vec<u32>); 2] = [(usize::MAX, vec![0; dw]), (usize::MAX, vec![0; dw])];
    let fetch = |y: usize, slot_hint: usize, cache: &mut [(usize, Vec<u32>); 2]| -> usize {
        if cache[0].0 == y {
            return 0;
        }
        if cache[1].0 == y {
            return 1;
        }
        let s = slot_hint;
        hline(row(y), &tx, &mut cache[s].1);
        cache[s].0 = y;
        s
    };
    for (dy, out_row) in out.chunks_exact_mut(dw).enumerate() {
        if dy < ty.min || dy >= ty.max {
            let y = if dy < ty.min { 0 } else { sh - 1 };
            let s = fetch(y, 0, &mut cache);
            for (o, &v) in out_row.iter_mut().zip(&cache[s].1) {
                *o = ((v + 128) >> 8) as u8;
            }
            continue;
        }
        let y0 = ty.offset[dy];
        let y1 = (y0 + 1).min(sh - 1);
        let s0 = fetch(y0, if cache[1].0 == y1 { 0 } else { 1 }, &mut cache);
        let s1 = fetch(y1, 1 - s0, &mut cache);
        let [c0, c1] = ty.coeff[dy];
        let (a, b) = (&cache[s0].1, &cache[s1].1);
        for ((o, &va), &vb) in out_row.iter_mut().zip(a).zip(b) {
            *o = ((va * c0 + vb * c1 + 32768) >> 16).min(255) as u8;
        }
    }
    out
}

/// Convert an image to 8-bit grey the way OpenCV's `cvtColor(.., COLOR_RGB2GRAY)` does:
/// `Y = (4899 R + 9617 G + 1868 B + 8192) >> 14` (the 0.299/0.587/0.114 weights in 14-bit fixed
/// point). Grey images are returned unchanged; alpha is ignored.
///
/// `image`'s own `to_luma8` uses different (Rec. 709) weights, which moves many pixels by a level
/// or more; use this function when detections should match OpenCV's.
pub fn to_gray_opencv(img: &DynamicImage) -> GrayImage {
    if let DynamicImage::ImageLuma8(g) = img {
        return g.clone();
    }
    if matches!(
        img,
        DynamicImage::ImageLuma16(_) | DynamicImage::ImageLumaA8(_) | DynamicImage::ImageLumaA16(_)
    ) {
        return img.to_luma8();
    }
    // Borrow an RGB image rather than copying it (36 MB for a 12-megapixel photo).
    let converted;
    let rgb = match img {
        DynamicImage::ImageRgb8(rgb) => rgb,
        other => {
            converted = other.to_rgb8();
            &converted
        }
    };
    let (w, h) = rgb.dimensions();
    let data: Vec<u8> = rgb
        .pixels()
        .map(|p| {
            let [r, g, b] = p.0;
            ((4899 * u32::from(r) + 9617 * u32::from(g) + 1868 * u32::from(b) + 8192) >> 14) as u8
        })
        .collect();
    GrayImage::from_raw(w, h, data).unwrap_or_else(|| GrayImage::new(w, h))
}

/// `gray` shrunk by area averaging to at most `width` columns (0: never), and the factor from
/// the shrunk image's pixels back to `gray`'s (1 when it is not shrunk): detection on a video
/// frame costs in proportion to its pixels.
pub(crate) fn shrunk_to_width(gray: &GrayImage, width: u32) -> (Cow<'_, GrayImage>, f64) {
    let (w, h) = gray.dimensions();
    if width == 0 || w <= width {
        return (Cow::Borrowed(gray), 1.0);
    }
    let scale = f64::from(w) / f64::from(width);
    let height = ((f64::from(h) * f64::from(width) / f64::from(w)).round() as u32).max(1);
    (
        Cow::Owned(crate::resample::shrink_by_area(gray, width, height)),
        scale,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Wider images are shrunk to the width, keeping the aspect (rounded), with the factor
    /// back; narrower ones and width 0 are borrowed as they are.
    #[test]
    fn shrunk_to_width_keeps_the_aspect_and_says_by_how_much() {
        let gray = GrayImage::new(1920, 1080);
        let (small, scale) = shrunk_to_width(&gray, 640);
        assert_eq!((small.dimensions(), scale), ((640, 360), 3.0));
        for width in [0, 1920, 4000] {
            let (same, scale) = shrunk_to_width(&gray, width);
            assert!(matches!(same, Cow::Borrowed(_)) && scale == 1.0, "{width}");
        }
    }

    #[test]
    fn identity_and_constant_images() {
        let img: Vec<u8> = (0..35).map(|v| (v * 7) as u8).collect();
        assert_eq!(resize_linear_exact(&img, 7, 5, 7, 5), img);
        let flat = vec![77u8; 40 * 30];
        assert!(resize_linear_exact(&flat, 40, 30, 23, 17)
            .iter()
            .all(|&v| v == 77));
    }

    #[test]
    fn matches_opencv_on_known_case() {
        // A 4x1 ramp halved: OpenCV's INTER_LINEAR_EXACT averages neighbour pairs
        // (src x = 2d + 0.5), rounding half up.
        let img = [0u8, 10, 20, 31];
        assert_eq!(resize_linear_exact(&img, 4, 1, 2, 1), vec![5, 26]);
        // Upscaling 2 -> 4: taps at -0.25 (clamped), 0.25, 0.75, 1.25 (clamped).
        let img = [0u8, 100];
        assert_eq!(resize_linear_exact(&img, 2, 1, 4, 1), vec![0, 25, 75, 100]);
    }

    #[test]
    fn gray_uses_opencv_weights() {
        let mut rgb = image::RgbImage::new(2, 1);
        rgb.put_pixel(0, 0, image::Rgb([255, 0, 0]));
        rgb.put_pixel(1, 0, image::Rgb([10, 200, 30]));
        let g = to_gray_opencv(&DynamicImage::ImageRgb8(rgb));
        // cv2.cvtColor(np.array([[[255,0,0],[10,200,30]]],np.uint8), cv2.COLOR_RGB2GRAY)
        assert_eq!(g.as_raw(), &vec![76, 124]);
    }
}
