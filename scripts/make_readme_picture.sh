#!/usr/bin/env bash
# The README's picture, docs/img/rerun_view.png, from a real run: a short run of the node graph
# (the layered Singapore network, the paper's rate, the example constraints, exact MWIS) whose
# .rrd the Rerun viewer renders headless at 1400x800 (uam_sim.views.screenshot); the frame is
# scaled to 1400 px wide and stored with a 256-colour palette to stay small.
#
#   scripts/make_readme_picture.sh [--duration S] [--out PNG]
#
# The run's folder (runs/readme-picture-XXXX) is kept; its summary is printed as usual.
set -euo pipefail
cd "$(dirname "$0")/.."

DURATION=660   # past 600 s, when the example's TFR-CENTRAL starts: all three constraints in force
OUT=docs/img/rerun_view.png
while (( $# )); do
  case "$1" in
    --duration) DURATION="${2:?--duration needs seconds}"; shift 2;;
    --out) OUT="${2:?--out needs a PNG path}"; shift 2;;
    -h|--help) sed -n '2,9p' "$0"; exit 0;;
    *) echo "make_readme_picture: unknown option '$1' (--duration S, --out PNG)" >&2; exit 2;;
  esac
done

mkdir -p runs
RUN=$(mktemp -d runs/readme-picture-XXXX)
bash scripts/run_fleet.sh --duration "$DURATION" --rate 10 --backend exact --seed 0 \
  --network config/networks/singapore-layered.yaml --constraints config/constraints_example.geojson \
  --rerun save --out "$RUN"
# shellcheck disable=SC1091
source scripts/env.sh >/dev/null
python -m uam_sim.views.screenshot "$RUN/run.rrd" "$RUN/screenshot.png" --size 1400x800
python - "$RUN/screenshot.png" "$OUT" <<'PY'
import sys
from PIL import Image

shot, out = sys.argv[1:]
img = Image.open(shot).convert("RGB")
if img.width != 1400:   # the viewer saves physical pixels (2x on a HiDPI scale)
    img = img.resize((1400, round(img.height * 1400 / img.width)), Image.LANCZOS)
img.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
PY
echo "make_readme_picture: wrote $OUT ($(du -k "$OUT" | cut -f1) KB) from $RUN/run.rrd"
