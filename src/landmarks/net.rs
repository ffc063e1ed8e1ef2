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
//! general matrix product, while a framework (candle: 157 crates, measured 12.5 ms for a network
//! of this size; tract: ONNX parsing at run time) would add most of this crate's build time for
//! no gain. The file format is documented on [`LandmarkNet::from_bytes`].

use serde::Deserialize;

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::modelfile::ModelFile;

/// Landmarks the network locates, in this order.
pub const LANDMARK_NAMES: [&str; 4] = ["right_eye", "left_eye", "nose", "mouth"];

/// The file's magic bytes.
const MAGIC: &[u8; 8] = b"UNSHEARN";

/// The file format version this build reads.
const VERSION: u32 = 1;

/// How far (crop pixels, or shear) a loaded network's output on the check crop may be from what
/// its trainer recorded: float rounding in another order of summation stays far below this, a
/// wrong layer, stride or layout far above.
const CHECK_TOLERANCE: f64 = 0.01;

/// The committed network (`models/landmarks.bin`).
static EMBEDDED: &[u8] = include_bytes!("../../models/landmarks.bin");

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

/// One convolution (or dense layer: a 1x1 convolution of a 1x1 input); also the face proposal
/// classifier's layers (`detect::proposals`).
#[derive(Debug, Clone)]
pub(crate) struct Conv {
    pub(crate) inputs: usize,
    pub(crate) outputs: usize,
    pub(crate) kernel: usize,
    pub(crate) stride: usize,
    pub(crate) relu: bool,
    /// `outputs x (inputs * kernel * kernel)`, row-major (PyTorch's layout).
    pub(crate) weight: Vec<f32>,
    pub(crate) bias: Vec<f32>,
}

/// A `channels x height x width` activation (also the face proposal classifier's,
/// `detect::proposals`).
#[derive(Debug, Clone, Default)]
pub(crate) struct Tensor {
    pub(crate) data: Vec<f32>,
    pub(crate) channels: usize,
    pub(crate) height: usize,
    pub(crate) width: usize,
}

impl Tensor {
    /// Sets the shape; the buffer only grows.
    pub(crate) fn resize(&mut self, channels: usize, height: usize, width: usize) {
        self.channels = channels;
        self.height = height;
        self.width = width;
        self.data.resize(channels * height * width, 0.0);
    }
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
/// `gemm` crate still allocates small packing buffers inside some products: 20 allocations per
/// forward pass, in a one-off count with a counting global allocator, not kept
/// (`matrixmultiply` before it made 15). Against a pass of about 0.8 ms they do not show.
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
}

/// What the network reads off one crop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetOutput {
    /// Right eye, left eye, nose, mouth, in crop pixels (pixel centres at integers).
    pub points: [Point; 4],
    /// How widely each heatmap's probability is spread about its point (the root of the
    /// summed variances, crop pixels): small when the network is sure.
    pub spread: [f64; 4],
    /// The crop's shear as the network reads it (see [`super::crop_shear`]).
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
    pub fn crop_eye_distances(&self) -> f64 {
        self.crop_eye_distances
    }

    /// How far above the crop's centre the eyes' midpoint sits, eye distances.
    pub fn eyes_above_centre(&self) -> f64 {
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
}

/// `layer` applied to `input` into `output` (resized), through im2col and one matrix product,
/// with the "same" zero padding of `kernel / 2` the network was trained with.
fn conv(layer: &Conv, input: &Tensor, output: &mut Tensor, buffers: &mut Im2col) {
    conv_padded(layer, input, output, buffers, layer.kernel / 2);
}

/// [`conv`] with a zero border `pad` wide (0: an unpadded convolution, as the face proposal
/// classifier's).
pub(crate) fn conv_padded(
    layer: &Conv,
    input: &Tensor,
    output: &mut Tensor,
    buffers: &mut Im2col,
    pad: usize,
) {
    debug_assert_eq!(input.channels, layer.inputs);
    let (k, s) = (layer.kernel, layer.stride);
    let (h, w) = (input.height, input.width);
    let ho = (h + 2 * pad - k) / s + 1;
    let wo = (w + 2 * pad - k) / s + 1;
    output.resize(layer.outputs, ho, wo);
    let plane = ho * wo;
    let depth = layer.inputs * k * k;
    let source: &[f32] = if k == 1 && s == 1 {
        &input.data
    } else {
        im2col(layer, input, (ho, wo), pad, buffers)
    };
    matmul(
        &layer.weight,
        source,
        &mut output.data,
        layer.outputs,
        depth,
        plane,
    );
    add_bias(&mut output.data, plane, &layer.bias, layer.relu);
}

/// Adds each channel's bias to its `plane` values of `data`, then the ReLU if `relu`.
///
/// Also compiled for AVX2, chosen at run time (the same operations per value, so the same bits).
#[multiversion::multiversion(targets("x86_64+avx2"))]
pub(crate) fn add_bias(data: &mut [f32], plane: usize, bias: &[f32], relu: bool) {
    for (o, b) in data.chunks_exact_mut(plane).zip(bias) {
        for v in o.iter_mut() {
            *v += b;
            if relu && *v < 0.0 {
                *v = 0.0;
            }
        }
    }
}

/// The buffers of [`im2col`]: the input with its zero border, and the column matrix.
#[derive(Debug, Clone, Default)]
pub(crate) struct Im2col {
    padded: Vec<f32>,
    columns: Vec<f32>,
}

/// The im2col matrix of `input` for `layer` (output `ho x wo`): row `(ci * k + ky) * k + kx`
/// holds, for each output pixel, the input value under kernel tap `(ky, kx)` of channel `ci`,
/// zero where the tap falls in the padding.
///
/// The input is first copied into a buffer with a zero border `pad` wide and each row split
/// by column phase (for stride `s`, the columns `0, s, 2s, ...`, then `1, s + 1, ...`, and so
/// on), so that every row of every tap is one contiguous copy with no test for the border. With
/// the border tested per row and strided reads, this copy took about a third of a forward
/// pass, more than half as long as the matrix products. The matrix is the same, value for
/// value.
///
/// Also compiled for AVX2, chosen at run time (the same operations per value, so the same bits).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn im2col<'a>(
    layer: &Conv,
    input: &Tensor,
    (ho, wo): (usize, usize),
    pad: usize,
    buffers: &'a mut Im2col,
) -> &'a [f32] {
    let (k, s) = (layer.kernel, layer.stride);
    let (h, w) = (input.height, input.width);
    let hp = h + 2 * pad;
    // Each padded row is `s` phases of `phase_len` values; padded column `x` is value `x / s`
    // of phase `x % s`.
    let phase_len = (w + 2 * pad).div_ceil(s);
    let row_len = s * phase_len;
    let Im2col { padded, columns } = buffers;
    // Grown, never shrunk: every value in use is written below (the border's zeros too), so
    // nothing is cleared that is not needed.
    let padded_len = layer.inputs * hp * row_len;
    if padded.len() < padded_len {
        padded.resize(padded_len, 0.0);
    }
    for (channel, padded_channel) in input
        .data
        .chunks_exact(h * w)
        .zip(padded[..padded_len].chunks_exact_mut(hp * row_len))
    {
        let (top, rest) = padded_channel.split_at_mut(pad * row_len);
        let (middle, bottom) = rest.split_at_mut(h * row_len);
        top.fill(0.0);
        bottom.fill(0.0);
        for (row, padded_row) in channel
            .chunks_exact(w)
            .zip(middle.chunks_exact_mut(row_len))
        {
            padded_row.fill(0.0);
            if s == 1 {
                padded_row[pad..pad + w].copy_from_slice(row);
                continue;
            }
            for (phase, phase_row) in padded_row.chunks_exact_mut(phase_len).enumerate() {
                // The first input column whose padded column `x + pad` has this phase.
                let first = (phase + s - pad % s) % s;
                let Some(values) = row.get(first..) else {
                    continue;
                };
                let at = (first + pad) / s;
                deinterleave(&mut phase_row[at..], values, s);
            }
        }
    }
    let plane = ho * wo;
    let depth = layer.inputs * k * k;
    if columns.len() < depth * plane {
        columns.resize(depth * plane, 0.0);
    }
    // Row `(ci, ky, kx)` of the matrix, output row `oy`, holds padded row `oy * s + ky` of
    // channel `ci` from column `kx` on, every `s`-th value: `wo` values of phase `kx % s` from
    // `kx / s` on.
    let mut column_rows = columns[..depth * plane].chunks_exact_mut(plane);
    for padded_channel in padded[..padded_len].chunks_exact(hp * row_len) {
        for ky in 0..k {
            for kx in 0..k {
                let Some(column_row) = column_rows.next() else {
                    break;
                };
                let mut start = ky * row_len + (kx % s) * phase_len + kx / s;
                for out_row in column_row.chunks_exact_mut(wo) {
                    copy_short(out_row, &padded_channel[start..start + wo]);
                    start += s * row_len;
                }
            }
        }
    }
    &columns[..depth * plane]
}

/// `dst[i] = src[i * step]` for as many values as both allow. A step of 2 (the network's
/// strided convolutions) has its own loop with the step known to the compiler: the general
/// `step_by` loop, which the old copy used, recomputes its bounds for every value.
fn deinterleave(dst: &mut [f32], src: &[f32], step: usize) {
    if step == 2 {
        for (d, pair) in dst.iter_mut().zip(src.chunks(2)) {
            *d = pair[0];
        }
    } else {
        for (d, &v) in dst.iter_mut().zip(src.iter().step_by(step)) {
            *d = v;
        }
    }
}

/// `dst = src` for the short rows of [`im2col`] (6 to 48 values for the built-in network), in
/// blocks of 8 whose length the compiler knows: `copy_from_slice` calls `memcpy`, whose call
/// cost dominates a copy this short.
fn copy_short(dst: &mut [f32], src: &[f32]) {
    debug_assert_eq!(dst.len(), src.len());
    let mut dst_blocks = dst.chunks_exact_mut(8);
    let mut src_blocks = src.chunks_exact(8);
    for (d, s) in (&mut dst_blocks).zip(&mut src_blocks) {
        d.copy_from_slice(s);
    }
    let (dst_rest, src_rest) = (dst_blocks.into_remainder(), src_blocks.remainder());
    if dst_rest.len() >= 4 {
        dst_rest[..4].copy_from_slice(&src_rest[..4]);
    }
    let done = dst_rest.len() / 4 * 4;
    for (d, &s) in dst_rest[done..].iter_mut().zip(&src_rest[done..]) {
        *d = s;
    }
}

/// `c = a b` for row-major `a` (`m x k`), `b` (`k x n`) and `c` (`m x n`).
///
/// Computed as `c^T = b^T a^T`, so that the pixels (thousands) are `gemm`'s row dimension,
/// along which its micro-kernels are tiled several SIMD vectors deep, and the few output
/// channels are its columns. With the `gemm` crate so, one forward pass took 0.81-0.83 ms
/// instead of the 1.00-1.03 ms of the `matrixmultiply` crate used before (criterion, the two
/// builds one after the other in both orders; README, *Performance*).
pub(crate) fn matmul(a: &[f32], b: &[f32], c: &mut [f32], m: usize, k: usize, n: usize) {
    assert!(a.len() >= m * k && b.len() >= k * n && c.len() >= m * n);
    // `gemm` computes dst = alpha dst + beta lhs rhs and takes each column stride before the
    // row stride; with `read_dst` false, alpha (0) is not used and dst is overwritten.
    // SAFETY: the assertion bounds every element gemm reads and writes. In gemm's terms (element
    // (i, j) at i * row stride + j * column stride) the destination is n x m with strides (1, n),
    // which is `c` row-major m x n; the left operand is n x k with strides (1, n), `b` row-major
    // k x n; the right operand is k x m with strides (1, k), `a` row-major m x k. `c` is
    // borrowed mutably, so it overlaps neither input.
    unsafe {
        gemm::gemm(
            n,
            m,
            k,
            c.as_mut_ptr(),
            n as isize,
            1,
            false,
            b.as_ptr(),
            n as isize,
            1,
            a.as_ptr(),
            k as isize,
            1,
            0.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// `target += nearest-neighbour 2x upsampling of low` (the pyramid's merge).
///
/// Also compiled for AVX2, chosen at run time (the same operations per value, so the same bits).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn add_upsampled(target: &mut Tensor, low: &Tensor) {
    debug_assert_eq!(target.channels, low.channels);
    let (h, w) = (target.height, target.width);
    for c in 0..target.channels {
        let t = &mut target.data[c * h * w..(c + 1) * h * w];
        let l = &low.data[c * low.height * low.width..(c + 1) * low.height * low.width];
        for y in 0..h {
            let ly = (y / 2).min(low.height - 1);
            for x in 0..w {
                t[y * w + x] += l[ly * low.width + (x / 2).min(low.width - 1)];
            }
        }
    }
}

/// A dense layer on a vector, into `output` (cleared first).
fn dense(layer: &Conv, input: &[f32], output: &mut Vec<f32>) {
    output.clear();
    output.extend(
        layer
            .weight
            .chunks_exact(layer.inputs)
            .zip(&layer.bias)
            .map(|(row, b)| {
                let v = row.iter().zip(input).map(|(w, x)| w * x).sum::<f32>() + b;
                if layer.relu {
                    v.max(0.0)
                } else {
                    v
                }
            }),
    );
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

    fn layer(inputs: usize, outputs: usize, kernel: usize, stride: usize, relu: bool) -> Conv {
        let n = outputs * inputs * kernel * kernel;
        Conv {
            inputs,
            outputs,
            kernel,
            stride,
            relu,
            weight: (0..n)
                .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.5)
                .collect(),
            bias: (0..outputs).map(|i| i as f32 * 0.1 - 0.05).collect(),
        }
    }

    fn tensor(channels: usize, height: usize, width: usize) -> Tensor {
        Tensor {
            data: (0..channels * height * width)
                .map(|i| ((i * 104729) % 17) as f32 / 17.0 - 0.3)
                .collect(),
            channels,
            height,
            width,
        }
    }

    /// The direct definition of a zero-padded convolution, for checking the im2col path.
    fn conv_direct(l: &Conv, x: &Tensor) -> Tensor {
        let pad = l.kernel / 2;
        let ho = (x.height + 2 * pad - l.kernel) / l.stride + 1;
        let wo = (x.width + 2 * pad - l.kernel) / l.stride + 1;
        let mut out = Tensor::default();
        out.resize(l.outputs, ho, wo);
        for co in 0..l.outputs {
            for oy in 0..ho {
                for ox in 0..wo {
                    let mut acc = l.bias[co];
                    for ci in 0..l.inputs {
                        for ky in 0..l.kernel {
                            for kx in 0..l.kernel {
                                let iy = (oy * l.stride + ky) as isize - pad as isize;
                                let ix = (ox * l.stride + kx) as isize - pad as isize;
                                if iy < 0
                                    || ix < 0
                                    || iy >= x.height as isize
                                    || ix >= x.width as isize
                                {
                                    continue;
                                }
                                let wv = l.weight
                                    [((co * l.inputs + ci) * l.kernel + ky) * l.kernel + kx];
                                acc += wv
                                    * x.data[(ci * x.height + iy as usize) * x.width + ix as usize];
                            }
                        }
                    }
                    out.data[(co * ho + oy) * wo + ox] = if l.relu { acc.max(0.0) } else { acc };
                }
            }
        }
        out
    }

    /// The im2col matrix by its definition, one value at a time.
    fn im2col_direct(l: &Conv, x: &Tensor, ho: usize, wo: usize) -> Vec<f32> {
        let (k, s, pad) = (l.kernel, l.stride, l.kernel / 2);
        let mut m = Vec::new();
        for ci in 0..l.inputs {
            for ky in 0..k {
                for kx in 0..k {
                    for oy in 0..ho {
                        for ox in 0..wo {
                            let iy = (oy * s + ky) as isize - pad as isize;
                            let ix = (ox * s + kx) as isize - pad as isize;
                            let inside = (0..x.height as isize).contains(&iy)
                                && (0..x.width as isize).contains(&ix);
                            m.push(if inside {
                                x.data[(ci * x.height + iy as usize) * x.width + ix as usize]
                            } else {
                                0.0
                            });
                        }
                    }
                }
            }
        }
        m
    }

    #[test]
    fn the_im2col_matrix_is_its_definition_value_for_value() {
        // One set of buffers for all shapes, large ones first, so that stale values of an
        // earlier, larger layer would show.
        let mut buffers = Im2col::default();
        for (ci, k, s, h, w) in [
            (3, 3, 1, 48, 48),
            (12, 3, 2, 24, 24),
            (2, 3, 2, 7, 5),
            (3, 3, 1, 7, 9),
            (2, 3, 2, 6, 6),
            (1, 3, 2, 1, 1),
            (2, 3, 1, 3, 1),
            (2, 5, 1, 6, 7),
            (2, 5, 3, 8, 11),
            (3, 1, 2, 5, 6),
            (1, 3, 3, 10, 10),
        ] {
            let l = layer(ci, 1, k, s, false);
            let x = tensor(ci, h, w);
            let pad = k / 2;
            let ho = (h + 2 * pad - k) / s + 1;
            let wo = (w + 2 * pad - k) / s + 1;
            let got = im2col(&l, &x, (ho, wo), pad, &mut buffers).to_vec();
            let want = im2col_direct(&l, &x, ho, wo);
            assert_eq!(got.len(), want.len(), "{ci} {k} {s} {h} {w}");
            for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "value {i} of {ci} {k} {s} {h} {w}"
                );
            }
        }
    }

    #[test]
    fn short_copies_and_strided_reads_copy_every_value() {
        let src: Vec<f32> = (0..40).map(|i| i as f32 + 0.5).collect();
        for len in 0..=20 {
            let mut dst = vec![-1.0; len];
            copy_short(&mut dst, &src[3..3 + len]);
            assert_eq!(dst, src[3..3 + len]);
        }
        for step in 1..=3 {
            for len in 0..=12 {
                let mut dst = vec![-1.0; len];
                deinterleave(&mut dst, &src[1..], step);
                let want: Vec<f32> = (0..len).map(|i| src[1 + i * step]).collect();
                assert_eq!(dst, want, "step {step}, {len} values");
            }
        }
    }

    #[test]
    fn convolutions_match_their_definition() {
        let mut buffers = Im2col::default();
        for (ci, co, k, s, h, w, relu) in [
            (1, 4, 3, 2, 12, 12, true),
            (3, 5, 3, 1, 7, 9, false),
            (4, 2, 1, 1, 5, 6, false),
            (2, 3, 3, 2, 7, 5, true),
            // Rows of one and two pixels: the padding covers all or most of each row.
            (2, 3, 3, 1, 3, 1, false),
            (2, 3, 3, 2, 2, 2, false),
            (1, 2, 3, 2, 1, 1, true),
        ] {
            let l = layer(ci, co, k, s, relu);
            let x = tensor(ci, h, w);
            let mut out = Tensor::default();
            conv(&l, &x, &mut out, &mut buffers);
            let want = conv_direct(&l, &x);
            assert_eq!(
                (out.channels, out.height, out.width),
                (want.channels, want.height, want.width)
            );
            for (a, b) in out.data.iter().zip(&want.data) {
                assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn upsampling_adds_each_low_pixel_to_its_two_by_two_block() {
        let low = Tensor {
            data: vec![1.0, 2.0, 3.0, 4.0],
            channels: 1,
            height: 2,
            width: 2,
        };
        let mut t = Tensor::default();
        t.resize(1, 4, 4);
        add_upsampled(&mut t, &low);
        assert_eq!(
            t.data,
            vec![1., 1., 2., 2., 1., 1., 2., 2., 3., 3., 4., 4., 3., 3., 4., 4.]
        );
    }

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
