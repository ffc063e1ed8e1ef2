#!/usr/bin/env bash
# How the estimate behaves on rolled, unsheared faces: each test fixture rotated by 20, 25, 30
# and 35 degrees (OpenCV warpAffine about the centre, border replicated), then
# `unshear estimate --json`. The true k is 0 for every image.
# Usage: scripts/rolled_fixtures.sh   (needs python3 with OpenCV: pip install opencv-python-headless)
set -euo pipefail
bin=${UNSHEAR:-target/release/unshear}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
python3 - "$work" <<'PY'
import sys, cv2
out = sys.argv[1]
for n in ["subject01", "subject03", "subject14"]:
    im = cv2.imread(f"tests/fixtures/faces/{n}.normal.jpeg", cv2.IMREAD_GRAYSCALE)
    h, w = im.shape
    for a in [20, 25, 30, 35]:
        m = cv2.getRotationMatrix2D((w / 2, h / 2), a, 1.0)
        cv2.imwrite(f"{out}/{n}_roll{a}.png", cv2.warpAffine(im, m, (w, h), borderMode=cv2.BORDER_REPLICATE))
PY
"$bin" estimate "$work" --json | python3 -c '
import sys, json, os
for line in sys.stdin:
    d = json.loads(line)
    faces = ", ".join("k_measured %+.3f roll %+.1f conf %.2f" % (f["k_measured"], f["roll"], f["confidence"]) for f in d["faces"])
    print("%s: k %s; %s" % (os.path.basename(d["file"]), d["k"], faces or "no face"))
'
