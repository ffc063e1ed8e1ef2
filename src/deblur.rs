//! Motion blur removed along the rows. A camera panning at `v` pixels per frame with each row
//! exposed for `e` of the frame interval smears every row by a box `|v| e` pixels long, centred
//! on the row's read time (issue 61). [`deblur_rows`] undoes it row by row with a 1-D Wiener
//! deconvolution, `X = Y (1 + nsr) conj(H) / (|H|^2 + nsr)`, `H` the box's spectrum: the
//! frequencies the box nearly removed are restored only as far as the noise allows, and the
//! factor `1 + nsr` keeps the level of flat areas and slow gradients (where `H = 1`). (A
//! regulariser growing with frequency, as constrained least squares uses, leaves a long box's
//! first zeros, at low frequencies, unregularised: far worse on simulated pans.) Each row is mirrored
//! out past both ends before its transform, so the frame's edges do not ring, and the result
//! is clamped to the samples' range (a saturated highlight cannot ring into negative light).
//!
//! Real-input FFTs come from `realfft` (rustfft's real-to-complex wrapper); each thread plans
//! once per padded length and keeps the box spectra it has used, so a frame's rows allocate
//! nothing after the first.

use std::collections::HashMap;
use std::sync::Arc;

use rayon::prelude::*;
use realfft::num_complex::Complex32;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};

use crate::{Error, Result};

/// The Wiener filter's noise-to-signal ratio by default: how much of each frequency the box nearly removed is left unrestored. Chosen on simulated
/// clips of development faces (docs/video.md, motion blur).
pub const DEFAULT_NOISE_TO_SIGNAL: f64 = 0.02;

/// Blur shorter than this (pixels) is left as it is: a box under a pixel long is what any
/// resampling does.
pub const MIN_BLUR: f64 = 1.0;

/// The longest blur (pixels) undone: beyond it a row has lost too much to restore.
pub const MAX_BLUR: f64 = 256.0;

/// The shortest blur [`blur_length`] looks for (pixels): shorter boxes leave their first zero
/// in the top quarter of the spectrum, where noise and the picture's own fall-off hide it.
pub const MIN_FOUND_BLUR: f64 = 4.0;

/// How deep (natural log of power) the zeros of a box of the length found must lie below the
/// spectrum on both sides of them for [`blur_length`] to report it: on camera-like frames of
/// development faces (`eval shear --camera`, 300 photos, bands of about 96 rows), sharp bands
/// score a median -0.51 at their best length (4.3% at -0.9 or deeper: JPEG and texture), bands
/// blurred by a pan at `k` 0.2 and 0.4 (9 to 18 px at the eyes) a median -1.25 (84-88% at -0.9
/// or deeper).
const MIN_ZERO_DEPTH: f64 = 0.9;

/// The most zeros of a box's spectrum [`blur_length`] compares (from the lowest frequency):
/// higher ones lie where noise and JPEG's quantisation fill them.
const MAX_ZEROS: usize = 4;

/// How long boxes are told apart (pixels): rows whose lengths round to the same multiple of
/// this share one spectrum.
const LENGTH_STEP: f64 = 0.125;

/// A sample type the rows hold (8- or 16-bit).
pub trait Sample: Copy + Send + Sync {
    /// As a float.
    fn to_f32(self) -> f32;
    /// Rounded and clamped to `0..=max`.
    fn from_f32(v: f32, max: f32) -> Self;
}

impl Sample for u8 {
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
    fn from_f32(v: f32, max: f32) -> Self {
        // Clamped first, so adding a half and truncating rounds (and inlines, unlike `round`).
        (v.clamp(0.0, max.min(255.0)) + 0.5) as u8
    }
}

impl Sample for u16 {
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
    fn from_f32(v: f32, max: f32) -> Self {
        (v.clamp(0.0, max.min(65535.0)) + 0.5) as u16
    }
}

/// Removes a horizontal box blur from each row of an interleaved image: `data` holds rows of
/// `width` pixels of `channels` samples, `lengths[y]` is row `y`'s blur in pixels (under
/// [`MIN_BLUR`]: left alone), `noise_to_signal` the Wiener filter's ratio, `max` the largest
/// sample value. Rows are done in parallel.
///
/// # Errors
/// [`Error::InvalidArgument`] when `data` is not `lengths.len()` rows of `width * channels`
/// samples, a length is not finite, or `noise_to_signal` is not positive.
pub fn deblur_rows<T: Sample>(
    data: &mut [T],
    width: usize,
    channels: usize,
    lengths: &[f64],
    noise_to_signal: f64,
    max: f32,
) -> Result<()> {
    let stride = width * channels;
    if stride == 0 || data.len() != stride * lengths.len() {
        return Err(Error::InvalidArgument(format!(
            "deblur: {} samples are not {} rows of {width} pixels x {channels} channels",
            data.len(),
            lengths.len()
        )));
    }
    if let Some(l) = lengths.iter().find(|l| !l.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "deblur: blur length {l} is not finite"
        )));
    }
    if !(noise_to_signal > 0.0 && noise_to_signal.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "deblur: the noise-to-signal ratio must be positive (got {noise_to_signal})"
        )));
    }
    data.par_chunks_mut(stride)
        .zip(lengths.par_iter())
        .filter(|(_, l)| l.abs() >= MIN_BLUR)
        .for_each(|(row, &length)| {
            WIENER.with(|wiener| {
                let wiener = &mut wiener.borrow_mut();
                let length = length.abs().min(MAX_BLUR);
                let nsr = noise_to_signal as f32;
                if channels == 1 {
                    // A plane's row: plain iteration (no stride to step over).
                    wiener.load(row.iter().map(|s| s.to_f32()));
                    wiener.deconvolve(length, nsr);
                    for (s, &v) in row.iter_mut().zip(wiener.result()) {
                        *s = T::from_f32(v, max);
                    }
                    return;
                }
                for c in 0..channels {
                    wiener.load(row.iter().skip(c).step_by(channels).map(|s| s.to_f32()));
                    wiener.deconvolve(length, nsr);
                    for (s, &v) in row
                        .iter_mut()
                        .skip(c)
                        .step_by(channels)
                        .zip(wiener.result())
                    {
                        *s = T::from_f32(v, max);
                    }
                }
            });
        });
    Ok(())
}

thread_local! {
    /// Each thread's plans and spectra, kept from row to row and frame to frame.
    static WIENER: std::cell::RefCell<RowWiener> = std::cell::RefCell::new(RowWiener::default());
}

/// [`deblur_rows`] on every row of an image, `lengths[y]` for row `y` (8- and 16-bit layouts;
/// floating-point images are left as they are).
///
/// # Errors
/// As [`deblur_rows`].
pub fn deblur_image(img: &mut image::DynamicImage, lengths: &[f64], nsr: f64) -> Result<()> {
    use image::DynamicImage as D;
    if lengths.len() != img.height() as usize {
        return Err(Error::InvalidArgument(format!(
            "deblur: {} blur lengths for {} rows",
            lengths.len(),
            img.height()
        )));
    }
    let w = img.width() as usize;
    let c = usize::from(img.color().channel_count());
    let (u8_max, u16_max) = (255.0, 65535.0);
    match img {
        D::ImageLuma8(b) => deblur_rows(b, w, c, lengths, nsr, u8_max),
        D::ImageLumaA8(b) => deblur_rows(b, w, c, lengths, nsr, u8_max),
        D::ImageRgb8(b) => deblur_rows(b, w, c, lengths, nsr, u8_max),
        D::ImageRgba8(b) => deblur_rows(b, w, c, lengths, nsr, u8_max),
        D::ImageLuma16(b) => deblur_rows(b, w, c, lengths, nsr, u16_max),
        D::ImageLumaA16(b) => deblur_rows(b, w, c, lengths, nsr, u16_max),
        D::ImageRgb16(b) => deblur_rows(b, w, c, lengths, nsr, u16_max),
        D::ImageRgba16(b) => deblur_rows(b, w, c, lengths, nsr, u16_max),
        _ => Ok(()),
    }
}

/// A padded length's forward and inverse plans.
type Plans = (Arc<dyn RealToComplex<f32>>, Arc<dyn ComplexToReal<f32>>);

/// The length (pixels, at most `max`) of a horizontal box blur over `rows` of `gray`, from the
/// zeros it leaves in the rows' mean power spectrum: a box `L` long has zeros at the
/// frequencies `j / L`, so the length whose zeros lie deepest below the spectrum between them
/// (by 0.9 in natural log of power at least) is the blur. `None` when no length from
/// [`MIN_FOUND_BLUR`] to `max` leaves clear zeros (a sharp picture, little texture) or the rows
/// are too few.
pub fn blur_length(gray: &image::GrayImage, rows: std::ops::Range<u32>, max: f64) -> Option<f64> {
    RowSpectra::new(gray.width() as usize)?.blur_length(gray, rows, max)
}

/// A row width's FFT plan and Hann window, made once for every band [`blur_lengths`] reads.
struct RowSpectra {
    forward: Arc<dyn RealToComplex<f32>>,
    window: Vec<f32>,
}

impl RowSpectra {
    /// `None` for rows too short to show a blur's zeros.
    fn new(w: usize) -> Option<Self> {
        if w < 32 {
            return None;
        }
        let window = (0..w)
            .map(|i| {
                let t = std::f32::consts::TAU * i as f32 / (w - 1) as f32;
                0.5 - 0.5 * t.cos()
            })
            .collect();
        let forward = RealFftPlanner::<f32>::new().plan_fft_forward(fast_length(w));
        Some(Self { forward, window })
    }

    /// [`blur_length`] with this plan (`gray` must be as wide as the window).
    fn blur_length(
        &self,
        gray: &image::GrayImage,
        rows: std::ops::Range<u32>,
        max: f64,
    ) -> Option<f64> {
        let w = gray.width() as usize;
        let rows = rows.start..rows.end.min(gray.height());
        if w != self.window.len() || rows.len() < 8 || max.is_nan() || max < MIN_FOUND_BLUR {
            return None;
        }
        let (forward, window) = (&self.forward, &self.window);
        let n = forward.len();
        let mut input = vec![0.0f32; n];
        let mut spectrum = vec![Complex32::default(); n / 2 + 1];
        let mut scratch = vec![Complex32::default(); forward.get_scratch_len()];
        let mut power = vec![0.0f64; n / 2 + 1];
        for y in rows.clone() {
            let row = &gray.as_raw()[y as usize * w..(y as usize + 1) * w];
            let mean = row.iter().map(|&v| f32::from(v)).sum::<f32>() / w as f32;
            for ((o, &v), &h) in input.iter_mut().zip(row).zip(window) {
                *o = (f32::from(v) - mean) * h;
            }
            input[w..].fill(0.0);
            if forward
                .process_with_scratch(&mut input, &mut spectrum, &mut scratch)
                .is_err()
            {
                return None;
            }
            for (p, c) in power.iter_mut().zip(&spectrum) {
                *p += f64::from(c.norm_sqr());
            }
        }
        let log: Vec<f64> = power
            .iter()
            .map(|p| (p / rows.len() as f64 + 1e-9).ln())
            .collect();
        let at = |f: f64| {
            let i = f.floor() as usize;
            let t = f - i as f64;
            log[i] + (log[(i + 1).min(log.len() - 1)] - log[i]) * t
        };
        let top = (log.len() - 2) as f64;
        let depth = |length: f64| {
            let step = n as f64 / length;
            let (mut zeros, mut between) = (0.0, 0.0);
            let mut count = 0;
            for j in 1..=MAX_ZEROS {
                let zero = j as f64 * step;
                let (before, after) = (zero - 0.5 * step, zero + 0.5 * step);
                if after >= top {
                    break;
                }
                // The spectrum between the zeros on both sides: the picture's own fall-off with
                // frequency tilts the two alike, so it does not count as depth.
                zeros += at(zero);
                between += (at(before) + at(after)) / 2.0;
                count += 1;
            }
            (count >= 2).then(|| (zeros - between) / f64::from(count))
        };
        let steps = ((max.min(MAX_BLUR) - MIN_FOUND_BLUR) / 0.25).floor() as usize;
        (0..=steps)
            .map(|i| MIN_FOUND_BLUR + 0.25 * i as f64)
            .filter_map(|l| depth(l).map(|d| (l, d)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .filter(|&(_, d)| d <= -MIN_ZERO_DEPTH)
            .map(|(l, _)| l)
    }
}

/// Rows per band [`blur_lengths`] aims for: enough rows for a steady mean spectrum, few
/// enough that a blur changing down the frame (a pan changing speed during the readout) is
/// nearly constant within one.
const BAND_ROWS: u32 = 96;

/// The blur length of every row of `gray` (at most `max` pixels), for a blur that may change
/// down the frame: [`blur_length`] over bands of about 96 rows, then a straight
/// line through the bands' lengths (least squares, bands more than a third from their median
/// left out), or one length when one band gives it. `None` when fewer than half the bands
/// agree on a clear blur.
pub fn blur_lengths(gray: &image::GrayImage, max: f64) -> Option<Vec<f64>> {
    let h = gray.height();
    let bands = (h / BAND_ROWS).clamp(1, 8);
    let size = h / bands;
    let spectra = RowSpectra::new(gray.width() as usize)?;
    let found: Vec<(f64, f64)> = (0..bands)
        .filter_map(|b| {
            let rows = b * size..if b + 1 == bands { h } else { (b + 1) * size };
            let centre = f64::from(rows.start + rows.end - 1) / 2.0;
            spectra.blur_length(gray, rows, max).map(|l| (centre, l))
        })
        .collect();
    let mid = crate::stats::median(found.iter().map(|f| f.1).collect())?;
    let kept: Vec<(f64, f64)> = found
        .into_iter()
        .filter(|&(_, l)| (l - mid).abs() <= mid / 3.0)
        .collect();
    // A camera's motion blurs every row: a length only some bands show is texture (stripes,
    // JPEG's blocks), not motion.
    if 2 * kept.len() < bands as usize {
        return None;
    }
    let n = kept.len() as f64;
    let (my, ml) = (
        kept.iter().map(|k| k.0).sum::<f64>() / n,
        kept.iter().map(|k| k.1).sum::<f64>() / n,
    );
    let (sxy, sxx) = kept.iter().fold((0.0, 0.0), |(sxy, sxx), &(y, l)| {
        (sxy + (y - my) * (l - ml), sxx + (y - my) * (y - my))
    });
    let slope = if kept.len() >= 2 && sxx > 0.0 {
        sxy / sxx
    } else {
        0.0
    };
    Some(
        (0..h)
            .map(|y| (ml + slope * (f64::from(y) - my)).clamp(MIN_FOUND_BLUR, max))
            .collect(),
    )
}

/// One thread's plans, spectra and buffers.
#[derive(Default)]
struct RowWiener {
    planner: RealFftPlanner<f32>,
    /// Per padded length: its plans.
    plans: HashMap<usize, Plans>,
    /// Per (padded length, length in steps): the box's spectrum.
    spectra: HashMap<(usize, i64), Vec<Complex32>>,
    row: Vec<f32>,
    padded: Vec<f32>,
    spectrum: Vec<Complex32>,
    scratch: Vec<Complex32>,
    /// Where the row starts in `padded`.
    start: usize,
}

impl RowWiener {
    fn load(&mut self, row: impl Iterator<Item = f32>) {
        self.row.clear();
        self.row.extend(row);
    }

    /// The row's samples after [`Self::deconvolve`].
    fn result(&self) -> &[f32] {
        &self.padded[self.start..self.start + self.row.len()]
    }

    fn plans(&mut self, n: usize) -> Plans {
        let planner = &mut self.planner;
        self.plans
            .entry(n)
            .or_insert_with(|| (planner.plan_fft_forward(n), planner.plan_fft_inverse(n)))
            .clone()
    }

    /// Deconvolves the loaded row by a box `length` pixels long into `padded[start..]`.
    fn deconvolve(&mut self, length: f64, nsr: f32) {
        let w = self.row.len();
        if w == 0 {
            return;
        }
        // Mirrored out by twice the box on each side: what lies beyond the frame's edge blurs
        // in as the edge's own content, not as a jump to black.
        let pad = (2.0 * length).ceil() as usize + 8;
        let n = fast_length(w + 2 * pad);
        self.start = pad;
        self.padded.clear();
        let right = n - pad - w;
        if pad < w && right < w {
            // The mirrored ends copied as reversed slices (the edge sample not repeated).
            self.padded.extend(self.row[1..=pad].iter().rev());
            self.padded.extend_from_slice(&self.row);
            self.padded
                .extend(self.row[w - 1 - right..w - 1].iter().rev());
        } else {
            self.padded
                .extend((0..n).map(|i| self.row[mirror(i as i64 - pad as i64, w)]));
        }
        let (forward, inverse) = self.plans(n);
        let steps = (length / LENGTH_STEP).round() as i64;
        let h = self
            .spectra
            .entry((n, steps))
            .or_insert_with(|| box_spectrum(&*forward, n, steps as f64 * LENGTH_STEP));
        self.spectrum.resize(n / 2 + 1, Complex32::default());
        self.scratch
            .resize(forward.get_scratch_len(), Complex32::default());
        // The lengths match by construction; should a transform fail, the row stays as loaded.
        if forward
            .process_with_scratch(&mut self.padded, &mut self.spectrum, &mut self.scratch)
            .is_err()
        {
            self.keep_loaded_row();
            return;
        }
        let gain = (1.0 + nsr) / n as f32;
        for (y, h) in self.spectrum.iter_mut().zip(h.iter()) {
            *y = *y * h.conj() * (gain / (h.norm_sqr() + nsr));
        }
        // The DC and Nyquist bins of a real signal's spectrum are real; rounding may leave a
        // trace that the inverse refuses.
        self.spectrum[0].im = 0.0;
        if n.is_multiple_of(2) {
            self.spectrum[n / 2].im = 0.0;
        }
        self.scratch
            .resize(inverse.get_scratch_len(), Complex32::default());
        if inverse
            .process_with_scratch(&mut self.spectrum, &mut self.padded, &mut self.scratch)
            .is_err()
        {
            self.keep_loaded_row();
        }
    }

    /// Puts the loaded row back where [`Self::result`] reads it (a transform, which works in
    /// place, failed).
    fn keep_loaded_row(&mut self) {
        self.padded.clear();
        self.padded.resize(self.start, 0.0);
        self.padded.extend_from_slice(&self.row);
    }
}

/// The spectrum (`n / 2 + 1` bins) of a box `length` pixels long centred on 0, laid out
/// circularly over `n` samples: tap `j` weighs the part of `[j - 1/2, j + 1/2]` inside
/// `[-length/2, length/2]`, over `length`.
fn box_spectrum(forward: &dyn RealToComplex<f32>, n: usize, length: f64) -> Vec<Complex32> {
    let half = length / 2.0;
    let mut taps = vec![0.0f32; n];
    let reach = half.ceil() as i64;
    for j in -reach..=reach {
        let lo = (j as f64 - 0.5).max(-half);
        let hi = (j as f64 + 0.5).min(half);
        if hi > lo {
            taps[j.rem_euclid(n as i64) as usize] += ((hi - lo) / length) as f32;
        }
    }
    let mut spectrum = vec![Complex32::default(); n / 2 + 1];
    if forward.process(&mut taps, &mut spectrum).is_err() {
        // Lengths match by construction; an identity keeps the row as it is.
        spectrum.fill(Complex32::new(1.0, 0.0));
    }
    spectrum
}

/// Index `i` mirrored into `0..w` (the edge sample not repeated), for any `i`.
fn mirror(i: i64, w: usize) -> usize {
    if w == 1 {
        return 0;
    }
    let period = 2 * (w as i64 - 1);
    let m = i.rem_euclid(period);
    (if m < w as i64 { m } else { period - m }) as usize
}

/// The smallest length at least `n` whose only prime factors are 2, 3 and 5 (fast transforms).
fn fast_length(n: usize) -> usize {
    let mut best = n.next_power_of_two();
    let mut p2 = 1;
    while p2 < best {
        let mut p3 = p2;
        while p3 < best {
            let mut p5 = p3;
            while p5 < n {
                p5 *= 5;
            }
            best = best.min(p5);
            p3 *= 3;
        }
        p2 *= 2;
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row of texture (a deterministic mix of frequencies and steps).
    fn texture(w: usize) -> Vec<f32> {
        (0..w)
            .map(|x| {
                let x = x as f32;
                let steps = if (x / 23.0) as i32 % 2 == 0 {
                    60.0
                } else {
                    0.0
                };
                100.0 + steps + 40.0 * (x * 0.21).sin() + 25.0 * (x * 0.057).cos()
            })
            .collect()
    }

    /// `row` blurred by the box of [`box_spectrum`] (edges mirrored, as the camera's scene
    /// would continue).
    fn blurred(row: &[f32], length: f64) -> Vec<f32> {
        let half = length / 2.0;
        let reach = half.ceil() as i64;
        (0..row.len() as i64)
            .map(|x| {
                (-reach..=reach)
                    .map(|j| {
                        let lo = (j as f64 - 0.5).max(-half);
                        let hi = (j as f64 + 0.5).min(half);
                        let w = ((hi - lo).max(0.0) / length) as f32;
                        w * row[mirror(x + j, row.len())]
                    })
                    .sum()
            })
            .collect()
    }

    fn rms(a: &[f32], b: &[f32]) -> f32 {
        let sum: f32 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
        (sum / a.len() as f32).sqrt()
    }

    #[test]
    fn a_known_box_is_undone() {
        let w = 400;
        let sharp = texture(w);
        for length in [3.0, 7.5, 20.0, 41.25] {
            let blur = blurred(&sharp, length);
            let mut data: Vec<u16> = blur.iter().map(|&v| v.round() as u16).collect();
            deblur_rows(&mut data, w, 1, &[length], 0.01, 1023.0).unwrap();
            let restored: Vec<f32> = data.iter().map(|&v| f32::from(v)).collect();
            let before = rms(&blur, &sharp);
            let after = rms(&restored, &sharp);
            // Rounding to whole levels is the noise, amplified where the box's spectrum is
            // near zero: the same filter in numpy leaves 2.2-2.6 times less error.
            assert!(after < before / 2.0, "length {length}: {before} -> {after}");
        }
    }

    #[test]
    fn short_blur_and_flat_rows_are_left_alone() {
        let mut data: Vec<u8> = texture(64).iter().map(|&v| v as u8).collect();
        let before = data.clone();
        deblur_rows(&mut data, 64, 1, &[0.6], DEFAULT_NOISE_TO_SIGNAL, 255.0).unwrap();
        assert_eq!(data, before);
        let mut flat = vec![77u8; 3 * 100];
        deblur_rows(&mut flat, 100, 3, &[12.0], DEFAULT_NOISE_TO_SIGNAL, 255.0).unwrap();
        assert!(flat.iter().all(|&v| v == 77), "a flat row stays flat");
    }

    #[test]
    fn channels_are_deblurred_apart() {
        let w = 200;
        let sharp = texture(w);
        let blur = blurred(&sharp, 9.0);
        // Channel 0 the texture, channel 1 constant: the constant stays constant.
        let mut data: Vec<u8> = blur
            .iter()
            .flat_map(|&v| [(v * 0.9).round() as u8, 40u8])
            .collect();
        deblur_rows(&mut data, w, 2, &[9.0], 0.01, 255.0).unwrap();
        assert!(data.chunks(2).all(|p| p[1] == 40));
        let restored: Vec<f32> = data.chunks(2).map(|p| f32::from(p[0]) / 0.9).collect();
        let (before, after) = (rms(&blur, &sharp), rms(&restored, &sharp));
        assert!(after < before / 1.5, "{before} -> {after}");
    }

    #[test]
    fn bad_arguments_are_errors() {
        let mut data = vec![0u8; 10];
        assert!(deblur_rows(&mut data, 5, 1, &[3.0], 0.01, 255.0).is_err());
        assert!(deblur_rows(&mut data, 5, 1, &[3.0, f64::NAN], 0.01, 255.0).is_err());
        assert!(deblur_rows(&mut data, 5, 1, &[3.0, 3.0], 0.0, 255.0).is_err());
        assert!(deblur_rows(&mut data, 0, 1, &[], 0.01, 255.0).is_err());
        assert!(deblur_rows(&mut data, 5, 1, &[3.0, 3.0], 0.01, 255.0).is_ok());
    }

    /// A grey image of rows of broadband texture (a fixed pseudo-random pattern, as a busy scene
    /// has) blurred by `length`.
    fn blurred_image(length: f64) -> image::GrayImage {
        blurred_rows(120, |_| length)
    }

    /// [`blurred_image`] with `h` rows, row `y` blurred by `length(y)`.
    fn blurred_rows(h: u32, length: impl Fn(u32) -> f64) -> image::GrayImage {
        let w = 640u32;
        let mut img = image::GrayImage::new(w, h);
        let mut state = 0x2545_f491_u32;
        for y in 0..h {
            let row: Vec<f32> = (0..w)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    60.0 + (state % 128) as f32
                })
                .collect();
            let row = if length(y) > 0.0 {
                blurred(&row, length(y))
            } else {
                row
            };
            for (x, v) in row.iter().enumerate() {
                img.put_pixel(
                    x as u32,
                    y,
                    image::Luma([v.round().clamp(0.0, 255.0) as u8]),
                );
            }
        }
        img
    }

    #[test]
    fn the_blur_length_is_found_from_its_zeros() {
        for length in [6.0, 13.5, 27.0, 56.25] {
            let found = blur_length(&blurred_image(length), 0..120, 100.0).expect("found");
            assert!((found - length).abs() <= 0.5, "{length}: {found}");
        }
        // Sharp: nothing to find; too few rows or too short a search: no answer.
        assert_eq!(blur_length(&blurred_image(0.0), 0..120, 100.0), None);
        assert_eq!(blur_length(&blurred_image(27.0), 0..4, 100.0), None);
        assert_eq!(blur_length(&blurred_image(27.0), 0..120, 3.0), None);
    }

    /// A blur that grows down the frame (a pan speeding up during the readout) is followed row
    /// by row; a steady one is one length; a sharp picture has none.
    #[test]
    fn the_rows_blur_lengths_follow_a_changing_blur() {
        let growing = |y: u32| 16.0 + 8.0 * f64::from(y) / 383.0;
        let found = blur_lengths(&blurred_rows(384, growing), 100.0).expect("found");
        assert_eq!(found.len(), 384);
        for y in [0u32, 100, 200, 383] {
            let (f, t) = (found[y as usize], growing(y));
            assert!((f - t).abs() <= 1.0, "row {y}: {f} against {t}");
        }
        let steady = blur_lengths(&blurred_rows(384, |_| 20.0), 100.0).expect("found");
        assert!(
            steady.iter().all(|&l| (l - 20.0).abs() <= 0.5),
            "{steady:?}"
        );
        assert_eq!(blur_lengths(&blurred_rows(384, |_| 0.0), 100.0), None);
    }

    #[test]
    fn helpers() {
        assert_eq!(
            (0..8).map(|i| mirror(i - 3, 4)).collect::<Vec<_>>(),
            [3, 2, 1, 0, 1, 2, 3, 2]
        );
        for n in [1, 7, 97, 1000, 1921, 2100] {
            let f = fast_length(n);
            assert!(f >= n && f <= n.next_power_of_two());
            let mut m = f;
            for p in [2, 3, 5] {
                while m.is_multiple_of(p) {
                    m /= p;
                }
            }
            assert_eq!(m, 1, "{f}");
        }
        assert_eq!(fast_length(1921), 1944);
    }
}
