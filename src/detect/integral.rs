//! Integral images: plain sums, sums of squares and OpenCV's 45° ("tilted") sums.
//!
//! All three use OpenCV's `(w + 1) × (h + 1)` layout with a zero first row and column, so the
//! sum over any rectangle is four look-ups. Values are kept in wrapping 32-bit integers exactly
//! like OpenCV's `CV_32S` buffers: the totals of a large image overflow, but every window sum the
//! detector takes is a difference of small, exactly representable numbers, and two's-complement
//! wrap-around makes those differences exact anyway.

/// The integral planes of one (scaled) image, or of a horizontal band of it, stored back to back
/// in one buffer so that a feature can address any plane with a single precomputed offset.
///
/// The detector builds them band by band (see `viola_jones`): a window sum is a difference of
/// four entries, and the parts of the image above the band cancel out of that difference, so
/// integrals that start at the band's first row give every window inside the band exactly the
/// same sums as integrals of the whole image, for a fraction of the memory.
#[derive(Debug, Clone)]
pub(crate) struct Integrals {
    /// Row length of every plane: image width + 1.
    pub(crate) stride: usize,
    /// Rows of every plane: the most image rows it can hold + 1.
    pub(crate) rows: usize,
    /// `[sum | sqsum | tilted?]`, each `stride * rows` long.
    pub(crate) buf: Vec<i32>,
    tilted: bool,
}

impl Integrals {
    /// Plane index of the plain sum.
    pub(crate) const SUM: usize = 0;
    /// Plane index of the sum of squares (read back as `u32`).
    pub(crate) const SQSUM: usize = 1;
    /// Plane index of the tilted sum (present only when asked for).
    pub(crate) const TILTED: usize = 2;

    /// Build the integrals of a `width × height` 8-bit image stored row-major in `pixels`.
    #[cfg(test)]
    pub(crate) fn new(pixels: &[u8], width: usize, height: usize, tilted: bool) -> Self {
        let mut ii = Self::with_capacity(width, height, tilted);
        ii.compute(pixels, height);
        ii
    }

    /// Zeroed planes for images `width` wide and up to `max_height` rows high; the plane layout
    /// (and so every feature offset) depends only on these two numbers.
    pub(crate) fn with_capacity(width: usize, max_height: usize, tilted: bool) -> Self {
        let stride = width + 1;
        let rows = max_height + 1;
        let planes = if tilted { 3 } else { 2 };
        Integrals {
            stride,
            rows,
            buf: vec![0i32; stride * rows * planes],
            tilted,
        }
    }

    /// Fill the planes from the first `height` rows of `pixels` (row-major, `stride − 1` wide;
    /// `height` at most the capacity). Entries below row `height` keep stale values and must
    /// not be read.
    pub(crate) fn compute(&mut self, pixels: &[u8], height: usize) {
        let (stride, width) = (self.stride, self.stride - 1);
        let plane = stride * self.rows;
        debug_assert!(height < self.rows && pixels.len() >= width * height);
        {
            let (sum, rest) = self.buf.split_at_mut(plane);
            let sq = &mut rest[..plane];
            // Row 0 is all zeros; it is only ever written as zero, so the first call's zeroed
            // buffer keeps it so.
            for y in 0..height {
                let src = &pixels[y * width..(y + 1) * width];
                let (prev, cur) = sum.split_at_mut((y + 1) * stride);
                let prev = &prev[y * stride..];
                let cur = &mut cur[..stride];
                let (sq_prev, sq_cur) = sq.split_at_mut((y + 1) * stride);
                let sq_prev = &sq_prev[y * stride..];
                let sq_cur = &mut sq_cur[..stride];
                let mut acc = 0i32;
                let mut acc_sq = 0i32;
                for x in 0..width {
                    let v = i32::from(src[x]);
                    acc = acc.wrapping_add(v);
                    acc_sq = acc_sq.wrapping_add(v * v);
                    cur[x + 1] = prev[x + 1].wrapping_add(acc);
                    sq_cur[x + 1] = sq_prev[x + 1].wrapping_add(acc_sq);
                }
            }
        }
        if self.tilted {
            tilted_integral(pixels, width, height, &mut self.buf[2 * plane..]);
        }
    }

    /// Start of plane `p` in [`Integrals::buf`].
    #[cfg(test)]
    pub(crate) fn plane_offset(&self, p: usize) -> usize {
        Self::plane_offset_in(self.stride, self.rows, p)
    }

    /// Start of plane `p` in the buffer of integrals with this `stride` and `rows`.
    pub(crate) fn plane_offset_in(stride: usize, rows: usize, p: usize) -> usize {
        p * stride * rows
    }
}

/// OpenCV's tilted integral: `T(X, Y) = Σ_{y < Y, |x − X + 1| ≤ Y − 1 − y} I(x, y)`, the sum over
/// the upward-opening 45° cone whose apex is pixel `(X − 1, Y − 1)`.
///
/// Going from row `Y − 1` to `Y` the cone gains the apex pixel plus one pixel per earlier row on
/// each flank; those flank pixels lie on the diagonals `x − y = X − Y` and `x + y = X + Y − 2`, so
/// running sums along both diagonal directions give every entry in O(1):
/// `T(X, Y) = T(X, Y − 1) + I(X − 1, Y − 1) + D↘(X − Y) + D↙(X + Y − 2)`.
fn tilted_integral(pixels: &[u8], width: usize, height: usize, out: &mut [i32]) {
    let stride = width + 1;
    let w = width as isize;
    let h = height as isize;
    // diag_a[c + h] = Σ over rows done of I(x, y) with x − y = c   (c ∈ [−h, w])
    // diag_b[c + 1] = Σ over rows done of I(x, y) with x + y = c   (c ∈ [−1, w + h])
    let mut diag_a = vec![0i32; (w + h + 2) as usize];
    let mut diag_b = vec![0i32; (w + h + 3) as usize];
    for yy in 1..=h {
        let row = (yy - 1) as usize;
        let src = &pixels[row * width..(row + 1) * width];
        let (prev, cur) = out.split_at_mut(yy as usize * stride);
        let prev = &prev[(yy as usize - 1) * stride..];
        let cur = &mut cur[..stride];
        for xx in 0..=w {
            let apex = if xx >= 1 {
                i32::from(src[(xx - 1) as usize])
            } else {
                0
            };
            let a = diag_a[(xx - yy + h) as usize];
            let b = diag_b[(xx + yy - 2 + 1) as usize];
            cur[xx as usize] = prev[xx as usize]
                .wrapping_add(apex)
                .wrapping_add(a)
                .wrapping_add(b);
        }
        // Now fold row `row` into the diagonal running sums for the next output row.
        let y = row as isize;
        for (x, &v) in src.iter().enumerate() {
            let x = x as isize;
            let v = i32::from(v);
            let ia = (x - y + h) as usize;
            let ib = (x + y + 1) as usize;
            diag_a[ia] = diag_a[ia].wrapping_add(v);
            diag_b[ib] = diag_b[ib].wrapping_add(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pseudo_random(n: usize, seed: u32) -> Vec<u8> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (s >> 24) as u8
            })
            .collect()
    }

    #[test]
    fn integrals_match_brute_force() {
        for &(w, h) in &[(1usize, 1usize), (9, 7), (7, 9), (13, 4), (3, 17)] {
            let img = pseudo_random(w * h, (w * 31 + h) as u32);
            let ii = Integrals::new(&img, w, h, true);
            let px = |x: usize, y: usize| i64::from(img[y * w + x]);
            let (s0, q0, t0) = (
                ii.plane_offset(Integrals::SUM),
                ii.plane_offset(Integrals::SQSUM),
                ii.plane_offset(Integrals::TILTED),
            );
            for yy in 0..=h {
                for xx in 0..=w {
                    let mut s = 0i64;
                    let mut q = 0i64;
                    let mut t = 0i64;
                    for y in 0..h {
                        for x in 0..w {
                            if y < yy && x < xx {
                                s += px(x, y);
                                q += px(x, y) * px(x, y);
                            }
                            let r = yy as i64 - 1 - y as i64;
                            if (y < yy) && (x as i64 - xx as i64 + 1).abs() <= r {
                                t += px(x, y);
                            }
                        }
                    }
                    let i = yy * ii.stride + xx;
                    assert_eq!(i64::from(ii.buf[s0 + i]), s, "sum {w}x{h} at {xx},{yy}");
                    assert_eq!(i64::from(ii.buf[q0 + i]), q, "sqsum {w}x{h} at {xx},{yy}");
                    assert_eq!(i64::from(ii.buf[t0 + i]), t, "tilted {w}x{h} at {xx},{yy}");
                }
            }
        }
    }

    /// Integrals of a band that starts below the top give every rectangle inside the band the
    /// same sum as the integrals of the whole image (all three planes), also when the band's
    /// buffer is reused after a taller band.
    #[test]
    fn band_integrals_give_whole_image_window_sums() {
        let (w, h) = (23usize, 40usize);
        let img = pseudo_random(w * h, 7);
        let whole = Integrals::new(&img, w, h, true);
        let mut band = Integrals::with_capacity(w, 20, true);
        for (y0, bh) in [(0usize, 20usize), (13, 20), (25, 15), (31, 9)] {
            band.compute(&img[y0 * w..], bh);
            for p in [Integrals::SUM, Integrals::SQSUM, Integrals::TILTED] {
                let at = |ii: &Integrals, x: usize, y: usize| {
                    ii.buf[ii.plane_offset(p) + y * ii.stride + x]
                };
                // Upright rectangles (x0, y0)..(x1, y1) inside the band (sum and sqsum), and
                // 45° rectangles with apex (x, y), sides a and b (tilted plane).
                for (xa, ya, xb, yb) in [(0, 0, w, bh), (3, 2, 11, 9), (5, 1, 6, bh)] {
                    let s = |ii: &Integrals, off: usize| {
                        at(ii, xb, yb + off)
                            .wrapping_sub(at(ii, xa, yb + off))
                            .wrapping_sub(at(ii, xb, ya + off))
                            .wrapping_add(at(ii, xa, ya + off))
                    };
                    if p != Integrals::TILTED {
                        assert_eq!(s(&band, 0), s(&whole, y0), "plane {p} band at {y0}");
                    }
                }
                for (x, y, a, b) in [
                    (8usize, 0usize, 4usize, 3usize),
                    (12, 2, 5, 6),
                    (6, 1, 2, 2),
                ] {
                    if y + a + b > bh {
                        continue;
                    }
                    let t = |ii: &Integrals, off: usize| {
                        at(ii, x, y + off)
                            .wrapping_sub(at(ii, x - b, y + b + off))
                            .wrapping_sub(at(ii, x + a, y + a + off))
                            .wrapping_add(at(ii, x + a - b, y + a + b + off))
                    };
                    if p == Integrals::TILTED {
                        assert_eq!(t(&band, 0), t(&whole, y0), "tilted band at {y0}");
                    }
                }
            }
        }
    }

    #[test]
    fn window_sums_survive_wraparound() {
        // 300x300 of 255 has a squared total of 5.85e9, past i32: window differences still exact.
        let (w, h) = (300, 300);
        let img = vec![255u8; w * h];
        let ii = Integrals::new(&img, w, h, false);
        let q0 = ii.plane_offset(Integrals::SQSUM);
        let at = |x: usize, y: usize| ii.buf[q0 + y * ii.stride + x];
        let win = at(290, 290)
            .wrapping_sub(at(270, 290))
            .wrapping_sub(at(290, 270))
            .wrapping_add(at(270, 270)) as u32;
        assert_eq!(win, 20 * 20 * 255 * 255);
    }
}
