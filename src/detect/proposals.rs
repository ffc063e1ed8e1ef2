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
//! The same code runs the single-pass face detector (`models/detector.bin`,
//! [`ProposalNet::embedded_detector`], `examples/detector_crops.rs`,
//! `scripts/train_detector.py`): a cheaper network of output stride 8 whose windows are run
//! over a coarser pyramid, and which makes up for the coarse grid by regressing, besides the
//! logit, where the eyes' midpoint is in the window, how large the face is, and its shear and
//! roll (a version-2 file names its output channels). [`ProposalNet::propose`] moves each window
//! by what it regresses.
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

/// The file format versions this build reads: 1 (one output, the logit) and 2 (the output
/// channels named in the header).
const VERSIONS: [u32; 2] = [1, 2];

/// The output channels a version-2 file may name, the logit first: the eyes' midpoint's offset
/// from the window's expected one (`dx`, `dy`, window eye distances), the log of the face's
/// eye distance over the window's (`log_scale`), the face's shear `k` and roll (radians).
pub(crate) const OUTPUT_NAMES: [&str; 6] = ["logit", "dx", "dy", "log_scale", "k", "roll"];

/// How far this forward pass's logit on the check window may be from the trainer's: summation
/// order moves it by far less, a wrong layout or layer by far more.
const CHECK_TOLERANCE: f32 = 0.01;

/// The committed network (`models/proposals.bin`).
static EMBEDDED: &[u8] = include_bytes!("../../models/proposals.bin");

/// The committed single-pass detector (`models/detector.bin`).
static EMBEDDED_DETECTOR: &[u8] = include_bytes!("../../models/detector.bin");

/// The most a regression may move a window's eyes, window eye distances, and its log scale:
/// far beyond what the detector is trained on (0.45 and 0.19), so only a runaway value is cut.
const MAX_OFFSET: f64 = 2.0;
const MAX_LOG_SCALE: f64 = 1.0;
/// The largest shear and roll (radians) a proposal reports.
const MAX_SHEAR: f64 = 1.5;
const MAX_ROLL: f64 = std::f64::consts::PI;

/// The pyramid step of a file that does not give one (version 1).
const DEFAULT_SCALE_STEP: f64 = 1.25;

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
    /// Version 2: the trainer's every output on the check window.
    #[serde(default)]
    check_outputs: Option<Vec<f32>>,
    /// Version 2: the output channels' names ([`OUTPUT_NAMES`]), the logit first.
    #[serde(default)]
    outputs: Option<Vec<String>>,
    /// The pyramid step the network is meant to be run with.
    #[serde(default)]
    scale_step: Option<f64>,
    /// The logit threshold the network is meant to be run with.
    #[serde(default)]
    min_logit: Option<f32>,
    layers: Vec<LayerSpec>,
}

/// Where each regression is among a network's outputs (`None`: not given).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Channels {
    dx: Option<usize>,
    dy: Option<usize>,
    log_scale: Option<usize>,
    k: Option<usize>,
    roll: Option<usize>,
}

impl Channels {
    fn from_names(names: &[String]) -> Self {
        let at = |name: &str| names.iter().position(|n| n == name);
        Self {
            dx: at("dx"),
            dy: at("dy"),
            log_scale: at("log_scale"),
            k: at("k"),
            roll: at("roll"),
        }
    }
}

/// Output `channel` of one window's `outputs`, 0 when the network has no such output or it is
/// not finite, clamped to `limit` either way.
fn regressed(outputs: &[f32], channel: Option<usize>, limit: f64) -> f64 {
    let v = channel.map_or(0.0, |c| f64::from(outputs[c]));
    if v.is_finite() {
        v.clamp(-limit, limit)
    } else {
        0.0
    }
}

/// A place where the classifier sees a face.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Proposal {
    /// The eyes' midpoint the window expects, image pixels (moved by the network's regressed
    /// offset when it gives one).
    pub eyes_midpoint: Point,
    /// The eye distance the window expects, image pixels (scaled by the network's regressed
    /// size when it gives one): the upright face's, as the landmark network's frame takes it.
    pub eye_distance: f64,
    /// The classifier's logit (higher: more face-like).
    pub logit: f32,
    /// The face's shear as the network reads it (the `k` that
    /// `locate::network::frame_around_eyes` removes); 0 when the network gives none.
    pub k: f64,
    /// The face's roll as the network reads it, radians (positive: clockwise on screen, as the
    /// crop frame's); 0 when the network gives none.
    pub roll: f64,
}

/// How [`ProposalNet::propose`] searches. `Default` is the proposal classifier's;
/// [`ProposalNet::default_params`] gives each network's own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProposalParams {
    /// Smallest eye distance searched, image pixels: the first pyramid level's windows', or,
    /// for a network that regresses the face's size, the smallest face's (the first level's
    /// windows are then `scale_step.sqrt()` larger: a level finds the faces from its windows'
    /// size divided by the root of the step to its size times it).
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

/// The proposal classifier (or the single-pass detector), loaded and checked.
#[derive(Debug, Clone)]
pub struct ProposalNet {
    window: usize,
    /// Unpadded convolutions.
    layers: Vec<Conv>,
    /// Pixels between neighbouring windows' outputs (the product of the strides).
    stride: usize,
    /// The output channels' names, the logit first.
    outputs: Vec<String>,
    channels: Channels,
    /// The search the file asks for.
    defaults: ProposalParams,
}

impl ProposalNet {
    /// The proposal classifier built into the library (`models/proposals.bin`).
    pub fn embedded() -> Result<Self> {
        Self::from_bytes(EMBEDDED)
    }

    /// The single-pass face detector built into the library (`models/detector.bin`): output
    /// stride 8, and the face's offset, size, shear and roll regressed besides the logit. Run
    /// it with [`Self::default_params`] (its pyramid step and threshold).
    pub fn embedded_detector() -> Result<Self> {
        Self::from_bytes(EMBEDDED_DETECTOR)
    }

    /// The search this network was trained for: [`ProposalParams::default`] with the file's
    /// pyramid step and logit threshold when it gives them.
    pub fn default_params(&self) -> ProposalParams {
        self.defaults
    }

    /// The output channels' names ([`OUTPUT_NAMES`]), the logit first (`["logit"]` for a
    /// version-1 file).
    #[cfg(test)]
    pub(crate) fn outputs(&self) -> &[String] {
        &self.outputs
    }

    /// Whether the network regresses the face's size (and so places its proposals itself
    /// between pyramid levels).
    pub(crate) fn regresses_size(&self) -> bool {
        self.channels.log_scale.is_some()
    }

    /// Reads a classifier file: the magic `UNSHEARP`, a little-endian `u32` version (1 or 2), a
    /// `u32` header length, a JSON header (`window`; `check_logit`, the trainer's logit on a
    /// fixed synthetic window, pixel `i` at grey level `(i * 31) % 255`; and `layers`, each with
    /// `in`, `out`, `kernel`, `stride`, `relu`), then each layer's weights and biases as
    /// little-endian `f32`. The layers must chain (each one's inputs the previous one's outputs,
    /// one input channel first) and shrink the window to exactly one output position, and this
    /// forward pass must give the trainer's logit on the check window.
    ///
    /// Version 1 has one output, the logit. Version 2 adds `outputs`, the output channels'
    /// names (of `OUTPUT_NAMES`, each at most once, `"logit"` first; the last layer has one
    /// output per name), and `check_outputs`, the trainer's every output on the check window
    /// (each compared, as the logit); optionally `scale_step` and `min_logit`, the search the
    /// network is meant for ([`Self::default_params`]). The output stride is the product of
    /// the layers' strides.
    pub(crate) fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let (header, version, mut file): (Header, _, _) =
            ModelFile::open_versions(bytes, MAGIC, &VERSIONS, "a face proposal network")?;
        let outputs: Vec<String> = match (version, header.outputs) {
            (1, None) => vec!["logit".to_string()],
            (1, Some(_)) => {
                return Err(Error::ModelFile(
                    "a version-1 proposal file names no outputs".into(),
                ))
            }
            (_, None) => {
                return Err(Error::ModelFile(
                    "the proposal file does not name its outputs".into(),
                ))
            }
            (_, Some(names)) => names,
        };
        let known = outputs.iter().all(|n| OUTPUT_NAMES.contains(&n.as_str()));
        let unique = outputs
            .iter()
            .enumerate()
            .all(|(i, n)| !outputs[..i].contains(n));
        if outputs.first().map(String::as_str) != Some("logit") || !known || !unique {
            return Err(Error::ModelFile(format!(
                "proposal outputs {outputs:?}: not \"logit\" first then distinct names of \
                 {OUTPUT_NAMES:?}"
            )));
        }
        let step_ok = header
            .scale_step
            .is_none_or(|s| s.is_finite() && s > 1.0 && s <= 4.0);
        let logit_ok = header.min_logit.is_none_or(f32::is_finite);
        if !step_ok || !logit_ok {
            return Err(Error::ModelFile(
                "the proposal file's scale step or logit threshold is out of range".into(),
            ));
        }
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
        if layers.is_empty() || side != 1 || channels != outputs.len() {
            return Err(Error::ModelFile(format!(
                "the proposal layers do not reduce the window to its {} output(s)",
                outputs.len()
            )));
        }
        file.finish()?;
        let mut wanted = vec![header.check_logit];
        match header.check_outputs {
            Some(all) if all.len() == outputs.len() && all.first() == Some(&header.check_logit) => {
                wanted = all;
            }
            Some(_) => {
                return Err(Error::ModelFile(
                    "the proposal file's check outputs do not match its outputs".into(),
                ))
            }
            None if version >= 2 => {
                return Err(Error::ModelFile(
                    "the proposal file gives no check outputs".into(),
                ))
            }
            None => {}
        }
        let defaults = ProposalParams {
            scale_step: header.scale_step.unwrap_or(DEFAULT_SCALE_STEP),
            min_logit: header.min_logit.unwrap_or(0.0),
            ..ProposalParams::default()
        };
        let net = Self {
            window: header.window,
            layers,
            stride,
            channels: Channels::from_names(&outputs),
            outputs,
            defaults,
        };
        let n = net.window as u32;
        let check = GrayImage::from_fn(n, n, |x, y| {
            image::Luma([((((y * n + x) as usize) * 31) % 255) as u8])
        });
        let (got, ..) = net.output_map(&check);
        for (channel, (&want, &got)) in wanted.iter().zip(&got).enumerate() {
            let deviation = (got - want).abs();
            if deviation.is_nan() || deviation > CHECK_TOLERANCE * want.abs().max(1.0) {
                return Err(Error::ModelFile(format!(
                    "the proposal network gives {got} on the check window, its trainer {want} \
                     (output {channel}; a damaged file, or weights in another layout)"
                )));
            }
        }
        Ok(net)
    }

    /// Side of the window the classifier judges, pixels.
    #[cfg(test)]
    pub(crate) fn window(&self) -> usize {
        self.window
    }

    /// Pixels between neighbouring windows in [`Self::score_map`].
    #[cfg(test)]
    pub(crate) fn stride(&self) -> usize {
        self.stride
    }

    /// The classifier's logit for every window of `level` whose top-left corner is a multiple
    /// of [`Self::stride`], as `(scores, columns, rows)`, row-major; empty when `level` is
    /// smaller than the window.
    #[cfg(test)]
    pub(crate) fn score_map(&self, level: &GrayImage) -> (Vec<f32>, usize, usize) {
        let (all, cols, rows) = self.output_map(level);
        let per = self.outputs.len();
        (all.into_iter().step_by(per).collect(), cols, rows)
    }

    /// Every output ([`Self::outputs`]) for every window of [`Self::score_map`], as
    /// `(outputs, columns, rows)`: the windows row-major, each window's outputs together.
    pub(crate) fn output_map(&self, level: &GrayImage) -> (Vec<f32>, usize, usize) {
        self.output_map_in(level, None)
    }

    /// [`Self::output_map`], its tiles scored one after the other in `buffers` if given (a
    /// large photo's levels: the memory of one tile's activations, freed with `buffers`), else
    /// as parallel tasks, each in its thread's own buffers, kept for the next level and frame.
    fn output_map_in(
        &self,
        level: &GrayImage,
        buffers: Option<&mut Buffers>,
    ) -> (Vec<f32>, usize, usize) {
        let (w, h) = (level.width() as usize, level.height() as usize);
        let n = self.window;
        let per = self.outputs.len();
        if w < n || h < n {
            return (Vec::new(), 0, 0);
        }
        let (cols, rows) = ((w - n) / self.stride + 1, (h - n) / self.stride + 1);
        // Tiles are scored as tasks of their own: a 1080p frame's largest level, half the
        // pyramid's pixels, is six tiles, which would otherwise keep one core busy alone.
        let tiles: Vec<(usize, usize)> = (0..rows)
            .step_by(TILE)
            .flat_map(|r| (0..cols).step_by(TILE).map(move |c| (r, c)))
            .collect();
        let size =
            |(first_row, first_col)| (TILE.min(rows - first_row), TILE.min(cols - first_col));
        let scored: Vec<Vec<f32>> = match buffers {
            Some(buffers) => tiles
                .iter()
                .map(|&first| self.score_tile(level, first, size(first), buffers))
                .collect(),
            None => tiles
                .par_iter()
                .map(|&first| {
                    BUFFERS.with(|buffers| {
                        self.score_tile(level, first, size(first), &mut buffers.borrow_mut())
                    })
                })
                .collect(),
        };
        let mut scores = vec![0f32; cols * rows * per];
        for (&(first_row, first_col), tile) in tiles.iter().zip(&scored) {
            let tile_cols = TILE.min(cols - first_col);
            for (y, values) in tile.chunks_exact(tile_cols * per).enumerate() {
                let at = ((first_row + y) * cols + first_col) * per;
                scores[at..at + values.len()].copy_from_slice(values);
            }
        }
        (scores, cols, rows)
    }

    /// The outputs of the `tile_rows x tile_cols` windows from window `(first_row, first_col)`
    /// of `level`, row-major, each window's outputs together.
    fn score_tile(
        &self,
        level: &GrayImage,
        (first_row, first_col): (usize, usize),
        (tile_rows, tile_cols): (usize, usize),
        buffers: &mut Buffers,
    ) -> Vec<f32> {
        let w = level.width() as usize;
        let n = self.window;
        let per = self.outputs.len();
        let raw = level.as_raw();
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
        let out = self.forward(buffers);
        debug_assert_eq!((out.height, out.width), (tile_rows, tile_cols));
        let plane = tile_rows * tile_cols;
        let mut scores = vec![0f32; plane * per];
        for (channel, map) in out.data.chunks_exact(plane).take(per).enumerate() {
            for (o, &v) in scores[channel..].iter_mut().step_by(per).zip(map) {
                *o = v;
            }
        }
        scores
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
    /// `min_logit`, moved and scaled by what the network regresses. The level is padded by half
    /// a window of repeated edge pixels (as the trainer's renderer reads past a photo's edge),
    /// so that a face at the edge of the image, or filling it, is still seen whole by some
    /// window. Scored in `buffers` if given (see [`Self::output_map_in`]).
    fn level_proposals(
        &self,
        gray: &GrayImage,
        eye_distance: f64,
        min_logit: f32,
        buffers: Option<&mut Buffers>,
    ) -> Vec<Proposal> {
        let level = self.level(gray, gray, eye_distance);
        self.proposals_on_level(gray.dimensions(), &level, eye_distance, min_logit, buffers)
    }

    /// The size of `gray`'s pyramid level for eyes `eye_distance` image pixels apart.
    fn level_size(&self, (w, h): (u32, u32), eye_distance: f64) -> (u32, u32) {
        // Window pixels per image pixel at this level: the window spans CROP_EYE_DISTANCES.
        let scale = self.window as f64 / (eye_distance * CROP_EYE_DISTANCES);
        (
            ((f64::from(w) * scale).round() as u32).max(1),
            ((f64::from(h) * scale).round() as u32).max(1),
        )
    }

    /// `gray`'s pyramid level for eyes `eye_distance` image pixels apart, reduced from `source`:
    /// `gray` itself or (for the detector) an earlier, larger level of it.
    fn level(&self, gray: &GrayImage, source: &GrayImage, eye_distance: f64) -> GrayImage {
        let (lw, lh) = self.level_size(gray.dimensions(), eye_distance);
        let large = u64::from(gray.width()) * u64::from(gray.height()) > LARGE_PHOTO_PIXELS;
        let reduced = lw <= source.width() && lh <= source.height();
        if (large || self.regresses_size()) && reduced {
            // `resize` keeps an intermediate of 16 bytes per pixel of the photo's width times the
            // level's height (83 MB for a level of a 12 MP photo, more than all the rest of
            // the search); an area average (`thumbnail`'s, bit for bit) makes the level directly
            // and is many times faster than the triangle filter, and its box average is the blur the
            // detector's training windows have (`examples/detector_crops.rs`), so the
            // detector's levels are always made with it.
            crate::resample::shrink_by_area(source, lw, lh)
        } else {
            image::imageops::resize(source, lw, lh, image::imageops::FilterType::Triangle)
        }
    }

    /// The proposals of pyramid `level` (of an image `w x h`) for eyes `eye_distance` image
    /// pixels apart: see [`Self::level_proposals`].
    fn proposals_on_level(
        &self,
        (w, h): (u32, u32),
        level: &GrayImage,
        eye_distance: f64,
        min_logit: f32,
        buffers: Option<&mut Buffers>,
    ) -> Vec<Proposal> {
        let (w, h) = (f64::from(w), f64::from(h));
        let (lw, lh) = level.dimensions();
        let n = self.window as f64;
        let border = self.window / 2;
        let padded = with_edge_border(level, border as u32);
        let (sx, sy) = (w / f64::from(lw), h / f64::from(lh));
        let (outputs, cols, _) = self.output_map_in(&padded, buffers);
        // Level pixels per window eye distance.
        let per_eye_distance = n / CROP_EYE_DISTANCES;
        let ch = self.channels;
        outputs
            .chunks_exact(self.outputs.len())
            .enumerate()
            .filter(|&(_, out)| out[0] >= min_logit)
            .map(|(i, out)| {
                let (col, row) = (i % cols, i / cols);
                // The window's centre in the level (pixel centres at integers), then up to the
                // eyes and by the regressed offset, then to the image.
                let cx = (col * self.stride) as f64 - border as f64 + (n - 1.0) / 2.0;
                let cy = (row * self.stride) as f64 - border as f64 + (n - 1.0) / 2.0;
                let eyes_x = cx + regressed(out, ch.dx, MAX_OFFSET) * per_eye_distance;
                let eyes_y = cy - EYES_ABOVE_CENTRE * per_eye_distance
                    + regressed(out, ch.dy, MAX_OFFSET) * per_eye_distance;
                Proposal {
                    eyes_midpoint: Point::new((eyes_x + 0.5) * sx - 0.5, (eyes_y + 0.5) * sy - 0.5),
                    eye_distance: eye_distance * regressed(out, ch.log_scale, MAX_LOG_SCALE).exp(),
                    logit: out[0],
                    k: regressed(out, ch.k, MAX_SHEAR),
                    roll: regressed(out, ch.roll, MAX_ROLL),
                }
            })
            .collect()
    }

    /// The detector's levels' proposals, in the order of `eye_distances` (increasing): each
    /// level reduced from the smallest level already made that is at least twice its size
    /// each way (else from `gray`), which costs a fraction of reducing the whole photo again
    /// (on a 1080p frame, a third of the detector's time went into the reductions). The
    /// levels are made one after the other on this thread and each is scored as a task of its
    /// own as soon as it exists, so scoring the first (largest) level overlaps making the
    /// others. For a `large` photo one level at a time, only the levels still needed as a
    /// source kept.
    fn chained_levels(
        &self,
        gray: &GrayImage,
        eye_distances: &[f64],
        min_logit: f32,
        large: bool,
    ) -> Vec<Vec<Proposal>> {
        let dims = gray.dimensions();
        // The smallest of `built` at least twice `size` each way.
        let source = |built: &[std::sync::Arc<GrayImage>], size: (u32, u32)| -> Option<usize> {
            built
                .iter()
                .enumerate()
                .filter(|(_, l)| l.width() >= 2 * size.0 && l.height() >= 2 * size.1)
                .min_by_key(|(_, l)| u64::from(l.width()) * u64::from(l.height()))
                .map(|(i, _)| i)
        };
        let mut built: Vec<std::sync::Arc<GrayImage>> = Vec::new();
        if large {
            // One tile's buffers for every level, freed when the photo's levels are done.
            let mut buffers = Buffers::default();
            let mut out = Vec::with_capacity(eye_distances.len());
            for &d in eye_distances {
                let size = self.level_size(dims, d);
                let level = match source(&built, size) {
                    Some(i) => self.level(gray, &built[i], d),
                    None => self.level(gray, gray, d),
                };
                out.push(self.proposals_on_level(dims, &level, d, min_logit, Some(&mut buffers)));
                built.push(std::sync::Arc::new(level));
                // A level is a source for the levels at most half its size; with the levels
                // shrinking, the last three serve every step down to 1.26.
                if built.len() > 3 {
                    built.remove(0);
                }
            }
            return out;
        }
        let results: Vec<std::sync::Mutex<Vec<Proposal>>> = eye_distances
            .iter()
            .map(|_| std::sync::Mutex::new(Vec::new()))
            .collect();
        rayon::scope(|scope| {
            for (i, &d) in eye_distances.iter().enumerate() {
                let size = self.level_size(dims, d);
                let level = std::sync::Arc::new(match source(&built, size) {
                    Some(j) => self.level(gray, &built[j], d),
                    None => self.level(gray, gray, d),
                });
                built.push(level.clone());
                let slot = &results[i];
                scope.spawn(move |_| {
                    let found = self.proposals_on_level(dims, &level, d, min_logit, None);
                    if let Ok(mut s) = slot.lock() {
                        *s = found;
                    }
                });
            }
        });
        results
            .into_iter()
            .map(|m| m.into_inner().unwrap_or_default())
            .collect()
    }

    /// Windows that the classifier takes for a face in `gray`, strongest first: the
    /// classifier run over a pyramid from `params.min_eye_distance` (times the root of the
    /// step for a network that regresses the face's size) up to windows of
    /// 1.5 times the image's shorter side (each level a triangle-filtered reduction of the
    /// image, an area-averaged one for photos over 4 megapixels, padded by half a window of
    /// repeated edge pixels), windows at or above `params.min_logit`, each moved and scaled by
    /// what the network regresses (when it does), a window dropped when a stronger one
    /// expects eyes within half an eye distance of its own at a size within
    /// `params.scale_step` squared (for a network that regresses the face's size, averaged into
    /// that one instead, weighted by the logistic of its logit: the proposal's eyes, log eye
    /// distance, shear and roll are its windows' weighted means, its logit the strongest's), and
    /// at most `params.max_proposals` kept.
    pub fn propose(&self, gray: &GrayImage, params: &ProposalParams) -> Vec<Proposal> {
        let (w, h) = (f64::from(gray.width()), f64::from(gray.height()));
        let step = params.scale_step.max(1.01);
        let mut eye_distances = Vec::new();
        let mut eye_distance = params.min_eye_distance.max(1.0);
        if self.regresses_size() {
            eye_distance *= step.sqrt();
        }
        while eye_distance * CROP_EYE_DISTANCES <= MAX_WINDOW_PER_SIDE * w.min(h) {
            eye_distances.push(eye_distance);
            eye_distance *= step;
        }
        // The levels are independent: in parallel (in the order of the levels either way), but
        // one at a time for a large photo, whose levels and tile buffers would otherwise be
        // alive at once on every core (as the pipeline searches a large photo's views).
        let large = u64::from(gray.width()) * u64::from(gray.height()) > LARGE_PHOTO_PIXELS;
        let per_level: Vec<Vec<Proposal>> = if self.regresses_size() {
            self.chained_levels(gray, &eye_distances, params.min_logit, large)
        } else if large {
            let mut buffers = Buffers::default();
            eye_distances
                .iter()
                .map(|&d| self.level_proposals(gray, d, params.min_logit, Some(&mut buffers)))
                .collect()
        } else {
            eye_distances
                .par_iter()
                .map(|&d| self.level_proposals(gray, d, params.min_logit, None))
                .collect()
        };
        let mut found: Vec<Proposal> = per_level.into_iter().flatten().collect();
        found.sort_by(|a, b| b.logit.total_cmp(&a.logit));
        let overlap = |p: &Proposal, k: &Proposal| {
            let ratio = p.eye_distance / k.eye_distance;
            ratio < step * step
                && ratio > 1.0 / (step * step)
                && p.eyes_midpoint.distance(k.eyes_midpoint)
                    < 0.5 * p.eye_distance.max(k.eye_distance)
        };
        if !self.regresses_size() {
            let mut kept: Vec<Proposal> = Vec::new();
            for p in found {
                if kept.len() >= params.max_proposals {
                    break;
                }
                if !kept.iter().any(|k| overlap(&p, k)) {
                    kept.push(p);
                }
            }
            return kept;
        }
        // A regressing network's neighbouring windows on one face each give their own reading
        // of it: a window that overlaps a stronger one is not dropped but averaged into it,
        // weighted by its chance of being a face (the strongest window's logit is kept).
        let mut kept: Vec<(Proposal, Vote)> = Vec::new();
        for p in found {
            let full = kept.len() >= params.max_proposals;
            match kept.iter_mut().find(|(k, _)| overlap(&p, k)) {
                Some((_, vote)) => vote.add(&p),
                None if !full => {
                    let mut vote = Vote::default();
                    vote.add(&p);
                    kept.push((p, vote));
                }
                None => {}
            }
        }
        kept.into_iter().map(|(p, vote)| vote.result(p)).collect()
    }
}

/// The weighted sums of the windows averaged into one proposal ([`ProposalNet::propose`]).
#[derive(Debug, Default)]
struct Vote {
    weight: f64,
    x: f64,
    y: f64,
    log_eye_distance: f64,
    k: f64,
    roll: f64,
}

impl Vote {
    fn add(&mut self, p: &Proposal) {
        // The logistic of the logit, at least a tiny weight so that a sum is never zero.
        let w = (1.0 / (1.0 + (-f64::from(p.logit)).exp())).max(1e-6);
        self.weight += w;
        self.x += w * p.eyes_midpoint.x;
        self.y += w * p.eyes_midpoint.y;
        self.log_eye_distance += w * p.eye_distance.ln();
        self.k += w * p.k;
        self.roll += w * p.roll;
    }

    /// `strongest` (the first window added) with the averages.
    fn result(&self, strongest: Proposal) -> Proposal {
        let w = self.weight;
        Proposal {
            eyes_midpoint: Point::new(self.x / w, self.y / w),
            eye_distance: (self.log_eye_distance / w).exp(),
            k: self.k / w,
            roll: self.roll / w,
            ..strongest
        }
    }
}

/// `image` with `border` pixels added on every side, each a copy of the nearest edge pixel.
fn with_edge_border(image: &GrayImage, border: u32) -> GrayImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let b = border as usize;
    let width = w + 2 * b;
    let mut out = vec![0u8; width * (h + 2 * b)];
    let source = image.as_raw();
    for (y, row) in out.chunks_exact_mut(width).enumerate() {
        let from = &source[y.saturating_sub(b).min(h - 1) * w..][..w];
        let (left, rest) = row.split_at_mut(b);
        let (middle, right) = rest.split_at_mut(w);
        left.fill(from[0]);
        middle.copy_from_slice(from);
        right.fill(from[w - 1]);
    }
    GrayImage::from_raw(width as u32, (h + 2 * b) as u32, out)
        .unwrap_or_else(|| unreachable!("the buffer has the image's size"))
}

thread_local! {
    /// The activations and im2col matrices of one tile, per thread and reused by every level
    /// and frame: made afresh for each level, their first touch (page faults, the kernel zeroing
    /// pages) cost as much as the strided convolutions themselves.
    static BUFFERS: std::cell::RefCell<Buffers> = std::cell::RefCell::new(Buffers::default());
}

/// The buffers one tile's forward pass works in.
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
        reference_outputs(window, layers, pixels)[0]
    }

    /// Every output by the definition of the layers on one window.
    fn reference_outputs(window: usize, layers: &[Spec], pixels: &[u8]) -> Vec<f32> {
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
        values
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
        let specs = layer_specs(layers);
        let header = serde_json::json!({"window": window, "check_logit": check, "layers": specs})
            .to_string();
        let mut bytes = file_start(1, &header);
        for (w, b) in weights(layers) {
            bytes.extend(w.iter().chain(&b).flat_map(|v| v.to_le_bytes()));
        }
        bytes
    }

    /// The layers' entries of a file header.
    fn layer_specs(layers: &[Spec]) -> Vec<serde_json::Value> {
        layers
            .iter()
            .map(|&(i, o, k, s, r)| {
                serde_json::json!({"in": i, "out": o, "kernel": k, "stride": s, "relu": r})
            })
            .collect()
    }

    /// The start of a file of format `version`: the magic, the version and `header`; the
    /// weights follow.
    fn file_start(version: u32, header: &str) -> Vec<u8> {
        let mut bytes = MAGIC.to_vec();
        bytes.extend(version.to_le_bytes());
        bytes.extend((header.len() as u32).to_le_bytes());
        bytes.extend(header.as_bytes());
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

    /// A version-2 file: `layers` with the weights of [`weights`], output channels `names`,
    /// the check outputs of [`reference_outputs`], and `extra` header entries.
    fn file_v2(
        window: usize,
        layers: &[Spec],
        names: &[&str],
        extra: serde_json::Value,
    ) -> Vec<u8> {
        let check = reference_outputs(window, layers, &check_pixels(window));
        let specs = layer_specs(layers);
        let mut header = serde_json::json!({
            "window": window,
            "check_logit": check[0],
            "check_outputs": check,
            "outputs": names,
            "layers": specs,
        });
        if let (Some(h), Some(e)) = (header.as_object_mut(), extra.as_object()) {
            h.extend(e.clone());
        }
        let header = header.to_string();
        let mut bytes = file_start(2, &header);
        for (w, b) in weights(layers) {
            bytes.extend(w.iter().chain(&b).flat_map(|v| v.to_le_bytes()));
        }
        bytes
    }

    /// Window 32, output stride 8 (32 -> 15 -> 7 -> 3 -> 1), six outputs: the detector's shape
    /// with fewer channels.
    const DETECTOR: [Spec; 5] = [
        (1, 2, 3, 2, true),
        (2, 3, 3, 2, true),
        (3, 4, 3, 2, true),
        (4, 5, 3, 1, true),
        (5, 6, 1, 1, false),
    ];

    #[test]
    fn a_version_2_file_gives_every_named_output_of_every_window() {
        let bytes = file_v2(
            32,
            &DETECTOR,
            &OUTPUT_NAMES,
            serde_json::json!({"scale_step": 1.4}),
        );
        let net = ProposalNet::from_bytes(&bytes).expect("a valid version-2 file");
        assert_eq!((net.window(), net.stride()), (32, 8));
        assert_eq!(net.outputs(), OUTPUT_NAMES);
        assert!(net.regresses_size());
        let defaults = net.default_params();
        assert_eq!(defaults.scale_step, 1.4);
        assert_eq!(defaults.min_logit, 0.0);
        // Two tiles wide.
        let level = noise((8 * (TILE + 2) + 32) as u32, 8 * 3 + 32, 5);
        let (map, cols, rows) = net.output_map(&level);
        assert_eq!((cols, rows), (TILE + 3, 4));
        assert_eq!(map.len(), cols * rows * 6);
        let (logits, ..) = net.score_map(&level);
        for row in 0..rows {
            for col in [0, 1, TILE - 1, TILE, cols - 1] {
                let window =
                    image::imageops::crop_imm(&level, 8 * col as u32, 8 * row as u32, 32, 32)
                        .to_image();
                let want = reference_outputs(32, &DETECTOR, window.as_raw());
                let got = &map[(row * cols + col) * 6..][..6];
                for (g, w) in got.iter().zip(&want) {
                    assert!(
                        (g - w).abs() <= 1e-4 * w.abs().max(1.0),
                        "{got:?} vs {want:?}"
                    );
                }
                assert_eq!(logits[row * cols + col], got[0]);
            }
        }
        // Fewer outputs, in another order.
        let mut three = DETECTOR;
        three[4].1 = 3;
        let net = ProposalNet::from_bytes(&file_v2(
            32,
            &three,
            &["logit", "k", "dx"],
            serde_json::json!({}),
        ))
        .expect("three outputs");
        assert!(!net.regresses_size());
        assert_eq!(net.default_params(), ProposalParams::default());
    }

    /// A window-12 stride-2 net whose outputs are its last biases whatever the window (all
    /// weights zero).
    fn constant_net(outputs: &[(&str, f32)]) -> ProposalNet {
        let layers: [Spec; 2] = [(1, 2, 12, 2, true), (2, outputs.len(), 1, 1, false)];
        let names: Vec<&str> = outputs.iter().map(|o| o.0).collect();
        let specs = layer_specs(&layers);
        let values: Vec<f32> = outputs.iter().map(|o| o.1).collect();
        let header = serde_json::json!({
            "window": 12, "check_logit": values[0], "check_outputs": values,
            "outputs": names, "layers": specs,
        })
        .to_string();
        let mut bytes = file_start(2, &header);
        let zeros = 2 * 144 + 2 + outputs.len() * 2;
        bytes.extend((0..zeros).flat_map(|_| 0f32.to_le_bytes()));
        bytes.extend(values.iter().flat_map(|v| v.to_le_bytes()));
        ProposalNet::from_bytes(&bytes).expect("a constant network")
    }

    #[test]
    fn proposals_are_moved_scaled_and_given_the_shear_and_roll_the_network_regresses() {
        let plain = constant_net(&[("logit", 2.0)]);
        let scale = 1.2f32.ln();
        let moved = constant_net(&[
            ("logit", 2.0),
            ("dx", 0.3),
            ("dy", -0.2),
            ("log_scale", scale),
            ("k", 0.25),
            ("roll", -0.1),
        ]);
        let gray = noise(200, 150, 3);
        let a = plain.level_proposals(&gray, 20.0, 0.0, None);
        let b = moved.level_proposals(&gray, 20.0, 0.0, None);
        assert_eq!(a.len(), b.len());
        assert!(!a.is_empty());
        for (a, b) in a.iter().zip(&b) {
            assert_eq!((a.k, a.roll), (0.0, 0.0));
            assert_eq!(a.eye_distance, 20.0);
            // 0.3 and -0.2 of the window's eye distance (20 px; the level's rounding of its
            // size moves it by up to 2%).
            let (dx, dy) = (
                b.eyes_midpoint.x - a.eyes_midpoint.x,
                b.eyes_midpoint.y - a.eyes_midpoint.y,
            );
            assert!(
                (dx - 6.0).abs() < 0.12 && (dy + 4.0).abs() < 0.08,
                "moved by ({dx}, {dy})"
            );
            assert!((b.eye_distance - 24.0).abs() < 1e-4, "{}", b.eye_distance);
            assert!((b.k - 0.25).abs() < 1e-6 && (b.roll + 0.1).abs() < 1e-6);
            assert_eq!(b.logit, 2.0);
        }
        // A runaway regression is clamped, a shear of 1e30 to the largest reported.
        let wild = constant_net(&[("logit", 2.0), ("k", 1e30), ("dx", -1e30)]);
        let c = wild.level_proposals(&gray, 20.0, 0.0, None);
        assert!(c
            .iter()
            .all(|p| p.k == MAX_SHEAR && p.eyes_midpoint.x.is_finite()));
        // The pyramid of a size-regressing network starts the root of the step above the
        // smallest eye distance: with a step of 4, the plain network's levels are at eye
        // distances 10 and 40, the regressing one's at 20 only (80 does not fit), its windows
        // all regressing to 24 (and so averaging to it).
        let params = ProposalParams {
            min_eye_distance: 10.0,
            scale_step: 4.0,
            max_proposals: 10_000,
            ..ProposalParams::default()
        };
        let smallest = |net: &ProposalNet| {
            net.propose(&gray, &params)
                .iter()
                .map(|p| p.eye_distance)
                .fold(f64::INFINITY, f64::min)
        };
        assert!((smallest(&plain) - 10.0).abs() < 1e-9);
        assert!((smallest(&moved) - 24.0).abs() < 1e-4);
        let merged = moved.propose(&gray, &params);
        assert!(merged
            .iter()
            .all(|p| (p.k - 0.25).abs() < 1e-6 && p.logit == 2.0));
    }

    #[test]
    fn version_2_files_that_break_the_contract_are_refused() {
        let none = serde_json::json!({});
        let good = file_v2(32, &DETECTOR, &OUTPUT_NAMES, none.clone());
        assert!(ProposalNet::from_bytes(&good).is_ok());
        let refused = |bytes: &[u8], why: &str| {
            assert!(ProposalNet::from_bytes(bytes).is_err(), "accepted: {why}");
        };
        let mut names = OUTPUT_NAMES;
        names.swap(0, 1);
        refused(
            &file_v2(32, &DETECTOR, &names, none.clone()),
            "logit not first",
        );
        let mut names = OUTPUT_NAMES;
        names[5] = "yaw";
        refused(
            &file_v2(32, &DETECTOR, &names, none.clone()),
            "an unknown output",
        );
        let mut names = OUTPUT_NAMES;
        names[5] = "dx";
        refused(
            &file_v2(32, &DETECTOR, &names, none.clone()),
            "a name twice",
        );
        refused(
            &file_v2(32, &DETECTOR, &OUTPUT_NAMES[..5], none.clone()),
            "6 outputs, 5 names",
        );
        for step in [1.0, 0.5, 10.0] {
            let extra = serde_json::json!({"scale_step": step});
            refused(&file_v2(32, &DETECTOR, &OUTPUT_NAMES, extra), "scale step");
        }
        // The check outputs: one of them off, too few, or none at all.
        let text = String::from_utf8_lossy(&good).into_owned();
        let start = text.find("\"check_outputs\":[").expect("check outputs") + 17;
        let end = start + text[start..].find(']').expect("end");
        let values: Vec<f32> = serde_json::from_str(&text[start - 1..=end]).expect("values");
        let with_check = |check: serde_json::Value| -> Vec<u8> {
            let header_len = u32::from_le_bytes([good[12], good[13], good[14], good[15]]) as usize;
            let mut header: serde_json::Value =
                serde_json::from_slice(&good[16..16 + header_len]).expect("header");
            match check {
                serde_json::Value::Null => {
                    header
                        .as_object_mut()
                        .expect("object")
                        .remove("check_outputs");
                }
                c => header["check_outputs"] = c,
            }
            let header = header.to_string();
            let mut bytes = good[..8].to_vec();
            bytes.extend(2u32.to_le_bytes());
            bytes.extend((header.len() as u32).to_le_bytes());
            bytes.extend(header.as_bytes());
            bytes.extend(&good[16 + header_len..]);
            bytes
        };
        assert!(ProposalNet::from_bytes(&with_check(serde_json::json!(values))).is_ok());
        let mut off = values.clone();
        off[3] += 0.5;
        refused(&with_check(serde_json::json!(off)), "a check output off");
        refused(
            &with_check(serde_json::json!(values[..5])),
            "five check outputs",
        );
        refused(&with_check(serde_json::Value::Null), "no check outputs");
        // A version-2 file without names; a version-1 file with them; version 3.
        let mut unnamed = good.clone();
        let at = String::from_utf8_lossy(&unnamed)
            .find("\"outputs\"")
            .expect("names");
        unnamed[at + 1] = b'X';
        refused(&unnamed, "no output names");
        let mut v1 = good.clone();
        v1[8..12].copy_from_slice(&1u32.to_le_bytes());
        refused(&v1, "a version-1 file naming outputs");
        let mut v3 = good.clone();
        v3[8..12].copy_from_slice(&3u32.to_le_bytes());
        refused(&v3, "version 3");
        // Truncated anywhere: an error, not a panic.
        for cut in (0..good.len()).step_by(97) {
            refused(&good[..cut], "truncated");
        }
    }

    #[test]
    fn the_edge_border_repeats_the_nearest_edge_pixel() {
        for (w, h, border) in [(1, 1, 3), (7, 5, 2), (20, 3, 16), (4, 9, 0)] {
            let image = noise(w, h, w * h);
            let padded = with_edge_border(&image, border);
            assert_eq!(padded.dimensions(), (w + 2 * border, h + 2 * border));
            for (x, y, v) in padded.enumerate_pixels() {
                let sx = x.saturating_sub(border).min(w - 1);
                let sy = y.saturating_sub(border).min(h - 1);
                assert_eq!(
                    v,
                    image.get_pixel(sx, sy),
                    "({x}, {y}) of {w}x{h} + {border}"
                );
            }
        }
    }

    #[test]
    fn the_built_in_networks_load_with_their_own_searches() {
        let classifier = ProposalNet::embedded().expect("proposals.bin");
        assert_eq!(classifier.outputs(), ["logit"]);
        assert_eq!(classifier.stride(), 4);
        assert_eq!(classifier.default_params(), ProposalParams::default());
        let detector = ProposalNet::embedded_detector().expect("detector.bin");
        assert_eq!(detector.outputs(), OUTPUT_NAMES);
        assert_eq!((detector.window(), detector.stride()), (32, 8));
        assert!(detector.regresses_size());
    }

    /// A Yale fixture and its face as the landmark network locates it.
    fn fixture_and_its_face() -> (GrayImage, crate::locate::network::LocatedFace) {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/faces/subject01.normal.jpeg"
        );
        let gray = image::open(path).expect("fixture").into_luma8();
        let landmarks = crate::locate::network::LandmarkNet::embedded().expect("built-in network");
        let start = landmarks.frame(Point::new(160.0, 100.0), 60.0, 0.0, 0.0);
        let mut ws = crate::locate::network::Workspace::default();
        let face =
            crate::locate::network::locate(&landmarks, &gray, start, &mut ws).expect("a face");
        (gray, face)
    }

    /// `gray` sheared by `k` about its middle row (the canvas grown to hold it), with where
    /// `face`'s eyes' midpoint lands and its eye distance.
    fn sheared_with_eyes(
        gray: &GrayImage,
        face: &crate::locate::network::LocatedFace,
        k: f64,
    ) -> (GrayImage, Point, f64) {
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
        (
            sheared.into_luma8(),
            eyes,
            face.right_eye.distance(face.left_eye),
        )
    }

    #[test]
    fn the_built_in_detector_finds_the_fixture_face_and_its_shear_at_any_shear() {
        let (gray, face) = fixture_and_its_face();
        let net = ProposalNet::embedded_detector().expect("built-in detector");
        let params = ProposalParams {
            min_eye_distance: 15.2,
            ..net.default_params()
        };
        for k in [0.0, 0.4, -0.4] {
            let (sheared, eyes, distance) = sheared_with_eyes(&gray, &face, k);
            let proposals = net.propose(&sheared, &params);
            // The eyes within a quarter of an eye distance, the size within 20%, and the
            // shear read to 0.2.
            let hit = proposals.iter().any(|p| {
                p.eyes_midpoint.distance(eyes) < 0.25 * distance
                    && (p.eye_distance / distance).ln().abs() < 1.2f64.ln()
                    && (p.k - k).abs() < 0.2
            });
            assert!(hit, "k = {k}: no proposal at the face in {proposals:?}");
            assert!(proposals.windows(2).all(|w| w[0].logit >= w[1].logit));
        }
    }

    #[test]
    fn the_built_in_classifier_proposes_the_fixture_face_at_any_shear() {
        let (gray, face) = fixture_and_its_face();
        let net = ProposalNet::embedded().expect("built-in proposal classifier");
        for k in [0.0, 0.4, -0.4] {
            let (sheared, eyes, distance) = sheared_with_eyes(&gray, &face, k);
            let proposals = net.propose(&sheared, &ProposalParams::default());
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
