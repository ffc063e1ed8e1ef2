//! RGB ↔ YUV for mixing frame folders and y4m streams (a folder of PNGs in, y4m out, or the
//! other way).
//!
//! BT.601 coefficients, as FFmpeg assumes for y4m, which carries no matrix tag; limited range
//! (luma 16-235, chroma 16-240) unless the stream says `XCOLORRANGE=FULL`. Subsampled chroma is
//! the mean of each `hs x vs` block on the way in and is repeated over the block on the way out
//! (nearest neighbour: simple and exact for flat colour, a little blocky on sharp colour edges).
//! Written by hand: these are a dozen lines of textbook arithmetic, off the speed-critical path
//! (y4m to y4m never converts), and a conversion crate would add a dependency for no gain.

use image::{DynamicImage, GrayImage, Rgb, RgbImage};

use super::{Chroma, YuvFrame};

/// `(Y, Cb, Cr)` of an 8-bit RGB pixel, unrounded.
fn rgb_to_ycbcr(rgb: [u8; 3], full_range: bool) -> [f32; 3] {
    let [r, g, b] = rgb.map(f32::from);
    let y = 0.299 * r + 0.587 * g + 0.114 * b;
    let cb = (b - y) / 1.772;
    let cr = (r - y) / 1.402;
    if full_range {
        [y, 128.0 + cb, 128.0 + cr]
    } else {
        [
            16.0 + y * 219.0 / 255.0,
            128.0 + cb * 224.0 / 255.0,
            128.0 + cr * 224.0 / 255.0,
        ]
    }
}

/// The RGB pixel of `(Y, Cb, Cr)`.
fn ycbcr_to_rgb(y: u8, cb: u8, cr: u8, full_range: bool) -> [u8; 3] {
    let (mut y, mut cb, mut cr) = (f32::from(y), f32::from(cb) - 128.0, f32::from(cr) - 128.0);
    if !full_range {
        y = (y - 16.0) * 255.0 / 219.0;
        cb *= 255.0 / 224.0;
        cr *= 255.0 / 224.0;
    }
    let r = y + 1.402 * cr;
    let b = y + 1.772 * cb;
    let g = (y - 0.299 * r - 0.114 * b) / 0.587;
    [r, g, b].map(|v| v.round().clamp(0.0, 255.0) as u8)
}

fn to_u8(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// An image as a YUV frame of the given layout and range (alpha is dropped; grey images get
/// neutral chroma).
pub fn image_to_yuv(img: &DynamicImage, chroma: Chroma, full_range: bool) -> YuvFrame {
    let rgb = img.to_rgb8();
    let (w, h) = rgb.dimensions();
    let mut y = GrayImage::new(w, h);
    let (cw, ch) = chroma.plane_size(w, h);
    let (hs, vs) = chroma.subsampling();
    let mut sum_u = vec![0f32; (cw * ch) as usize];
    let mut sum_v = vec![0f32; (cw * ch) as usize];
    let mut count = vec![0f32; (cw * ch) as usize];
    for (x, yy, p) in rgb.enumerate_pixels() {
        let [l, u, v] = rgb_to_ycbcr(p.0, full_range);
        y.put_pixel(x, yy, image::Luma([to_u8(l)]));
        if chroma != Chroma::Mono {
            let i = ((yy / vs) * cw + x / hs) as usize;
            sum_u[i] += u;
            sum_v[i] += v;
            count[i] += 1.0;
        }
    }
    let plane = |sum: &[f32]| {
        GrayImage::from_fn(cw, ch, |x, yy| {
            let i = (yy * cw + x) as usize;
            image::Luma([to_u8(sum[i] / count[i].max(1.0))])
        })
    };
    YuvFrame {
        chroma,
        full_range,
        bit_depth: 8,
        u: plane(&sum_u),
        v: plane(&sum_v),
        y,
        params: None,
    }
}

/// A YUV frame as an image: RGB, or grey for mono.
pub fn yuv_to_image(frame: &YuvFrame) -> DynamicImage {
    if frame.chroma == Chroma::Mono {
        let y = if frame.full_range {
            frame.y.clone()
        } else {
            GrayImage::from_fn(frame.y.width(), frame.y.height(), |x, yy| {
                let v = f32::from(frame.y.get_pixel(x, yy)[0]);
                image::Luma([to_u8((v - 16.0) * 255.0 / 219.0)])
            })
        };
        return DynamicImage::ImageLuma8(y);
    }
    let (hs, vs) = frame.chroma.subsampling();
    let (w, h) = frame.y.dimensions();
    DynamicImage::ImageRgb8(RgbImage::from_fn(w, h, |x, yy| {
        let (cx, cy) = (
            (x / hs).min(frame.u.width().saturating_sub(1)),
            (yy / vs).min(frame.u.height().saturating_sub(1)),
        );
        Rgb(ycbcr_to_rgb(
            frame.y.get_pixel(x, yy)[0],
            frame.u.get_pixel(cx, cy)[0],
            frame.v.get_pixel(cx, cy)[0],
            frame.full_range,
        ))
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_colours_limited_range() {
        // BT.601 limited range: white (235, 128, 128), black (16, 128, 128), red (81, 90, 240).
        assert_eq!(
            rgb_to_ycbcr([255, 255, 255], false).map(|v| v.round()),
            [235.0, 128.0, 128.0]
        );
        assert_eq!(
            rgb_to_ycbcr([0, 0, 0], false).map(|v| v.round()),
            [16.0, 128.0, 128.0]
        );
        assert_eq!(
            rgb_to_ycbcr([255, 0, 0], false).map(|v| v.round()),
            [81.0, 90.0, 240.0]
        );
        // The 8-bit code values round: (81, 90, 240) decodes to within a level of pure red.
        let red = ycbcr_to_rgb(81, 90, 240, false);
        assert!(red[0] >= 254 && red[1] <= 1 && red[2] <= 1, "{red:?}");
    }

    #[test]
    fn round_trip_is_within_two_levels() {
        for full in [false, true] {
            for rgb in [[10u8, 200, 30], [255, 128, 0], [90, 90, 90], [3, 4, 250]] {
                let [y, u, v] = rgb_to_ycbcr(rgb, full).map(to_u8);
                let back = ycbcr_to_rgb(y, u, v, full);
                for c in 0..3 {
                    assert!(
                        (i32::from(back[c]) - i32::from(rgb[c])).abs() <= 2,
                        "{rgb:?} -> {back:?} (full {full})"
                    );
                }
            }
        }
    }

    #[test]
    fn flat_colour_survives_subsampling() {
        let img = DynamicImage::ImageRgb8(RgbImage::from_pixel(7, 5, Rgb([200, 40, 90])));
        for chroma in [Chroma::Yuv420, Chroma::Yuv422, Chroma::Yuv444] {
            let f = image_to_yuv(&img, chroma, false);
            assert_eq!(f.u.dimensions(), chroma.plane_size(7, 5));
            let back = yuv_to_image(&f).to_rgb8();
            for p in back.pixels() {
                for c in 0..3 {
                    assert!((i32::from(p[c]) - [200, 40, 90][c]).abs() <= 2);
                }
            }
        }
        let grey = image_to_yuv(&img, Chroma::Mono, true);
        assert!(grey.u.is_empty() && grey.v.is_empty());
        assert!(matches!(yuv_to_image(&grey), DynamicImage::ImageLuma8(_)));
    }
}
