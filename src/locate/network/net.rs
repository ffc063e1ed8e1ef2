//! The landmark network's weights and its forward pass.
//!
//! The topology (fixed here and in `scripts/train_landmarks.py`, which trains it): a strided
//! trunk of 3x3 convolutions with ReLU, `size -> size/2 -> size/4 -> size/8 -> size/16` pixels
//! (stages of 2, 2, 3 and 2 convolutions, the first of each with stride 2); a feature pyramid
//! back up to `size/4` (1x1 lateral convolutions, nearest-neighbour upsampling, a 3x3
//! convolution after each merge); one heatmap per landmark at `size/4`, read as a spatial
//! softmax and its expectation; and the crop's shear and a face score (the logit of "this crop
//! shows a face") from the trunk's last stage averaged over space, through two dense layers. Batch normalisation was folded into the convolutions when
//! the weights were written.
//!
//! Written by hand rather than with an inference crate: the network is fifteen small
//! convolutions, which im2col and one `gemm` product each run at the speed of a
//! general matrix product, while an inference framework (with its own dependency tree, or ONNX
//! parsing at run time) would add most of this crate's build time for no gain. The file format is documented on [`LandmarkNet::from_bytes`].

use serde::Deserialize;

/// How many times [`LandmarkNet::run`] has run in this process, every network and thread
/// together (a mirrored reading is a run of its own); feature `dev`, to count a frame's runs
/// (`internals::landmark_network_runs`).
#[cfg(feature = "dev")]
pub(crate) static RUNS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::modelfile::ModelFile;
use crate::nn::{add_upsampled, conv, dense, Conv, Im2col, Tensor};

/// Landmarks the network locates, in this order.
pub(crate) const LANDMARK_NAMES: [&str; 4] = ["right_eye", "left_eye", "nose", "mouth"];

/// The file's magic bytes.
const MAGIC: &[u8; 8] = b"UNSHEARN";

/// The file format version this build reads.
const VERSION: u32 = 1;

/// How far (crop pixels, or shear) a loaded network's output on the check crop may be from what
/// its trainer recorded: float rounding in another order of summation stays far below this, a
/// wrong layer, stride or layout far above.
const CHECK_TOLERANCE: f64 = 0.01;

/// The committed network (`models/landmarks.bin`).
static EMBEDDED: &[u8] = include_bytes!("../../../models/landmarks.bin");

#[derive(Debug, Deserialize)]
struct LayerSpec {
    name: String,
    kind: String,
    #[serde(rename = "in")]
    inputs: usize,
    #[serde(rename = "out")]
    outputs: usize,
    #[serde(default)]
    kernel: usize,
    #[serde(default)]
    stride: usize,
    relu: bool,
}

/// What the trainer's network gave on a fixed synthetic crop (pixel `i` has grey level
/// `(i * 31) % 255`), stored in the file so the forward pass here can be checked against it.
#[derive(Debug, Clone, Deserialize)]
struct Check {
    points: [f64; 8],
    shear: f64,
    face_logit: f64,
}

#[derive(Debug, Deserialize)]
struct Header {
    size: usize,
    check: Check,
    widths: [usize; 4],
    fpn: usize,
    crop_eye_distances: f64,
    eyes_above_centre: f64,
    layers: Vec<LayerSpec>,
}

/// The network, loaded and checked.
#[derive(Debug, Clone)]
pub struct LandmarkNet {
    size: usize,
    check: Check,
    crop_eye_distances: f64,
    eyes_above_centre: f64,
    /// stem (2), down2 (2), down3 (3), down4 (2), lat4, lat3, lat2, smooth3, smooth2, heat.
    convs: Vec<Conv>,
    dense: [Conv; 2],
}

/// Reusable buffers for [`LandmarkNet::run`] (one per thread): the activations and im2col
/// matrices, which are not allocated again once they have grown to the network's sizes. The
/// `gemm` crate still allocates small packing buffers inside some products, a few per forward
/// pass, too small to matter beside the pass itself.
#[derive(Debug, Clone, Default)]
pub struct Workspace {
    input: Tensor,
    stages: [Tensor; 4],
    scratch: [Tensor; 2],
    pyramid: [Tensor; 3],
    heat: Tensor,
    im2col: Im2col,
    pooled: Vec<f32>,
    hidden: Vec<f32>,
    head: Vec<f32>,
    /// The crop mirrored left to right ([`LandmarkNet::averaged_with_mirrored`]).
    mirrored: Vec<f32>,
}

/// What the network reads off one crop.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct NetOutput {
    /// Right eye, left eye, nose, mouth, in crop pixels (pixel centres at integers).
    pub points: [Point; 4],
    /// How widely each heatmap's probability is spread about its point (the root of the
    /// summed variances, crop pixels): small when the network is sure.
    pub spread: [f64; 4],
    /// The crop's shear as the network reads it (see `super::crop_shear`).
    pub shear: f64,
    /// The chance, as the network rates it, that the crop shows a face at all (trained on face
    /// crops against crops of other things, including the detector's false alarms).
    pub face: f64,
    /// The face score's logit, `ln(face / (1 - face))`, kept because the score itself
    /// saturates at 0 or 1.
    pub face_logit: f64,
}

impl LandmarkNet {
    /// The network built into the library.
    pub fn embedded() -> Result<Self> {
        Self::from_bytes(EMBEDDED)
    }

    /// Reads a network file: the magic `UNSHEARN`, a little-endian `u32` version (1), a `u32`
    /// header length, a JSON header (crop size, stage widths, pyramid width, crop geometry, and
    /// the layers in order with their sizes), then each layer's weights and biases as
    /// little-endian `f32`, in the header's order. Every layer must match the topology in the
    /// module docs.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let (header, mut file): (Header, _) =
            ModelFile::open(bytes, MAGIC, VERSION, "a landmark network")?;
        let expected = Self::topology(&header)?;
        if header.layers.len() != expected.len() {
            return Err(Error::ModelFile(format!(
                "{} layers, expected {}",
                header.layers.len(),
                expected.len()
            )));
        }
        let mut layers = Vec::with_capacity(expected.len());
        for (spec, want) in header.layers.iter().zip(&expected) {
            let matches = spec.name == want.0
                && spec.kind == want.1
                && spec.inputs == want.2
                && spec.outputs == want.3
                && (spec.kind == "dense" || (spec.kernel == want.4 && spec.stride == want.5))
                && spec.relu == want.6;
            if !matches {
                return Err(Error::ModelFile(format!(
                    "layer {} does not match the topology (expected {want:?})",
                    spec.name
                )));
            }
            let kernel = spec.kernel.max(1);
            let weight = file.take(spec.outputs * spec.inputs * kernel * kernel)?;
            let bias = file.take(spec.outputs)?;
            layers.push(Conv {
                inputs: spec.inputs,
                outputs: spec.outputs,
                kernel,
                stride: spec.stride.max(1),
                relu: spec.relu,
                weight,
                bias,
            });
        }
        file.finish()?;
        let geometry_ok = header.crop_eye_distances.is_finite()
            && header.crop_eye_distances > 0.0
            && header.eyes_above_centre.is_finite();
        if !geometry_ok {
            return Err(Error::ModelFile("bad crop geometry".into()));
        }
        let second = layers
            .pop()
            .ok_or_else(|| Error::ModelFile("no layers".into()))?;
        let first = layers
            .pop()
            .ok_or_else(|| Error::ModelFile("no layers".into()))?;
        let net = Self {
            size: header.size,
            check: header.check,
            crop_eye_distances: header.crop_eye_distances,
            eyes_above_centre: header.eyes_above_centre,
            convs: layers,
            dense: [first, second],
        };
        let deviation = net.check_deviation();
        if deviation.is_nan() || deviation > CHECK_TOLERANCE {
            return Err(Error::ModelFile(format!(
                "the network's output on the check crop is {deviation:.4} off what its trainer \
                 recorded (a damaged file, or weights in another layout)"
            )));
        }
        Ok(net)
    }

    /// How far this forward pass's output on the trainer's check crop is from what the trainer
    /// recorded: the largest landmark distance (crop pixels), shear difference or face-logit
    /// difference.
    fn check_deviation(&self) -> f64 {
        let n = self.size;
        let crop: Vec<f32> = (0..n * n).map(|i| ((i * 31) % 255) as f32).collect();
        let out = self.run(&crop, &mut Workspace::default());
        let points = out
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                p.distance(Point::new(
                    self.check.points[2 * i],
                    self.check.points[2 * i + 1],
                ))
            })
            .fold(0.0, f64::max);
        points
            .max((out.shear - self.check.shear).abs())
            .max((out.face_logit - self.check.face_logit).abs())
    }

    /// The layers the header must list: (name, kind, inputs, outputs, kernel, stride, relu).
    #[allow(clippy::type_complexity)]
    fn topology(
        h: &Header,
    ) -> Result<Vec<(String, &'static str, usize, usize, usize, usize, bool)>> {
        if h.size == 0 || !h.size.is_multiple_of(16) || h.size > 512 {
            return Err(Error::ModelFile(format!(
                "crop size {} is not a multiple of 16 up to 512",
                h.size
            )));
        }
        if h.widths.iter().chain([&h.fpn]).any(|&w| w == 0 || w > 1024) {
            return Err(Error::ModelFile("bad layer widths".into()));
        }
        let [a, b, c, d] = h.widths;
        let f = h.fpn;
        let conv = |name: &str, i, o, k, s, r| (name.to_string(), "conv", i, o, k, s, r);
        Ok(vec![
            conv("stem.0", 1, a, 3, 2, true),
            conv("stem.1", a, a, 3, 1, true),
            conv("down2.0", a, b, 3, 2, true),
            conv("down2.1", b, b, 3, 1, true),
            conv("down3.0", b, c, 3, 2, true),
            conv("down3.1", c, c, 3, 1, true),
            conv("down3.2", c, c, 3, 1, true),
            conv("down4.0", c, d, 3, 2, true),
            conv("down4.1", d, d, 3, 1, true),
            conv("lat4", d, f, 1, 1, false),
            conv("lat3", c, f, 1, 1, false),
            conv("lat2", b, f, 1, 1, false),
            conv("smooth3", f, f, 3, 1, true),
            conv("smooth2", f, f, 3, 1, true),
            conv("heat", f, LANDMARK_NAMES.len(), 1, 1, false),
            ("head.0".into(), "dense", d, 64, 0, 0, true),
            ("head.1".into(), "dense", 64, 2, 0, 0, false),
        ])
    }

    /// Side of the crop the network takes, pixels.
    pub fn size(&self) -> usize {
        self.size
    }

    /// How many eye distances the crop's side spans (see [`super::CROP_EYE_DISTANCES`]); the
    /// network was trained on crops of this geometry.
    pub(crate) fn crop_eye_distances(&self) -> f64 {
        self.crop_eye_distances
    }

    /// How far above the crop's centre the eyes' midpoint sits, eye distances.
    pub(crate) fn eyes_above_centre(&self) -> f64 {
        self.eyes_above_centre
    }

    /// Runs the network on a `size x size` crop of grey levels (0-255, row-major).
    ///
    /// The activations are not allocated again once `ws` has grown to the network's sizes (see
    /// [`Workspace`] for the matrix product's own small buffers).
    ///
    /// # Panics
    /// If `crop` does not hold `size * size` values (a caller's bug, not a data error).
    pub fn run(&self, crop: &[f32], ws: &mut Workspace) -> NetOutput {
        #[cfg(feature = "dev")]
        RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let n = self.size;
        assert_eq!(crop.len(), n * n, "crop of the network's size");
        // Standardise as the trainer does: grey levels over 255, zero mean, unit spread (floor
        // 0.01).
        let count = (n * n) as f64;
        let mean = crop.iter().map(|&v| f64::from(v)).sum::<f64>() / count / 255.0;
        let var = crop
            .iter()
            .map(|&v| (f64::from(v) / 255.0 - mean).powi(2))
            .sum::<f64>()
            / count;
        let scale = 1.0 / (var.sqrt() + 0.01);
        ws.input.resize(1, n, n);
        for (o, &v) in ws.input.data.iter_mut().zip(crop) {
            *o = ((f64::from(v) / 255.0 - mean) * scale) as f32;
        }
        let Workspace {
            input,
            stages,
            scratch,
            pyramid,
            heat,
            im2col,
            pooled,
            hidden,
            head,
            ..
        } = ws;
        let c = &self.convs;
        let [s1, s2, s3, s4] = stages;
        let [t0, t1] = scratch;
        // Trunk.
        conv(&c[0], input, t0, im2col);
        conv(&c[1], t0, s1, im2col);
        conv(&c[2], s1, t0, im2col);
        conv(&c[3], t0, s2, im2col);
        conv(&c[4], s2, t0, im2col);
        conv(&c[5], t0, t1, im2col);
        conv(&c[6], t1, s3, im2col);
        conv(&c[7], s3, t0, im2col);
        conv(&c[8], t0, s4, im2col);
        // Pyramid.
        let [p4, p3, p2] = pyramid;
        conv(&c[9], s4, p4, im2col);
        conv(&c[10], s3, t0, im2col);
        add_upsampled(t0, p4);
        conv(&c[12], t0, p3, im2col);
        conv(&c[11], s2, t0, im2col);
        add_upsampled(t0, p3);
        conv(&c[13], t0, p2, im2col);
        conv(&c[14], p2, heat, im2col);
        // Shear from the last stage, averaged over space.
        pooled.clear();
        pooled.extend(
            s4.data
                .chunks_exact(s4.height * s4.width)
                .map(|ch| ch.iter().sum::<f32>() / ch.len() as f32),
        );
        dense(&self.dense[0], pooled, hidden);
        dense(&self.dense[1], hidden, head);
        let (points, spread) = decode(heat, n);
        NetOutput {
            points,
            spread,
            shear: f64::from(head[0]),
            face: 1.0 / (1.0 + (-f64::from(head[1])).exp()),
            face_logit: f64::from(head[1]),
        }
    }

    /// [`Self::run`] on `crop` averaged with its reading of the crop mirrored left to right,
    /// taken back (the eyes swap, the shear changes sign): the trainer mirrors crops at random,
    /// so both readings are equally good, and their errors partly cancel.
    #[cfg(test)]
    pub(crate) fn run_mirrored(&self, crop: &[f32], ws: &mut Workspace) -> NetOutput {
        let direct = self.run(crop, ws);
        self.averaged_with_mirrored(direct, crop, ws)
    }

    /// `direct`, the network's reading of `crop` as it is, averaged with its reading of the crop
    /// mirrored left to right, taken back (the eyes swap, the shear changes sign): the trainer
    /// mirrors crops at random, so both readings are equally good, and their errors partly
    /// cancel.
    pub(crate) fn averaged_with_mirrored(
        &self,
        direct: NetOutput,
        crop: &[f32],
        ws: &mut Workspace,
    ) -> NetOutput {
        let n = self.size;
        let mut mirrored = std::mem::take(&mut ws.mirrored);
        mirrored.clear();
        for row in crop.chunks_exact(n) {
            mirrored.extend(row.iter().rev());
        }
        let m = self.run(&mirrored, ws);
        ws.mirrored = mirrored;
        let back = |p: Point| Point::new((n - 1) as f64 - p.x, p.y);
        let swapped = [
            back(m.points[1]),
            back(m.points[0]),
            back(m.points[2]),
            back(m.points[3]),
        ];
        let spread = [m.spread[1], m.spread[0], m.spread[2], m.spread[3]];
        let mean = |a: f64, b: f64| 0.5 * (a + b);
        let face_logit = mean(direct.face_logit, m.face_logit);
        NetOutput {
            points: std::array::from_fn(|i| direct.points[i].midpoint(swapped[i])),
            spread: std::array::from_fn(|i| mean(direct.spread[i], spread[i])),
            shear: mean(direct.shear, -m.shear),
            face: 1.0 / (1.0 + (-face_logit).exp()),
            face_logit,
        }
    }
}

/// Each heatmap's spatial softmax, its expectation (the point, in crop pixels) and spread.
fn decode(heat: &Tensor, size: usize) -> ([Point; 4], [f64; 4]) {
    let (h, w) = (heat.height, heat.width);
    let stride = size as f64 / w as f64;
    let mut points = [Point::default(); 4];
    let mut spread = [0.0; 4];
    for (l, map) in heat.data.chunks_exact(h * w).take(4).enumerate() {
        let max = map.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let (mut total, mut sx, mut sy, mut sxx, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for (i, &v) in map.iter().enumerate() {
            let p = f64::from(v - max).exp();
            let x = ((i % w) as f64 + 0.5) * stride - 0.5;
            let y = ((i / w) as f64 + 0.5) * stride - 0.5;
            total += p;
            sx += p * x;
            sy += p * y;
            sxx += p * x * x;
            syy += p * y * y;
        }
        let (mx, my) = (sx / total, sy / total);
        points[l] = Point::new(mx, my);
        spread[l] = ((sxx / total - mx * mx) + (syy / total - my * my))
            .max(0.0)
            .sqrt();
    }
    (points, spread)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoding_finds_a_sharp_peak_and_the_middle_of_two() {
        let mut heat = Tensor::default();
        heat.resize(4, 8, 8);
        heat.data.fill(-50.0);
        // Landmark 0: one sharp cell at (5, 2); landmark 1: two equal cells at (1, 3) and (3, 3).
        heat.data[2 * 8 + 5] = 50.0;
        heat.data[64 + 3 * 8 + 1] = 50.0;
        heat.data[64 + 3 * 8 + 3] = 50.0;
        let (points, spread) = decode(&heat, 32);
        // Stride 4: cell i's centre is at 4 i + 1.5.
        assert!(points[0].distance(Point::new(21.5, 9.5)) < 1e-9);
        assert!(spread[0] < 1e-6);
        assert!(points[1].distance(Point::new(9.5, 13.5)) < 1e-9);
        assert!((spread[1] - 4.0).abs() < 1e-9);
    }

    /// The forward pass here gives what the trainer's (PyTorch) gave on the check crop stored
    /// in the file (loading checks it too, to `CHECK_TOLERANCE`; this asks for 100 times less).
    #[test]
    fn the_embedded_network_reproduces_the_trainers_check() {
        let net = LandmarkNet::embedded().expect("embedded network");
        assert!(net.check_deviation() < 1e-4, "{}", net.check_deviation());
        // The workspace is reused: a second run gives the same.
        let n = net.size();
        let crop: Vec<f32> = (0..n * n).map(|i| ((i * 7) % 251) as f32).collect();
        let mut ws = Workspace::default();
        let out = net.run(&crop, &mut ws);
        assert_eq!(net.run(&crop, &mut ws), out);
    }

    /// The mirrored reading is symmetric: reading the crop mirrored gives the same face
    /// mirrored (eyes swapped, shear negated, same face score), to rounding.
    #[test]
    fn a_mirrored_crop_reads_as_the_same_face_mirrored() {
        let net = LandmarkNet::embedded().expect("embedded network");
        let n = net.size();
        let crop: Vec<f32> = (0..n * n).map(|i| ((i * 7) % 251) as f32).collect();
        let flipped: Vec<f32> = crop
            .chunks_exact(n)
            .flat_map(|r| r.iter().rev().copied())
            .collect();
        let mut ws = Workspace::default();
        let a = net.run_mirrored(&crop, &mut ws);
        let b = net.run_mirrored(&flipped, &mut ws);
        let back = |p: Point| Point::new((n - 1) as f64 - p.x, p.y);
        for (i, j) in [(0, 1), (1, 0), (2, 2), (3, 3)] {
            assert!(
                a.points[i].distance(back(b.points[j])) < 1e-4,
                "{a:?} {b:?}"
            );
        }
        assert!((a.shear + b.shear).abs() < 1e-6 && (a.face_logit - b.face_logit).abs() < 1e-6);
    }

    #[test]
    fn a_network_whose_weights_were_changed_fails_its_check() {
        let mut changed = EMBEDDED.to_vec();
        // The last weight of the head's output layer (the face logit's bias) moves it by 0.5.
        let last = changed.len() - 4;
        let bias = f32::from_le_bytes([
            changed[last],
            changed[last + 1],
            changed[last + 2],
            changed[last + 3],
        ]);
        changed[last..].copy_from_slice(&(bias + 0.5).to_le_bytes());
        assert!(matches!(
            LandmarkNet::from_bytes(&changed),
            Err(Error::ModelFile(_))
        ));
    }

    #[test]
    fn malformed_files_are_refused() {
        let good = EMBEDDED;
        assert!(LandmarkNet::from_bytes(&good[..good.len() - 4]).is_err());
        assert!(LandmarkNet::from_bytes(b"UNSHEARF").is_err());
        let mut extra = good.to_vec();
        extra.extend_from_slice(&[0, 0, 0, 0]);
        assert!(LandmarkNet::from_bytes(&extra).is_err());
        let mut bad_version = good.to_vec();
        bad_version[8] = 9;
        assert!(LandmarkNet::from_bytes(&bad_version).is_err());
        let mut nan = good.to_vec();
        let last = nan.len() - 4;
        nan[last..].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(LandmarkNet::from_bytes(&nan).is_err());
    }
}
