#!/usr/bin/env bash
# Shear-estimation check on the 15 Yale "normal" faces (no eye annotations, so only k is scored):
# each face is sheared with `unshear distort --canvas crop` (the rectangle a camera delivers, every
# row kept at this size: no empty corner whose slant gives k away) for k in {-0.4, -0.2, 0, 0.2,
# 0.4}, then `unshear estimate --json` runs on all of them and a summary per k is printed.
# Usage: scripts/yale_shear.sh [path/to/yale-faces/images]   (needs python3, no packages)
# Environment: UNSHEAR (the binary, default target/release/unshear), UNSHEAR_ARGS (extra options
# for `estimate`, e.g. "--filter-type mosse"), YALE_CANVAS (`distort --canvas`, default crop;
# expand: the widened canvas, the paper's setting).
set -euo pipefail
images=${1:-../shared/data/yale-faces/images}
bin=${UNSHEAR:-target/release/unshear}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for f in "$images"/subject*.normal*; do
  s=$(basename "$f" | sed 's/\..*//')
  for k in -0.4 -0.2 0 0.2 0.4; do
    "$bin" distort "$f" --k "$k" --canvas "${YALE_CANVAS:-crop}" -o "$work/${s}_k$k.png"
  done
done
"$bin" estimate "$work" --json ${UNSHEAR_ARGS:-} | python3 -c '
import sys, json, re, statistics as st
rows = []
for line in sys.stdin:
    d = json.loads(line)
    k = float(re.search(r"_k(-?[0-9.]+)\.png$", d["file"]).group(1))
    rows.append((k, d["k"]))
print("| true k | faces | estimated | median k | median abs err | within 0.05 |")
print("|---:|---:|---:|---:|---:|---:|")
for k in sorted({r[0] for r in rows}):
    est = [e for kk, e in rows if kk == k and e is not None]
    n = sum(1 for kk, _ in rows if kk == k)
    err = [abs(e - k) for e in est]
    print(f"| {k:+.2f} | {n} | {len(est)} | {st.median(est):.3f} | {st.median(err):.3f} | {sum(e <= 0.05 for e in err)}/{n} |")
'
