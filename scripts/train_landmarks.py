#!/usr/bin/env python3
"""Trains the landmark network (eyes, nose point, mouth centre, and the crop's shear) on the
crops that `cargo run --release --example landmark_crops` cuts, and writes the weights in the
format `src/locate/network/net.rs` reads.

    python3 -m venv target/torch
    target/torch/bin/pip install -r scripts/requirements-train.txt
    cargo run --release --example landmark_crops -- ../shared/data/caltech-webfaces target/landmark-crops
    target/torch/bin/python scripts/train_landmarks.py target/landmark-crops -o target/landmarks.bin

`scripts/regenerate-models --only landmarks` runs these with the committed file's options.
Everything is seeded (`--seed`), and torch runs deterministic CPU kernels, so the same crops,
the same tool versions and the same CPU give the same weights; the file's header records the
versions, the CPU, the seed and the command (`provenance.py`).

The network (`Net` below, mirrored by `src/locate/network/net.rs`): a strided convolutional trunk
(96 -> 48 -> 24 -> 12 -> 6 pixels), a feature pyramid back up to 24x24, one heatmap per
landmark there, read by a spatial softmax and its expectation (integral regression), and the
crop's shear and a face score (is there a face in the crop at all?) regressed from the pooled
6x6 features. Batch normalisation is folded into the
convolutions when the weights are written.

Training: crops mirrored at random (the eyes swap, the shear changes sign), with random gamma,
contrast, blur and noise; the loss is the landmarks' L1 error in eye distances plus the
shear's L1 error, plus a small pull of each heatmap towards a Gaussian at its label (keeps the
maps single-peaked), on the face crops, and the face score's cross-entropy on all crops
(non-face crops teach it). 10% of the faces (by face index) are held out and scored every epoch.

Shear-only crops (label `shear_only`, the extra faces whose points are pseudo-labels:
`landmark_crops --extra`) teach the shear and the face score only: the landmarks' L1 and heatmap
losses leave them out. The held-out scores recorded in the file (`held_out_scores`) are those of
the held-out Caltech faces and non-face crops, as without extra faces; the held-out extra faces'
shear and face scores are logged and recorded apart (`held_out_extra_scores`).
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import sys
import time
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from provenance import provenance
from torch import nn

LANDMARKS = 4  # right eye, left eye, nose, mouth


def conv_bn(cin: int, cout: int, stride: int = 1, k: int = 3) -> nn.Sequential:
    """A convolution without bias, batch normalisation and ReLU (folded into one convolution
    when written)."""
    return nn.Sequential(
        nn.Conv2d(cin, cout, k, stride, k // 2, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class Net(nn.Module):
    def __init__(
        self, widths: tuple[int, ...] = (16, 32, 64, 96), fpn: int = 32, size: int = 96
    ) -> None:
        super().__init__()
        a, b, c, d = widths
        self.size = size
        self.widths = widths
        self.fpn_width = fpn
        self.stem = nn.Sequential(conv_bn(1, a, 2), conv_bn(a, a))  # 48
        self.down2 = nn.Sequential(conv_bn(a, b, 2), conv_bn(b, b))  # 24
        self.down3 = nn.Sequential(conv_bn(b, c, 2), conv_bn(c, c), conv_bn(c, c))  # 12
        self.down4 = nn.Sequential(conv_bn(c, d, 2), conv_bn(d, d))  # 6
        self.lat4 = nn.Conv2d(d, fpn, 1)
        self.lat3 = nn.Conv2d(c, fpn, 1)
        self.lat2 = nn.Conv2d(b, fpn, 1)
        self.smooth3 = conv_bn(fpn, fpn)
        self.smooth2 = conv_bn(fpn, fpn)
        self.heat = nn.Conv2d(fpn, LANDMARKS, 1)
        # Two outputs from the pooled last stage: the crop's shear and the face score's logit.
        self.head = nn.Sequential(nn.Linear(d, 64), nn.ReLU(inplace=True), nn.Linear(64, 2))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        c1 = self.stem(x)
        c2 = self.down2(c1)
        c3 = self.down3(c2)
        c4 = self.down4(c3)
        p4 = self.lat4(c4)
        p3 = self.smooth3(self.lat3(c3) + F.interpolate(p4, scale_factor=2, mode="nearest"))
        p2 = self.smooth2(self.lat2(c2) + F.interpolate(p3, scale_factor=2, mode="nearest"))
        heat = self.heat(p2)
        out = self.head(c4.mean(dim=(2, 3)))
        return heat, out[:, 0], out[:, 1]


def standardize(x: torch.Tensor) -> torch.Tensor:
    """Each crop (grey levels over 255) to zero mean and unit spread; the floor of 0.01 keeps a
    flat crop finite. `net.rs` does the same."""
    m = x.mean(dim=(2, 3), keepdim=True)
    s = x.std(dim=(2, 3), keepdim=True, unbiased=False)
    return (x - m) / (s + 0.01)


def decode(heat: torch.Tensor, size: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Spatial softmax and expectation: points in crop pixels (pixel centres at integers)."""
    n, l, h, w = heat.shape
    stride = size / w
    p = F.softmax(heat.reshape(n, l, -1), dim=-1).reshape(n, l, h, w)
    xs = (torch.arange(w, dtype=heat.dtype) + 0.5) * stride - 0.5
    ys = (torch.arange(h, dtype=heat.dtype) + 0.5) * stride - 0.5
    x = (p.sum(dim=2) * xs).sum(-1)
    y = (p.sum(dim=3) * ys).sum(-1)
    return torch.stack([x, y], dim=-1), p


def gaussian_targets(
    points: torch.Tensor, h: int, w: int, size: int, sigma_cells: float = 1.0
) -> torch.Tensor:
    """One Gaussian map per landmark at its label (sigma one heatmap cell), summing to 1."""
    stride = size / w
    xs = (torch.arange(w, dtype=points.dtype) + 0.5) * stride - 0.5
    ys = (torch.arange(h, dtype=points.dtype) + 0.5) * stride - 0.5
    gx = torch.exp(-(((xs[None, None, :] - points[..., 0:1]) / stride) ** 2) / (2 * sigma_cells**2))
    gy = torch.exp(-(((ys[None, None, :] - points[..., 1:2]) / stride) ** 2) / (2 * sigma_cells**2))
    g = gy[..., :, None] * gx[..., None, :]
    return g / g.sum(dim=(-1, -2), keepdim=True).clamp_min(1e-12)


def augment(
    x: torch.Tensor, pts: torch.Tensor, shear: torch.Tensor, rng: np.random.Generator
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Random mirror and photometric changes, in place on a float batch (N,1,S,S)."""
    n, _, s, _ = x.shape
    flip = torch.from_numpy(rng.random(n) < 0.5)
    if flip.any():
        x[flip] = torch.flip(x[flip], dims=[3])
        p = pts[flip].clone()
        p[..., 0] = (s - 1) - p[..., 0]
        # The subject's right eye of the mirror is the left eye of the original.
        p = p[:, [1, 0, 2, 3]]
        pts[flip] = p
        shear[flip] = -shear[flip]
    x /= 255.0
    gamma = torch.from_numpy(np.exp(rng.normal(0, 0.25, n))).float()[:, None, None, None]
    x.clamp_(1e-4, 1).pow_(gamma)
    contrast = torch.from_numpy(np.exp(rng.normal(0, 0.3, n))).float()[:, None, None, None]
    x.mul_(contrast)
    # Blur some crops (a smaller or softer face), sigma up to 1.2 px.
    sig = rng.random(n) * 1.2
    for i in np.nonzero(rng.random(n) < 0.4)[0]:
        r = 3
        t = torch.arange(-r, r + 1, dtype=torch.float32)
        g = torch.exp(-(t**2) / (2 * max(sig[i], 0.3) ** 2))
        g /= g.sum()
        xi = x[i : i + 1]
        xi = F.conv2d(F.pad(xi, (r, r, 0, 0), mode="replicate"), g.view(1, 1, 1, -1))
        xi = F.conv2d(F.pad(xi, (0, 0, r, r), mode="replicate"), g.view(1, 1, -1, 1))
        x[i : i + 1] = xi
    noise = torch.from_numpy(rng.random(n) * 0.03).float()[:, None, None, None]
    x.add_(torch.randn_like(x) * noise)
    return x, pts, shear


def shear_and_roll(e: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Port of `estimate::shear_and_roll` (numpy, vectorised): k from eye line e and axis v."""
    ex, ey, vx, vy = e[:, 0], e[:, 1], v[:, 0], v[:, 1]
    no_roll = vx / np.where(vy == 0, np.nan, vy)
    a = ey * vy
    b = -(ex * vy + ey * vx)
    c = ex * vx + ey * vy
    disc = b * b - 4 * a * c
    sq = np.sqrt(np.maximum(disc, 0))
    q = -0.5 * (b + np.sign(b) * sq)
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = q / a
        r2 = np.where(q != 0, c / q, np.inf)
        lin = -c / b
        vertex = -b / (2 * a)
    k = np.where(np.abs(r1 - no_roll) <= np.abs(r2 - no_roll), r1, r2)
    k = np.where(disc < 0, vertex, k)
    k = np.where(np.abs(a) < 1e-12 * np.maximum(np.abs(b) + np.abs(c), 1e-300), lin, k)
    return k


def geometric_shear(p: np.ndarray, beta: float = 0.3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pipeline's shear-roll-yaw estimate from (N,4,2) points: mouth axis extrapolated away
    from the nose axis by beta."""
    e = p[:, 1] - p[:, 0]
    mid = (p[:, 0] + p[:, 1]) / 2
    kn = shear_and_roll(e, p[:, 2] - mid)
    km = shear_and_roll(e, p[:, 3] - mid)
    return km + beta * (km - kn), km, kn


def evaluate(
    net: Net, X: np.ndarray, L: np.ndarray, idx: np.ndarray, size: int, batch: int = 256
) -> dict[str, float]:
    """The held-out scores (shares and medians) of the crops `idx`, logged every epoch and
    recorded in the file's header."""
    net.eval()
    preds: list[np.ndarray] = []
    shears: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    with torch.no_grad():
        for i in range(0, len(idx), batch):
            j = idx[i : i + batch]
            x = torch.from_numpy(X[j].astype(np.float32))[:, None] / 255.0
            heat, sh, fl = net(standardize(x))
            pts, _ = decode(heat, size)
            preds.append(pts.numpy())
            shears.append(sh.numpy())
            faces.append(torch.sigmoid(fl).numpy())
    p = np.concatenate(preds).astype(np.float64)
    s = np.concatenate(shears).astype(np.float64)
    f = np.concatenate(faces).astype(np.float64)
    lab = L[idx]
    is_face = lab[:, 12] > 0.5
    face_scores = {
        "faces_scored>=0.5": float(np.mean(f[is_face] >= 0.5)),
        "non_faces_scored>=0.5": float(np.mean(f[~is_face] >= 0.5))
        if (~is_face).any()
        else float("nan"),
    }
    p, s, lab = p[is_face], s[is_face], lab[is_face]
    t = lab[:, :8].reshape(-1, 4, 2).astype(np.float64)
    d = np.linalg.norm(t[:, 1] - t[:, 0], axis=1)
    err = np.linalg.norm(p - t, axis=2) / d[:, None]
    eyes = err[:, :2].max(axis=1)
    kappa = lab[:, 8].astype(np.float64)
    # The geometric estimates read the crop's shear only for unturned crops (roll 0 in the frame).
    out = {
        "eyes<=0.05": float(np.mean(eyes <= 0.05)),
        "eyes<=0.10": float(np.mean(eyes <= 0.10)),
        "nose_med": float(np.median(err[:, 2])),
        "mouth_med": float(np.median(err[:, 3])),
        "head_shear_med": float(np.median(np.abs(s - kappa))),
        "head_shear<=0.05": float(np.mean(np.abs(s - kappa) <= 0.05)),
    }
    for name, pts in [("geom", p), ("oracle", t)]:
        k, km, _kn = geometric_shear(pts)
        ok = np.isfinite(k)
        out[f"{name}<=0.05"] = float(np.mean(np.abs(k - kappa)[ok] <= 0.05) * ok.mean())
        out[f"{name}_mouth<=0.05"] = float(np.nanmean(np.abs(km - kappa) <= 0.05))
    comb = 0.5 * (geometric_shear(p)[0] + s)
    out["mean(geom,head)<=0.05"] = float(np.nanmean(np.abs(comb - kappa) <= 0.05))
    out.update(face_scores)
    net.train()
    return out


def evaluate_shear_only(
    net: Net, X: np.ndarray, L: np.ndarray, idx: np.ndarray, batch: int = 256
) -> dict[str, float]:
    """The held-out shear-only crops' scores: the shear head's error and the face score (their
    points are pseudo-labels, not scored)."""
    net.eval()
    shears: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    with torch.no_grad():
        for i in range(0, len(idx), batch):
            j = idx[i : i + batch]
            x = torch.from_numpy(X[j].astype(np.float32))[:, None] / 255.0
            _heat, sh, fl = net(standardize(x))
            shears.append(sh.numpy())
            faces.append(torch.sigmoid(fl).numpy())
    net.train()
    s = np.concatenate(shears).astype(np.float64)
    f = np.concatenate(faces).astype(np.float64)
    err = np.abs(s - L[idx, 8].astype(np.float64))
    return {
        "head_shear_med": float(np.median(err)),
        "head_shear<=0.05": float(np.mean(err <= 0.05)),
        "faces_scored>=0.5": float(np.mean(f >= 0.5)),
    }


def fold_bn(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> tuple[torch.Tensor, torch.Tensor]:
    """The convolution's weights and bias with the batch normalisation folded in."""
    w = conv.weight.detach().double()
    b = (
        conv.bias.detach().double()
        if conv.bias is not None
        else torch.zeros(w.shape[0], dtype=torch.float64)
    )
    scale = bn.weight.detach().double() / torch.sqrt(bn.running_var.double() + bn.eps)
    w = w * scale[:, None, None, None]
    b = (b - bn.running_mean.double()) * scale + bn.bias.detach().double()
    return w.float(), b.float()


def export(net: Net, path: str, meta: dict[str, Any]) -> None:
    """Writes the weights: magic `UNSHEARN`, u32 version 1, u32 header length, the JSON header
    (architecture and training summary), then every tensor as little-endian f32 in the order
    the header lists them."""
    tensors: list[tuple[str, torch.Tensor, torch.Tensor, int, bool]] = []

    def conv_entry(name: str, seq_or_conv: nn.Module, relu: bool) -> None:
        if isinstance(seq_or_conv, nn.Sequential):
            w, b = fold_bn(seq_or_conv[0], seq_or_conv[1])
            stride = seq_or_conv[0].stride[0]
        else:
            w, b = seq_or_conv.weight.detach().float(), seq_or_conv.bias.detach().float()
            stride = seq_or_conv.stride[0]
        tensors.append((name, w, b, stride, relu))

    for i, m in enumerate(net.stem):
        conv_entry(f"stem.{i}", m, True)
    for i, m in enumerate(net.down2):
        conv_entry(f"down2.{i}", m, True)
    for i, m in enumerate(net.down3):
        conv_entry(f"down3.{i}", m, True)
    for i, m in enumerate(net.down4):
        conv_entry(f"down4.{i}", m, True)
    conv_entry("lat4", net.lat4, False)
    conv_entry("lat3", net.lat3, False)
    conv_entry("lat2", net.lat2, False)
    conv_entry("smooth3", net.smooth3, True)
    conv_entry("smooth2", net.smooth2, True)
    conv_entry("heat", net.heat, False)
    fc = [net.head[0], net.head[2]]
    layers: list[dict[str, Any]] = []
    blobs: list[bytes] = []
    for name, w, b, stride, relu in tensors:
        co, ci, kh, _kw = w.shape
        layers.append(
            {
                "name": name,
                "kind": "conv",
                "in": ci,
                "out": co,
                "kernel": kh,
                "stride": stride,
                "relu": relu,
            }
        )
        blobs += [w.numpy().astype("<f4").tobytes(), b.numpy().astype("<f4").tobytes()]
    for i, l in enumerate(fc):
        layers.append(
            {
                "name": f"head.{i}",
                "kind": "dense",
                "in": l.in_features,
                "out": l.out_features,
                "relu": i == 0,
            }
        )
        blobs += [
            l.weight.detach().numpy().astype("<f4").tobytes(),
            l.bias.detach().numpy().astype("<f4").tobytes(),
        ]
    header = dict(meta)
    # What this network gives on a fixed synthetic crop, so the Rust forward pass can be checked
    # against the trainer's (`net.rs`, test `the_embedded_network_reproduces_the_trainers_check`).
    n = net.size
    probe = torch.tensor([float((i * 31) % 255) for i in range(n * n)]).reshape(1, 1, n, n) / 255.0
    net.eval()
    with torch.no_grad():
        heat, sh, fl = net(standardize(probe))
        pts, _ = decode(heat, n)
    header["check"] = {
        "input": "(i * 31) % 255",
        "points": [round(float(v), 5) for v in pts.flatten()],
        "shear": round(float(sh[0]), 6),
        "face_logit": round(float(fl[0]), 6),
    }
    header["layers"] = layers
    header["size"] = net.size
    header["widths"] = list(net.widths)
    header["fpn"] = net.fpn_width
    h = json.dumps(header, sort_keys=True).encode()
    with open(path + ".tmp", "wb") as f:
        f.write(b"UNSHEARN")
        f.write(struct.pack("<II", 1, len(h)))
        f.write(h)
        f.writelines(blobs)
    os.replace(path + ".tmp", path)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("crops")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--widths", default="16,32,64,96")
    ap.add_argument("--fpn", type=int, default=32)
    ap.add_argument("--shear-weight", type=float, default=1.0)
    ap.add_argument("--heat-weight", type=float, default=0.02)
    ap.add_argument("--face-weight", type=float, default=0.2)
    ap.add_argument("--val-percent", type=int, default=10, help="faces held out (0: train on all)")
    ap.add_argument(
        "--limit", type=int, default=0, help="use only the first N crops (quick trials)"
    )
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument(
        "--export-only",
        metavar="CHECKPOINT",
        help="write the weights of a saved checkpoint (OUT.pt of an earlier run) without training",
    )
    args = ap.parse_args()

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    rng = np.random.default_rng(args.seed)
    with open(os.path.join(args.crops, "meta.json"), encoding="utf-8") as f:
        meta = json.load(f)
    size = meta["size"]
    X = np.fromfile(os.path.join(args.crops, "crops.u8"), dtype=np.uint8).reshape(-1, size, size)
    L = np.fromfile(os.path.join(args.crops, "labels.f32"), dtype="<f4").reshape(
        -1, len(meta["label_fields"])
    )
    if args.limit:
        X, L = X[: args.limit], L[: args.limit]
    # Held out by face (non-face crops, index -1, by their position instead).
    face = L[:, 11].astype(np.int64)
    face = np.where(face < 0, np.arange(len(face)) // 4, face)
    held = (face * 2654435761 % 100) < args.val_percent
    # Shear-only crops (extra faces with pseudo-labelled points): no landmark loss, scored apart.
    fields = meta["label_fields"]
    if "shear_only" in fields:
        shear_only = L[:, fields.index("shear_only")] > 0.5
    else:
        shear_only = np.zeros(len(L), dtype=bool)
    train_idx = np.nonzero(~held)[0]
    val_idx = np.nonzero(held & ~shear_only)[0]
    val_extra_idx = np.nonzero(held & shear_only)[0]
    print(
        f"{len(train_idx)} training crops ({int(shear_only[train_idx].sum())} shear-only), "
        f"{len(val_idx)} held out (+{len(val_extra_idx)} shear-only); size {size}",
        flush=True,
    )

    widths = tuple(int(w) for w in args.widths.split(","))
    net = Net(widths, args.fpn, size)
    if args.export_only:
        saved = torch.load(args.export_only, weights_only=False)
        net.load_state_dict(saved["state"])
        summary = dict(saved["summary"])
        summary.setdefault("crop_eye_distances", meta["crop_eye_distances"])
        summary.setdefault("eyes_above_centre", meta["eyes_above_centre"])
        export(net, args.out, summary)
        print(f"wrote {args.out}", file=sys.stderr)
        return
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=1e-4)
    steps = args.epochs * (len(train_idx) // args.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=args.lr, total_steps=steps, pct_start=0.1
    )
    step = 0
    t0 = time.time()
    for epoch in range(args.epochs):
        order = rng.permutation(train_idx)
        total = 0.0
        for i in range(0, len(order) - args.batch + 1, args.batch):
            j = np.sort(order[i : i + args.batch])
            x = torch.from_numpy(X[j].astype(np.float32))[:, None]
            lab = torch.from_numpy(L[j])
            pts = lab[:, :8].reshape(-1, 4, 2).clone()
            kappa = lab[:, 8].clone()
            x, pts, kappa = augment(x, pts, kappa, rng)
            is_face = lab[:, 12] > 0.5
            # Faces whose points are labels (not shear-only): the landmark losses' crops.
            marked = is_face & ~torch.from_numpy(shear_only[j])
            heat, sh, face_logit = net(standardize(x))
            loss_face = F.binary_cross_entropy_with_logits(face_logit, is_face.float())
            loss = args.face_weight * loss_face
            if is_face.any():
                loss_shear = (sh[is_face] - kappa[is_face]).abs().mean()
                loss = loss + args.shear_weight * loss_shear
            if marked.any():
                pred, prob = decode(heat[marked], size)
                pts = pts[marked]
                d = (pts[:, 1] - pts[:, 0]).norm(dim=1).clamp_min(1.0)
                loss_pts = ((pred - pts).abs().sum(-1) / d[:, None]).mean()
                tgt = gaussian_targets(pts, heat.shape[2], heat.shape[3], size)
                loss_heat = -(tgt * torch.log(prob.clamp_min(1e-12))).sum(dim=(-1, -2)).mean()
                # Weighted by the marked share of the face crops, so that a batch's landmark
                # loss per marked crop is what it would be without shear-only crops around it.
                share = marked.sum() / is_face.sum()
                loss = loss + share * (loss_pts + args.heat_weight * loss_heat)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            step += 1
            total += loss.item()
        msg = {
            "epoch": epoch + 1,
            "loss": round(total / max(1, len(order) // args.batch), 4),
            "minutes": round((time.time() - t0) / 60, 1),
        }
        if len(val_idx):
            msg.update({k: round(v, 4) for k, v in evaluate(net, X, L, val_idx, size).items()})
        if len(val_extra_idx):
            extra = evaluate_shear_only(net, X, L, val_extra_idx)
            msg.update({f"extra_{k}": round(v, 4) for k, v in extra.items()})
        print(json.dumps(msg), flush=True)
        torch.save(
            {"state": net.state_dict(), "summary": {"epoch": epoch + 1}}, args.out + ".epoch.pt"
        )
    summary = {
        "trained_on": args.crops,
        "crops": len(train_idx),
        "held_out": len(val_idx),
        "epochs": args.epochs,
        "crop_eye_distances": meta["crop_eye_distances"],
        "eyes_above_centre": meta["eyes_above_centre"],
        **provenance(args.seed),
    }
    if len(val_idx):
        summary["held_out_scores"] = evaluate(net, X, L, val_idx, size)
    if len(val_extra_idx):
        summary["shear_only_crops"] = int(shear_only[train_idx].sum())
        summary["held_out_extra"] = len(val_extra_idx)
        summary["held_out_extra_scores"] = evaluate_shear_only(net, X, L, val_extra_idx)
    torch.save({"state": net.state_dict(), "summary": summary}, args.out + ".pt")
    export(net, args.out, summary)
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
