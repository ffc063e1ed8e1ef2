#!/usr/bin/env python3
"""Trains the single-pass face detector (`ProposalNet::embedded_detector` in
`src/detect/proposals.rs`) on the windows that `cargo run --release --example detector_crops`
cuts, and writes the weights in the format that module reads (version 2).

    python3 -m venv target/torch
    target/torch/bin/pip install -r scripts/requirements-train.txt
    cargo run --release --example detector_crops -- --repeat 4 ../shared/data/caltech-webfaces target/detector-crops
    target/torch/bin/python scripts/train_detector.py target/detector-crops -o target/detector.bin --epochs 16

`scripts/regenerate-models --only detector` runs these with the committed file's options.

The detector: four unpadded 3x3 convolutions with ReLU (the first three of stride 2) and a
1x1 head, taking a 32x32 window (3.3 eye distances across, the landmark crop's geometry at a
third of its size) to six outputs: the face logit; the eyes' midpoint's offset `dx`, `dy` from
the window's expected one, in window eye distances; `log_scale`, the log of the face's eye
distance over the window's; the face's shear `k` and roll (radians). Without padding, the same
layers run over a whole pyramid level give every 8th pixel exactly the window's outputs.

Training: binary cross-entropy on the logit, smooth L1 on the regressions of the face windows
only (`--regression-weight`), Adam with a one-cycle schedule; the windows mirrored at random
(`dx`, `k` and the roll change sign), with random gamma, contrast, brightness and noise. The
windows of 10% of the photos are held out; after every epoch the recall and false-positive
shares on them and the regressions' errors are printed, and the final figures are recorded in
the file's header (`held_out`). Everything is seeded and torch runs deterministic kernels on two
threads, so the same windows, tool versions and CPU give the same weights; the header records
the versions, the CPU, the seed and the command (`provenance.py`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import time
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from provenance import provenance
from torch import nn

OUTPUTS = ["logit", "dx", "dy", "log_scale", "k", "roll"]
# What each regression target is divided by in the loss (about its spread over the faces),
# so that each weighs about alike.
TARGET_SCALE = [0.25, 0.25, 0.1, 0.3, 0.5]


class Net(nn.Module):
    """The detector: unpadded convolutions from a 32x32 window to the six outputs."""

    def __init__(self, widths: list[int]) -> None:
        super().__init__()
        a, b, c, d = widths
        self.convs = nn.ModuleList(
            [
                nn.Conv2d(1, a, 3, 2),  # 32 -> 15
                nn.Conv2d(a, b, 3, 2),  # 7
                nn.Conv2d(b, c, 3, 2),  # 3
                nn.Conv2d(c, d, 3, 1),  # 1
                nn.Conv2d(d, len(OUTPUTS), 1),
            ]
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        last = len(self.convs) - 1
        for i, layer in enumerate(self.convs):
            x = layer(x)
            if i < last:
                x = F.relu(x)
        return x.flatten(1)


def scaled(x: torch.Tensor) -> torch.Tensor:
    """The scaling `src/detect/proposals.rs` applies: grey levels over 255, centred, times 4."""
    return (x - 0.5) * 4.0


def augment(x: torch.Tensor, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Random gamma, contrast, brightness, mirror and noise on a batch of windows in 0..1; the
    mirror negates `dx`, `k` and the roll of the targets."""
    b = x.shape[0]
    gamma = torch.exp(torch.randn(b, 1, 1, 1) * 0.25)
    x = x.clamp(1e-4, 1) ** gamma
    x = (x - 0.5) * torch.exp(torch.randn(b, 1, 1, 1) * 0.3) + 0.5 + torch.randn(b, 1, 1, 1) * 0.1
    flip = torch.rand(b) < 0.5
    x[flip] = x[flip].flip(-1)
    t = t.clone()
    sign = torch.tensor([-1.0, 1.0, 1.0, -1.0, -1.0])
    t[flip] = t[flip] * sign
    return x + torch.randn_like(x) * 0.02 * torch.rand(b, 1, 1, 1), t


def write(net: Net, path: str, window: int, meta: dict[str, Any]) -> None:
    """Writes the weights: magic `UNSHEARP`, u32 version 2, u32 header length, the JSON header
    (`meta`, the window side, the output channels' names, the outputs on the check window and
    the layer shapes), then every layer's weights and bias as little-endian f32."""
    layers: list[dict[str, Any]] = []
    blob = b""
    convs = [c for c in net.convs if isinstance(c, nn.Conv2d)]
    last = len(convs) - 1
    for i, layer in enumerate(convs):
        assert layer.bias is not None
        layers.append(
            {
                "in": layer.in_channels,
                "out": layer.out_channels,
                "kernel": layer.kernel_size[0],
                "stride": layer.stride[0],
                "relu": i < last,
            }
        )
        blob += layer.weight.detach().numpy().astype("<f4").tobytes()
        blob += layer.bias.detach().numpy().astype("<f4").tobytes()
    # The outputs on a fixed synthetic window (pixel i has grey level (i * 31) % 255), which
    # the reader recomputes to check its forward pass and the file.
    pattern = torch.tensor([(i * 31) % 255 for i in range(window * window)], dtype=torch.float32)
    net.eval()
    with torch.no_grad():
        check = net(scaled(pattern.reshape(1, 1, window, window) / 255.0))[0].tolist()
    header = json.dumps(
        {
            **meta,
            "window": window,
            "outputs": OUTPUTS,
            "check_logit": check[0],
            "check_outputs": check,
            "layers": layers,
        },
        sort_keys=True,
    ).encode()
    with open(path + ".tmp", "wb") as f:
        f.write(b"UNSHEARP" + struct.pack("<II", 2, len(header)) + header + blob)
    os.replace(path + ".tmp", path)


def outputs_on(net: Net, xt: torch.Tensor, rows: np.ndarray) -> torch.Tensor:
    """The network's outputs on the given windows."""
    net.eval()
    with torch.no_grad():
        return torch.cat(
            [
                net(scaled(xt[torch.from_numpy(rows[i : i + 4096])].float() / 255.0))
                for i in range(0, len(rows), 4096)
            ]
        )


def evaluate(out: torch.Tensor, labels: torch.Tensor, targets: torch.Tensor) -> dict[str, float]:
    """Held-out figures: shares at logit 0, false positives at fixed recalls, and the
    regressions' errors on the face windows."""
    logit = out[:, 0]
    is_face = labels > 0.5
    pos, neg = logit[is_face], logit[~is_face]
    result: dict[str, float] = {
        "faces_at_logit_0": (pos >= 0).float().mean().item(),
        "others_at_logit_0": (neg >= 0).float().mean().item(),
    }
    ordered = pos.sort().values
    for recall in (0.98, 0.99):
        threshold = ordered[int((1 - recall) * len(ordered))].item()
        result[f"others_at_recall_{recall}"] = (neg >= threshold).float().mean().item()
    error = out[is_face, 1:] - targets[is_face]
    offset = error[:, :2].norm(dim=1)
    result["offset_median_ed"] = offset.median().item()
    result["offset_p95_ed"] = offset.quantile(0.95).item()
    result["log_scale_median"] = error[:, 2].abs().median().item()
    result["k_median"] = error[:, 3].abs().median().item()
    result["k_p90"] = error[:, 3].abs().quantile(0.9).item()
    result["roll_median_deg"] = math.degrees(error[:, 4].abs().median().item())
    result["roll_p90_deg"] = math.degrees(error[:, 4].abs().quantile(0.9).item())
    # Faces whose regressed eyes are within 0.25 eye distances and whose size within 20%.
    good = (offset < 0.25) & (error[:, 2].abs() < math.log(1.2))
    result["located_share"] = good.float().mean().item()
    result["found_and_located"] = (good & (pos >= 0)).float().mean().item()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("crops", help="directory written by the detector_crops example")
    parser.add_argument("-o", "--out", required=True)
    parser.add_argument("--widths", default="8,16,32,64")
    parser.add_argument("--epochs", type=int, default=16)
    parser.add_argument("--regression-weight", type=float, default=2.0)
    parser.add_argument("--scale-step", type=float, default=math.sqrt(2.0))
    parser.add_argument("--min-logit", type=float, default=0.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--batch", type=int, default=512)
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    torch.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)

    with open(os.path.join(args.crops, "meta.json"), encoding="utf-8") as f:
        meta = json.load(f)
    window = meta["size"]
    x = np.fromfile(os.path.join(args.crops, "crops.u8"), dtype=np.uint8).reshape(
        -1, 1, window, window
    )
    y = np.fromfile(os.path.join(args.crops, "labels.u8"), dtype=np.uint8).astype(np.float32)
    t = np.fromfile(os.path.join(args.crops, "targets.f32"), dtype="<f4").reshape(-1, 5)
    photo = np.fromfile(os.path.join(args.crops, "photos.u32"), dtype="<u4")
    # 10% of the photos held out (all their windows).
    photos = np.unique(photo)
    held_photos = np.random.permutation(photos)[: len(photos) // 10]
    is_held = np.isin(photo, held_photos)
    held, train = np.nonzero(is_held)[0], np.nonzero(~is_held)[0]
    xt, yt, tt = torch.from_numpy(x), torch.from_numpy(y), torch.from_numpy(t.copy())
    print(
        f"{len(train)} training windows ({int(y[train].sum())} faces), {len(held)} held out "
        f"({int(y[held].sum())} faces) from {len(held_photos)} of {len(photos)} photos",
        flush=True,
    )

    widths = [int(w) for w in args.widths.split(",")]
    net = Net(widths)
    opt = torch.optim.Adam(net.parameters(), 2e-3)
    batch = args.batch
    steps = args.epochs * (len(train) // batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 4e-3, total_steps=steps)
    scale = torch.tensor(TARGET_SCALE)
    start = time.time()
    figures: dict[str, float] = {}
    for epoch in range(args.epochs):
        net.train()
        perm = train[np.random.permutation(len(train))]
        total_bce, total_reg = 0.0, 0.0
        for i in range(0, len(perm) - batch + 1, batch):
            b = torch.from_numpy(perm[i : i + batch])
            xb, tb = augment(xt[b].float() / 255.0, tt[b])
            out = net(scaled(xb))
            labels = yt[b]
            bce = F.binary_cross_entropy_with_logits(out[:, 0], labels)
            face = labels > 0.5
            reg = F.smooth_l1_loss(out[face, 1:] / scale, tb[face] / scale, beta=0.5)
            loss = bce + args.regression_weight * reg
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total_bce += bce.item()
            total_reg += reg.item()
        n = len(perm) // batch
        figures = evaluate(outputs_on(net, xt, held), yt[held], tt[held])
        print(
            f"epoch {epoch}: bce {total_bce / n:.4f}, regression {total_reg / n:.4f}, "
            f"{time.time() - start:.0f} s; "
            + ", ".join(f"{k} {v:.4f}" for k, v in figures.items()),
            flush=True,
        )
    summary = {
        "trained_on": args.crops,
        "windows": len(train),
        "epochs": args.epochs,
        "batch": batch,
        "widths": widths,
        "regression_weight": args.regression_weight,
        "scale_step": args.scale_step,
        "min_logit": args.min_logit,
        "held_out": {
            "windows": len(held),
            "photos": len(held_photos),
            **{k: round(v, 6) for k, v in figures.items()},
        },
        **provenance(args.seed),
    }
    write(net, args.out, window, summary)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
