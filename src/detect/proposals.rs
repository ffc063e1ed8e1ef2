//! Face proposals from a small convolutional window classifier, run over an image pyramid.
//!
//! The Viola-Jones cascade decides its marginal faces by whether one or two of its windows
//! clear the last of its twenty stages, which one resampling more or less tips; under strong
//! shear a handful of faces it found upright get no box in any view. The landmark network,
//! started anywhere near such a face (a sixth of an eye distance off, a tenth off in size,
//! even without a shear hypothesis), walks to it and scores it as a face. So what those faces
//! lack is a *proposal*: this module supplies one from a classifier trained on sheared,
//! rolled and jittered windows of the development faces (`examples/proposal_crops.rs`,
//! `scripts/train_proposals.py`), so that it fires about equally on a face at any shear.
//!
//! The classifier sees a `window x window` square (32 px) spanning
//! [`CROP_EYE_DISTANCES`] eye distances, with the eyes' midpoint
//! [`EYES_ABOVE_CENTRE`] eye distances above its centre: the landmark crop's
//! geometry at a third of its size, so a proposal is directly a start for the network. Its
//! convolutions have no padding, so run over a whole pyramid level it gives, at every
//! `stride`-th pixel, exactly what it gives on that window alone. The file format is
//! documented on [`ProposalNet::from_bytes`].
//!
//! Written by hand for the reason the landmark network is (`landmarks::net`): six small
//! convolutions run as im2col and one `gemm` product each (the same product function), where
//! an inference framework would add most of the crate's build time for no gain.

use image::GrayImage;
use rayon::prelude::*;
use serde::Deserialize;

use crate::detect::boxes::{CROP_EYE_DISTANCES, EYES_ABOVE_CENTRE};
use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::modelfile::ModelFile;
use crate::nn::{conv_padded, Conv, Im2col, Tensor};

/// The file's magic bytes.
const MAGIC: &[u8; 8] = b"UNSHEARP";

/// The file format version this build reads.
const VERSION: u32 = 1;

/// How far this forward pass's logit on the check window may be from the trainer's: summation
/// order moves it by far less, a wrong layout or layer by far more.
const CHECK_TOLERANCE: f32 = 0.01;

/// The committed network (`models/proposals.bin`).
static EMBEDDED: &[u8] = include_bytes!("../../models/proposals.bin");

/// The largest classifier window a file may declare, pixels.
const MAX_WINDOW: usize = 256;

/// The largest window searched, as a multiple of the image's shorter side: a face filling the
/// image spans about 1.3 of it (the window is 3.3 eye distances across, a face box about 2.6).
const MAX_WINDOW_PER_SIDE: f64 = 1.5;

/// Photos larger than this (pixels) have their pyramid levels reduced by area averaging
/// (`image::imageops::thumbnail`) instead of the triangle filter, and scored one at a time: the
/// memory a level takes stays near the level's own size.
const LARGE_PHOTO_PIXELS: u64 = 4_000_000;

/// Outputs per side of the square tiles a pyramid level is scored in: bounds the im2col
/// buffers whatever the photo's size (about 9 MB for the largest layer; a whole row of a 1700 px
/// level 32 outputs high took 28 MB), at the cost of recomputing the windows' overlap between
/// tiles (a tile reads (TILE - 1) * stride + window = 284 pixels a side for 256 new ones).
const TILE: usize = 64;

#[derive(Debug, Deserialize)]
struct LayerSpec {
    #[serde(rename = "in")]
    inputs: usize,
    #[serde(rename = "out")]
    outputs: usize,
    kernel: usize,
    stride: usize,
    relu: bool,
}

#[derive(Debug, Deserialize)]
struct Header {
    window: usize,
    /// The trainer's logit on the check window (pixel `i` has grey level `(i * 31) % 255`).
    check_logit: f32,
    layers: Vec<LayerSpec>,
}

/// A place where the classifier sees a face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proposal {
    /// The eyes' midpoint the window expects, image pixels.
    pub eyes_midpoint: Point,
    /// The eye distance the window expects, image pixels.
    pub eye_distance: f64,
    /// The classifier's logit (higher: more face-like).
    pub logit: f32,
}

/// How [`ProposalNet::propose`] searches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProposalParams {
    /// Smallest eye distance searched, image pixels.
    pub min_eye_distance: f64,
    /// Ratio between consecutive pyramid levels' eye distances.
    pub scale_step: f64,
    /// Logit a window must reach.
    pub min_logit: f32,
    /// Most proposals returned (the strongest, after suppression of overlapping ones).
    pub max_proposals: usize,
}

impl Default for ProposalParams {
    fn default() -> Self {
        Self {
            min_eye_distance: 20.0,
            scale_step: 1.25,
            min_logit: 0.0,
            max_proposals: 64,
        }
    }
}

/// The proposal classifier, loaded and checked.
#[derive(Debug, Clone)]
pub struct ProposalNet {
    window: usize,
    /// Unpadded convolutions.
    layers: Vec<Conv>,
    /// Pixels between neighbouring windows' outputs (the product of the strides).
    stride: usize,
}

impl ProposalNet {
    /// The classifier built into the library.
    pub fn embedded() -> Result<Self> {
        Self::from_bytes(EMBEDDED)
    }

    /// Reads a classifier file: the magic `UNSHEARP`, a little-endian `u32` version (1), a `u32`
    /// header length, a JSON header (`window`; `check_logit`, the trainer's logit on a fixed
    /// synthetic window, pixel `i` at grey level `(i * 31) % 255`; and `layers`, each with `in`,
    /// `out`, `kernel`, `stride`, `relu`), then each layer's weights and biases as
    /// little-endian `f32`. The layers must chain (each one's inputs the previous one's outputs,
    /// one input channel first, one output last) and shrink the window to exactly one output,
    /// and this forward pass must give the trainer's logit on the check window.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let (header, mut file): (Header, _) =
            ModelFile::open(bytes, MAGIC, VERSION, "a face proposal network")?;
        if !(1..=MAX_WINDOW).contains(&header.window) {
            return Err(Error::ModelFile(format!(
                "proposal window {} is not 1 to {MAX_WINDOW} pixels",
                header.window
            )));
        }
        let mut layers: Vec<Conv> = Vec::with_capacity(header.layers.len());
        let mut side = header.window;
        let mut channels = 1;
        let mut stride = 1;
        for spec in &header.layers {
            let sane = spec.inputs == channels
                && (1..=1024).contains(&spec.outputs)
                && (1..=side).contains(&spec.kernel)
                && (1..=8).contains(&spec.stride);
            if !sane {
                return Err(Error::ModelFile(format!(
                    "proposal layer {} does not fit the chain",
                    layers.len()
                )));
            }
            side = (side - spec.kernel) / spec.stride + 1;
            channels = spec.outputs;
            stride *= spec.stride;
            let weights = spec.outputs * spec.inputs * spec.kernel * spec.kernel;
            let weight = file.take(weights)?;
            let bias = file.take(spec.outputs)?;
            layers.push(Conv {
                inputs: spec.inputs,
                outputs: spec.outputs,
                kernel: spec.kernel,
                stride: spec.stride,
                relu: spec.relu,
                weight,
                bias,
            });
        }
        if layers.is_empty() || side != 1 || channels != 1 {
            return Err(Error::ModelFile(
                "the proposal layers do not reduce the window to one score".into(),
            ));
        }
        file.finish()?;
        let net = Self {
            window: header.window,
            layers,
            stride,
        };
        let n = net.window as u32;
        let check = GrayImage::from_fn(n, n, |x, y| {
            image::Luma([((((y * n + x) as usize) * 31) % 255) as u8])
        });
        let logit = net.score_map(&check).0.first().copied().unwrap_or(f32::NAN);
        let deviation = (logit - header.check_logit).abs();
        if deviation.is_nan() || deviation > CHECK_TOLERANCE * header.check_logit.abs().max(1.0) {
            return Err(Error::ModelFile(format!(
                "the proposal network gives {logit} on the check window, its trainer {} (a \
                 damaged file, or weights in another layout)",
                header.check_logit
            )));
        }
        Ok(net)
    }

    /// Side of the window the classifier judges, pixels.
    pub fn window(&self) -> usize {
        self.window
    }

    /// Pixels between neighbouring windows in [`Self::score_map`].
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The classifier's logit for every window of `level` whose top-left corner is a multiple
    /// of [`Self::stride`], as `(scores, columns, rows)`, row-major; empty when `level` is
    /// smaller than the window.
    pub fn score_map(&self, level: &GrayImage) -> (Vec<f32>, usize, usize) {
        let (w, h) = (level.width() as usize, level.height() as usize);
        let n = self.window;
        if w < n || h < n {
            return (Vec::new(), 0, 0);
        }
        let (cols, rows) = ((w - n) / self.stride + 1, (h - n) / self.stride + 1);
        let mut scores = vec![0f32; cols * rows];
        let mut buffers = Buffers::default();
        let raw = level.as_raw();
        for first_row in (0..rows).step_by(TILE) {
            for first_col in (0..cols).step_by(TILE) {
                let (tile_rows, tile_cols) =
                    (TILE.min(rows - first_row), TILE.min(cols - first_col));
                let (top, left) = (first_row * self.stride, first_col * self.stride);
                let height = (tile_rows - 1) * self.stride + n;
                let width = (tile_cols - 1) * self.stride + n;
                let input = &mut buffers.input;
                input.resize(1, height, width);
                for (y, row) in input.data.chunks_exact_mut(width).enumerate() {
                    let start = (top + y) * w + left;
                    for (o, &v) in row.iter_mut().zip(&raw[start..start + width]) {
                        // The trainer's scaling: grey levels over 255, centred on 0.5, times 4.
                        *o = (f32::from(v) / 255.0 - 0.5) * 4.0;
                    }
                }
                let out = self.forward(&mut buffers);
                debug_assert_eq!((out.height, out.width), (tile_rows, tile_cols));
                for (y, values) in out.data.chunks_exact(tile_cols).take(tile_rows).enumerate() {
                    let at = (first_row + y) * cols + first_col;
                    scores[at..at + tile_cols].copy_from_slice(values);
                }
            }
        }
        (scores, cols, rows)
    }

    /// Runs the layers on `buffers.input`; returns the last activation.
    fn forward<'a>(&self, buffers: &'a mut Buffers) -> &'a Tensor {
        let Buffers {
            input,
            a,
            b,
            columns,
        } = buffers;
        // The activation is always left in `a`; swapping two tensors moves no values.
        for (i, layer) in self.layers.iter().enumerate() {
            if i == 0 {
                conv_padded(layer, input, a, columns, 0);
            } else {
                conv_padded(layer, a, b, columns, 0);
                std::mem::swap(a, b);
            }
        }
        a
    }

    /// The windows of one pyramid level, for eyes `eye_distance` image pixels apart, that reach
    /// `min_logit`. The level is padded by half a window of repeated edge pixels (as the
    /// trainer's renderer reads past a photo's edge), so that a face at the edge of the image,
    /// or filling it, is still seen whole by some window.
    fn level_proposals(
        &self,
        gray: &GrayImage,
        eye_distance: f64,
        min_logit: f32,
    ) -> Vec<Proposal> {
        let (w, h) = (f64::from(gray.width()), f64::from(gray.height()));
        let n = self.window as f64;
        let border = self.window / 2;
        // Window pixels per image pixel at this level: the window spans CROP_EYE_DISTANCES.
        let scale = n / (eye_distance * CROP_EYE_DISTANCES);
        let (lw, lh) = (
            ((w * scale).round() as u32).max(1),
            ((h * scale).round() as u32).max(1),
        );
        let large = u64::from(gray.width()) * u64::from(gray.height()) > LARGE_PHOTO_PIXELS;
        let level = if large && lw <= gray.width() && lh <= gray.height() {
            // `resize` keeps an intermediate of 16 bytes per pixel of the photo's width times the
            // level's height (83 MB for a level of a 12 MP photo, more than all the rest of
            // the search); `thumbnail` averages areas into the level directly.
            image::imageops::thumbnail(gray, lw, lh)
        } else {
            image::imageops::resize(gray, lw, lh, image::imageops::FilterType::Triangle)
        };
        let padded = with_edge_border(&level, border as u32);
        let (sx, sy) = (w / f64::from(lw), h / f64::from(lh));
        let (scores, cols, _) = self.score_map(&padded);
        scores
            .iter()
            .enumerate()
            .filter(|&(_, &logit)| logit >= min_logit)
            .map(|(i, &logit)| {
                let (col, row) = (i % cols, i / cols);
                // The window's centre in the level (pixel centres at integers), then up to the
                // eyes, then to the image.
                let cx = (col * self.stride) as f64 - border as f64 + (n - 1.0) / 2.0;
                let cy = (row * self.stride) as f64 - border as f64 + (n - 1.0) / 2.0;
                let eyes_y = cy - EYES_ABOVE_CENTRE * n / CROP_EYE_DISTANCES;
                Proposal {
                    eyes_midpoint: Point::new((cx + 0.5) * sx - 0.5, (eyes_y + 0.5) * sy - 0.5),
                    eye_distance,
                    logit,
                }
            })
            .collect()
    }

    /// Windows that the classifier takes for a face in `gray`, strongest first: the
    /// classifier run over a pyramid from `params.min_eye_distance` up to windows of
    /// 1.5 times the image's shorter side (each level a triangle-filtered reduction of the
    /// image, an area-averaged one for photos over 4 megapixels, padded by half a window of
    /// repeated edge pixels), windows at or above `params.min_logit`,
    /// a window dropped when a stronger one expects eyes within half an eye distance of its own
    /// at a size within `params.scale_step` squared, and at most `params.max_proposals` kept.
    pub fn propose(&self, gray: &GrayImage, params: &ProposalParams) -> Vec<Proposal> {
        let (w, h) = (f64::from(gray.width()), f64::from(gray.height()));
        let step = params.scale_step.max(1.01);
        let mut eye_distances = Vec::new();
        let mut eye_distance = params.min_eye_distance.max(1.0);
        while eye_distance * CROP_EYE_DISTANCES <= MAX_WINDOW_PER_SIDE * w.min(h) {
            eye_distances.push(eye_distance);
            eye_distance *= step;
        }
        // The levels are independent: in parallel (in the order of the levels either way), but
        // one at a time for a large photo, whose levels and tile buffers would otherwise be
        // alive at once on every core (as the pipeline searches a large photo's views).
        let level = |&d: &f64| self.level_proposals(gray, d, params.min_logit);
        let per_level: Vec<Vec<Proposal>> =
            if u64::from(gray.width()) * u64::from(gray.height()) > LARGE_PHOTO_PIXELS {
                eye_distances.iter().map(level).collect()
            } else {
                eye_distances.par_iter().map(level).collect()
            };
        let mut found: Vec<Proposal> = per_level.into_iter().flatten().collect();
        found.sort_by(|a, b| b.logit.total_cmp(&a.logit));
        let mut kept: Vec<Proposal> = Vec::new();
        for p in found {
            if kept.len() >= params.max_proposals {
                break;
            }
            let overlaps = kept.iter().any(|k| {
                let ratio = p.eye_distance / k.eye_distance;
                ratio < step * step
                    && ratio > 1.0 / (step * step)
                    && p.eyes_midpoint.distance(k.eyes_midpoint)
                        < 0.5 * p.eye_distance.max(k.eye_distance)
            });
            if !overlaps {
                kept.push(p);
            }
        }
        kept
    }
}

/// `image` with `border` pixels added on every side, each a copy of the nearest edge pixel.
fn with_edge_border(image: &GrayImage, border: u32) -> GrayImage {
    let (w, h) = image.dimensions();
    GrayImage::from_fn(w + 2 * border, h + 2 * border, |x, y| {
        let sx = x.saturating_sub(border).min(w - 1);
        let sy = y.saturating_sub(border).min(h - 1);
        *image.get_pixel(sx, sy)
    })
}

#[derive(Debug, Default)]
struct Buffers {
    input: Tensor,
    a: Tensor,
    b: Tensor,
    columns: Im2col,
}

#[cfg(test)]
mod tests {
    use super::*;

    type Spec = (usize, usize, usize, usize, bool);

    /// Weights and biases for `layers`, drawn from a fixed sequence.
    fn weights(layers: &[Spec]) -> Vec<(Vec<f32>, Vec<f32>)> {
        let mut state = 0x2545_f491_u32;
        let mut draw = |n: usize| -> Vec<f32> {
            (0..n)
                .map(|_| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (state >> 8) as f32 / (1u32 << 24) as f32 - 0.45
                })
                .collect()
        };
        layers
            .iter()
            .map(|&(i, o, k, _, _)| (draw(o * i * k * k), draw(o)))
            .collect()
    }

    /// The logit by the definition of the layers (direct sums, no im2col, no matrix product) on
    /// one `window x window` window of grey levels.
    fn reference_logit(window: usize, layers: &[Spec], pixels: &[u8]) -> f32 {
        let mut side = window;
        let mut values: Vec<f32> = pixels
            .iter()
            .map(|&v| (f32::from(v) / 255.0 - 0.5) * 4.0)
            .collect();
        for (&(inputs, outputs, k, s, relu), (w, b)) in layers.iter().zip(weights(layers)) {
            let out_side = (side - k) / s + 1;
            let mut next = vec![0f32; outputs * out_side * out_side];
            for o in 0..outputs {
                for oy in 0..out_side {
                    for ox in 0..out_side {
                        let mut sum = b[o];
                        for i in 0..inputs {
                            for ky in 0..k {
                                for kx in 0..k {
                                    let v = values[(i * side + oy * s + ky) * side + ox * s + kx];
                                    sum += w[((o * inputs + i) * k + ky) * k + kx] * v;
                                }
                            }
                        }
                        next[(o * out_side + oy) * out_side + ox] =
                            if relu { sum.max(0.0) } else { sum };
                    }
                }
            }
            values = next;
            side = out_side;
        }
        values[0]
    }

    /// The check window's grey levels.
    fn check_pixels(window: usize) -> Vec<u8> {
        (0..window * window)
            .map(|i| ((i * 31) % 255) as u8)
            .collect()
    }

    /// A classifier file from `(inputs, outputs, kernel, stride, relu)` layers with the
    /// weights of [`weights`] and the check logit of [`reference_logit`] (when the layers chain).
    fn file(window: usize, layers: &[Spec]) -> Vec<u8> {
        let chains = layers.windows(2).all(|w| w[0].1 == w[1].0);
        let check = if chains {
            reference_logit(window, layers, &check_pixels(window))
        } else {
            0.0
        };
        file_with_check(window, check, layers)
    }

    /// [`file`] with the check logit given.
    fn file_with_check(window: usize, check: f32, layers: &[Spec]) -> Vec<u8> {
        let specs: Vec<serde_json::Value> = layers
            .iter()
            .map(|&(i, o, k, s, r)| {
                serde_json::json!({"in": i, "out": o, "kernel": k, "stride": s, "relu": r})
            })
            .collect();
        let header = serde_json::json!({"window": window, "check_logit": check, "layers": specs})
            .to_string();
        let mut bytes = MAGIC.to_vec();
        bytes.extend(VERSION.to_le_bytes());
        bytes.extend((header.len() as u32).to_le_bytes());
        bytes.extend(header.as_bytes());
        for (w, b) in weights(layers) {
            bytes.extend(w.iter().chain(&b).flat_map(|v| v.to_le_bytes()));
        }
        bytes
    }

    /// Window 12: 12 -> 5 -> 3 -> 1 -> 1, stride 2.
    const SMALL: [Spec; 4] = [
        (1, 3, 4, 2, true),
        (3, 4, 3, 1, true),
        (4, 5, 3, 1, true),
        (5, 1, 1, 1, false),
    ];

    fn noise(width: u32, height: u32, seed: u32) -> GrayImage {
        let mut state = seed;
        GrayImage::from_fn(width, height, |_, _| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            image::Luma([(state >> 24) as u8])
        })
    }

    #[test]
    fn the_map_over_a_level_is_the_classifier_on_each_window() {
        let net = ProposalNet::from_bytes(&file(12, &SMALL)).expect("a valid file");
        assert_eq!((net.window(), net.stride()), (12, 2));
        // Three tiles high and two wide (the last ones short).
        let level = noise(
            2 * (TILE + 5) as u32 + 12,
            (2 * (2 * TILE + 5) + 12) as u32,
            7,
        );
        let (map, cols, rows) = net.score_map(&level);
        assert_eq!((cols, rows), (TILE + 6, 2 * TILE + 6));
        assert_eq!(map.len(), cols * rows);
        for row in 0..rows {
            for col in [0, 3, TILE - 1, TILE, cols - 1] {
                let window =
                    image::imageops::crop_imm(&level, 2 * col as u32, 2 * row as u32, 12, 12)
                        .to_image();
                let (one, c, r) = net.score_map(&window);
                assert_eq!((c, r), (1, 1));
                let at = map[row * cols + col];
                assert!(
                    (at - one[0]).abs() <= 1e-4 * one[0].abs().max(1.0),
                    "window ({col}, {row}): {at} in the map, {} alone",
                    one[0]
                );
            }
        }
        // Smaller than the window: no scores.
        assert_eq!(net.score_map(&noise(11, 40, 1)).0.len(), 0);
    }

    #[test]
    fn a_window_scores_what_the_convolutions_definition_gives() {
        let net = ProposalNet::from_bytes(&file(12, &SMALL)).expect("a valid file");
        for seed in 1..20 {
            let window = noise(12, 12, seed);
            let got = net.score_map(&window).0[0];
            let want = reference_logit(12, &SMALL, window.as_raw());
            assert!(
                (got - want).abs() <= 1e-4 * want.abs().max(1.0),
                "seed {seed}: {got} against {want}"
            );
        }
    }

    #[test]
    fn a_file_whose_weights_do_not_give_its_check_logit_is_refused() {
        let good = file(12, &SMALL);
        // The last layer's bias (the last four bytes) moved by 0.5.
        let mut moved = good.clone();
        let at = moved.len() - 4;
        let bias = f32::from_le_bytes([moved[at], moved[at + 1], moved[at + 2], moved[at + 3]]);
        moved[at..].copy_from_slice(&(bias + 0.5).to_le_bytes());
        assert!(ProposalNet::from_bytes(&moved).is_err());
    }

    #[test]
    fn files_that_do_not_chain_to_one_score_are_refused() {
        let good = file(12, &SMALL);
        assert!(ProposalNet::from_bytes(&good).is_ok());
        let mut bad_magic = good.clone();
        bad_magic[0] = b'X';
        assert!(ProposalNet::from_bytes(&bad_magic).is_err());
        assert!(ProposalNet::from_bytes(&good[..good.len() - 4]).is_err());
        let mut longer = good.clone();
        longer.extend([0; 4]);
        assert!(ProposalNet::from_bytes(&longer).is_err());
        let mut inputs = SMALL;
        inputs[1].0 = 2; // does not take the previous layer's 3 channels
        assert!(ProposalNet::from_bytes(&file(12, &inputs)).is_err());
        let mut wide = SMALL;
        wide[3].1 = 2; // two outputs
        assert!(ProposalNet::from_bytes(&file(12, &wide)).is_err());
        // A window too large to check (its check image alone would be gigabytes).
        let huge = file_with_check(100_000, 0.0, &[(1, 1, 1, 1, false)]);
        let message = ProposalNet::from_bytes(&huge)
            .expect_err("too large")
            .to_string();
        assert!(message.contains("pixels"), "{message}");
        // Window 14 leaves 2x2 outputs, not one.
        assert!(ProposalNet::from_bytes(&file(14, &SMALL)).is_err());
        let mut not_finite = good.clone();
        let at = not_finite.len() - 8;
        not_finite[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(ProposalNet::from_bytes(&not_finite).is_err());
    }

    #[test]
    fn the_built_in_classifier_proposes_the_fixture_face_at_any_shear() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/faces/subject01.normal.jpeg"
        );
        let gray = image::open(path).expect("fixture").into_luma8();
        // The fixture's eyes as the landmark network locates them.
        let landmarks = crate::locate::network::LandmarkNet::embedded().expect("built-in network");
        let start = landmarks.frame(Point::new(160.0, 100.0), 60.0, 0.0, 0.0);
        let mut ws = crate::locate::network::Workspace::default();
        let face =
            crate::locate::network::locate(&landmarks, &gray, start, &mut ws).expect("a face");
        let net = ProposalNet::embedded().expect("built-in proposal classifier");
        for k in [0.0, 0.4, -0.4] {
            let shear = crate::geometry::Shear::about_middle(k, gray.height());
            let (sheared, placement) = crate::warp::try_apply_shear(
                &image::DynamicImage::ImageLuma8(gray.clone()),
                shear,
                crate::warp::Interpolation::Linear,
                crate::warp::Canvas::Expand,
            )
            .expect("sheared");
            let moved = |p: Point| placement.from_frame(shear.apply(p));
            let eyes = moved(face.right_eye).midpoint(moved(face.left_eye));
            let distance = face.right_eye.distance(face.left_eye);
            let proposals = net.propose(&sheared.into_luma8(), &ProposalParams::default());
            // A window that starts the network on this face: its eyes within half an eye
            // distance, its size within the pyramid's step and the jitter trained on.
            let hit = proposals.iter().any(|p| {
                p.eyes_midpoint.distance(eyes) < 0.5 * distance
                    && (p.eye_distance / distance).ln().abs() < 1.5f64.ln()
            });
            assert!(hit, "k = {k}: no proposal at the face in {proposals:?}");
            // Strongest first, and no two overlapping.
            assert!(proposals.windows(2).all(|w| w[0].logit >= w[1].logit));
        }
        // A large photo (levels reduced by area averaging): the fixture enlarged 8 times, to
        // about 5 MP, with a proposal at its face (eyes scaled alike).
        let large = image::imageops::resize(
            &gray,
            8 * gray.width(),
            8 * gray.height(),
            image::imageops::FilterType::Triangle,
        );
        assert!(u64::from(large.width()) * u64::from(large.height()) > LARGE_PHOTO_PIXELS);
        let scaled = |p: Point| Point::new(8.0 * p.x + 3.5, 8.0 * p.y + 3.5);
        let eyes = scaled(face.right_eye).midpoint(scaled(face.left_eye));
        let distance = 8.0 * face.right_eye.distance(face.left_eye);
        let proposals = net.propose(&large, &ProposalParams::default());
        assert!(
            proposals
                .iter()
                .any(|p| p.eyes_midpoint.distance(eyes) < 0.5 * distance
                    && (p.eye_distance / distance).ln().abs() < 1.5f64.ln()),
            "no proposal at the enlarged face in {proposals:?}"
        );
    }
}
