//! The small convolutional networks' building blocks, shared by the landmark network
//! (`locate::network`) and the face proposal classifier (`detect::proposals`): activations,
//! convolutions through im2col and one `gemm` product, bias and ReLU, dense layers.
//!
//! Written by hand rather than with an inference crate: the networks are a dozen small
//! convolutions, which im2col and one matrix product each run at the speed of a general matrix
//! product, while a framework would add most of this crate's build time for no gain.

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

/// `layer` applied to `input` into `output` (resized), through im2col and one matrix product,
/// with the "same" zero padding of `kernel / 2` the network was trained with.
pub(crate) fn conv(layer: &Conv, input: &Tensor, output: &mut Tensor, buffers: &mut Im2col) {
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
/// channels are its columns.
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
pub(crate) fn add_upsampled(target: &mut Tensor, low: &Tensor) {
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
pub(crate) fn dense(layer: &Conv, input: &[f32], output: &mut Vec<f32>) {
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
}
