#!/usr/bin/env python3
"""Trains the face proposal classifier (`src/detect/proposals.rs`) on the windows that
`cargo run --release --example proposal_crops` cuts, and writes the weights in the format that
module reads.

    python3 -m venv target/torch
    target/torch/bin/pip install -r scripts/requirements-train.txt
    cargo run --release --example proposal_crops -- ../shared/data/caltech-webfaces target/proposal-crops
    target/torch/bin/python scripts/train_proposals.py target/proposal-crops -o target/proposals.bin --epochs 14

`scripts/regenerate-models --only proposals` runs these with the committed file's options.

The classifier: five unpadded 3x3/4x4 convolutions with ReLU and a 1x1 output, taking a 32x32
window (the landmark crop's geometry at a third of its size: 3.3 eye distances across) to one
logit, "this window shows a face at this place and size". Without padding, the same layers run
over a whole pyramid level give, every 4th pixel, exactly the window's score.

Training: binary cross-entropy, Adam with a one-cycle schedule; the windows mirrored at random,
with random gamma, contrast, brightness and noise. 5% of the windows are held out and the
recall / false-positive trade-off on them is printed after every epoch, and the final shares at
logit 0 are recorded in the file's header (`held_out`). Everything is seeded and torch runs
deterministic kernels on two threads, so the same windows, the same tool versions and the same
CPU give the same weights; the header records the versions, the CPU, the seed and the command
(`provenance.py`).
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import time
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from provenance import provenance
from torch import nn


class Net(nn.Module):
    """The classifier: unpadded convolutions from a window to one logit."""

    def __init__(self, widths: list[int]) -> None:
        super().__init__()
        a, b, c, d, e = widths
        self.convs = nn.ModuleList(
            [
                nn.Conv2d(1, a, 4, 2),  # 32 -> 15
                nn.Conv2d(a, b, 3, 1),  # 13
                nn.Conv2d(b, c, 3, 2),  # 6
                nn.Conv2d(c, d, 3, 1),  # 4
                nn.Conv2d(d, e, 4, 1),  # 1
                nn.Conv2d(e, 1, 1),
            ]
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        last = len(self.convs) - 1
        for i, layer in enumerate(self.convs):
            x = layer(x)
            if i < last:
                x = F.relu(x)
        return x.flatten()


def scaled(x: torch.Tensor) -> torch.Tensor:
    """The scaling `src/detect/proposals.rs` applies: grey levels over 255, centred, times 4."""
    return (x - 0.5) * 4.0


def augment(x: torch.Tensor) -> torch.Tensor:
    """Random gamma, contrast, brightness, mirror and noise on a batch of windows in 0..1."""
    b = x.shape[0]
    gamma = torch.exp(torch.randn(b, 1, 1, 1) * 0.25)
    x = x.clamp(1e-4, 1) ** gamma
    x = (x - 0.5) * torch.exp(torch.randn(b, 1, 1, 1) * 0.3) + 0.5 + torch.randn(b, 1, 1, 1) * 0.1
    flip = torch.rand(b) < 0.5
    x[flip] = x[flip].flip(-1)
    return x + torch.randn_like(x) * 0.02 * torch.rand(b, 1, 1, 1)


def write(net: Net, path: str, window: int, meta: dict[str, Any]) -> None:
    """Writes the weights: magic `UNSHEARP`, u32 version 1, u32 header length, the JSON header
    (`meta`, the window side, the check logit and the layer shapes), then every layer's weights
    and bias as little-endian f32."""
    layers: list[dict[str, Any]] = []
    blob = b""
    last = len(net.convs) - 1
    for i, layer in enumerate(net.convs):
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
    # The logit on a fixed synthetic window (pixel i has grey level (i * 31) % 255), which the
    # reader recomputes to check its forward pass and the file.
    pattern = torch.tensor([(i * 31) % 255 for i in range(window * window)], dtype=torch.float32)
    with torch.no_grad():
        check = net(scaled(pattern.reshape(1, 1, window, window) / 255.0)).item()
    header = json.dumps(
        {**meta, "window": window, "check_logit": check, "layers": layers}, sort_keys=True
    ).encode()
    with open(path + ".tmp", "wb") as f:
        f.write(b"UNSHEARP" + struct.pack("<II", 1, len(header)) + header + blob)
    os.replace(path + ".tmp", path)


def held_out_logits(net: Net, xt: torch.Tensor, held: np.ndarray) -> torch.Tensor:
    """The network's logits on the held-out windows."""
    net.eval()
    with torch.no_grad():
        return torch.cat(
            [
                net(scaled(xt[torch.from_numpy(held[i : i + 4096])].float() / 255.0))
                for i in range(0, len(held), 4096)
            ]
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("crops", help="directory written by the proposal_crops example")
    parser.add_argument("-o", "--out", required=True)
    parser.add_argument("--widths", default="12,16,24,32,48")
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    torch.set_num_threads(2)
    torch.use_deterministic_algorithms(True)

    with open(os.path.join(args.crops, "meta.json"), encoding="utf-8") as f:
        meta = json.load(f)
    window = meta["size"]
    x = np.fromfile(os.path.join(args.crops, "crops.u8"), dtype=np.uint8).reshape(
        -1, 1, window, window
    )
    y = np.fromfile(os.path.join(args.crops, "labels.u8"), dtype=np.uint8).astype(np.float32)
    order = np.random.permutation(len(y))
    held, train = order[: len(y) // 20], order[len(y) // 20 :]
    xt, yt = torch.from_numpy(x), torch.from_numpy(y)

    net = Net([int(w) for w in args.widths.split(",")])
    opt = torch.optim.Adam(net.parameters(), 2e-3)
    batch = 256
    steps = args.epochs * (len(train) // batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 3e-3, total_steps=steps)
    start = time.time()
    for epoch in range(args.epochs):
        net.train()
        perm = train[np.random.permutation(len(train))]
        total = 0.0
        for i in range(0, len(perm) - batch + 1, batch):
            b = torch.from_numpy(perm[i : i + batch])
            out = net(scaled(augment(xt[b].float() / 255.0)))
            loss = F.binary_cross_entropy_with_logits(out, yt[b])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item()
        logits = held_out_logits(net, xt, held)
        labels = yt[torch.from_numpy(held)]
        pos = logits[labels > 0.5].sort().values
        neg = logits[labels < 0.5]
        report = []
        for recall in (0.95, 0.98, 0.99):
            threshold = pos[int((1 - recall) * len(pos))].item()
            fpr = (neg > threshold).float().mean().item()
            report.append(f"recall {recall}: logit {threshold:.2f}, false positives {fpr:.4f}")
        share0 = (pos >= 0).float().mean().item()
        fpr0 = (neg >= 0).float().mean().item()
        print(
            f"epoch {epoch}: loss {total / (len(perm) // batch):.4f}, {time.time() - start:.0f} s; "
            + "; ".join(report)
            + f"; at logit 0: recall {share0:.4f}, false positives {fpr0:.4f}",
            flush=True,
        )
    summary = {
        "trained_on": args.crops,
        "windows": len(train),
        "epochs": args.epochs,
        "widths": [int(w) for w in args.widths.split(",")],
        "held_out": {
            "windows": len(held),
            "faces_at_logit_0": round(share0, 6),
            "others_at_logit_0": round(fpr0, 6),
        },
        **provenance(args.seed),
    }
    write(net, args.out, window, summary)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
