#!/usr/bin/env bash
# The paper's analyses of outputs (section 6) on the shipped (generated) scenes at 4K, as
# recorded in benchmarks/EVALUATION.md: each figure, CSV and note into benchmarks/evaluation/.
# Run from the clone's root after ./dev setup (and .ci/fovvdp for FovVDP); about two hours of
# CPU on the 2-core machine. Each step runs niced; ./benchmarks/evaluation.sh STEP runs one
# (scenes, spectra, temporal, fovvdp, validation, compression, stereo).
set -euo pipefail
cd "$(dirname "$0")/.."
B=.venv/bin/fovexp
# FOVEXP_EVAL_PRESET=release runs the evaluate commands under the release preset, into
# benchmarks/evaluation/release/ (issue 26: both presets side by side in EVALUATION.md)
PRESET=${FOVEXP_EVAL_PRESET:-paper}
OUT=benchmarks/evaluation
[ "$PRESET" = paper ] || OUT=benchmarks/evaluation/$PRESET
S=stimuli/generated/3840x2160
WORK=${FOVEXP_EVAL_WORK:-out/evaluation}
# simulated participants of the validation dry runs (FOVEXP_EVAL_PARTICIPANTS="S01" for one)
run() { nice -n 5 "$@"; }
want() { [ "${1:-all}" = all ] || [ "${1:-all}" = "$2" ]; }
mkdir -p "$OUT" "$WORK"

if want "${1:-all}" scenes; then
  run $B stimuli generate --size 3840x2160 --stimuli stimuli   # the 15 scenes at 4K
  run $B stimuli generate --size 480x270 --stimuli stimuli     # what the dry runs show
fi
if want "${1:-all}" spectra; then   # 6.1: the 5 calibration scenes, Table 2's blur-rates
  run $B evaluate spectra $S/scene-0{0,1,2,3,4}.png --backend cpu --preset $PRESET \
    --out $OUT/spectra
fi
if want "${1:-all}" temporal; then  # 6.2: a 30-frame pan, 8 px per frame
  run $B stimuli pan --size 3840x2160 --frames 30 --step 8 --out "$WORK/pan"
  run $B evaluate temporal "$WORK/pan" --backend cpu --preset $PRESET --out $OUT/temporal
fi
if want "${1:-all}" fovvdp; then    # 6.1: the 10 validation scenes at the paper's 0.68
  run .venv-fovvdp/bin/fovexp evaluate fovvdp $S/scene-{05,06,07,08,09,10,11,12,13,14}.png \
    --blur-rate 0.68 --backend cpu --preset $PRESET --out $OUT/fovvdp
fi
if want "${1:-all}" validation; then  # 6.1 and 6.3: dry runs of both validations, analysed
  rm -rf "$WORK/results"
  if [ -n "${FOVEXP_EVAL_SIMULATED_LOGS:-}" ]; then
    # Trial logs written directly from a simulated truth (tests/analysis_fixtures.py: contrast
    # 0.30 + 0.02 i arcmin/deg for the i-th scene, ours 1.25 x that, 10 participants, the
    # fixture's noise), for the scenes scene-05 ... scene-14, at both impulse counts, with
    # each session file carrying its protocol's text: seconds instead of the dry runs' hour.
    PYTHONPATH=tests .venv/bin/python - "$WORK/results" <<'PY'
import json, sys
from pathlib import Path
import numpy as np
from analysis_fixtures import Noise, Truth, session_id, simulate_rows, write_trials
root = Path(sys.argv[1])
for k, (exp, proto) in enumerate((("validation", "validation"), ("validation-12", "validation-12"))):
    rng = np.random.default_rng(20 + k)
    text = Path(f"protocols/{proto}.yaml").read_text()
    for p in range(10):
        pid, sess = f"P{p + 1:02d}", session_id(100 * k + p)
        rows = [dict(r, experiment=exp, image=f"scene-{int(r['image'][5:]) + 5:02d}")
                for r in simulate_rows("validation", pid, sess, rng, Truth(), Noise())]
        write_trials(root / exp / pid, rows)
        info_path = root / exp / pid / f"session-{sess}.json"
        info = json.loads(info_path.read_text())
        info["protocol"] = text
        info_path.write_text(json.dumps(info))
print(f"simulated validation logs in {root}")
PY
  else
    for proto in validation validation-12; do
      for p in ${FOVEXP_EVAL_PARTICIPANTS:-S01 S02 S03}; do
        xvfb-run -a -s "-screen 0 1280x720x24" $B run $proto --participant $p --dry-run \
          --sim-speed 12 --practice 0 --results "$WORK/results" --stimuli stimuli
      done
    done
  fi
  run $B analyze "$WORK/results" --out "$WORK/report"
  cp "$WORK/report/figures/impulses-sampling.png" $OUT/impulses-sampling.png
  cp "$WORK/report/tables/impulses-"*.csv $OUT/
fi
if want "${1:-all}" compression; then  # 6.3: JPEG at the dry runs' blur-rates, native 4K scenes
  run $B evaluate compression "$WORK/results" --images $S --backend cpu --preset $PRESET \
    --out $OUT/compression
fi
if want "${1:-all}" stereo; then    # 6.4: the stereo test pair at 4K
  run $B stimuli stereo --size 3840x2160 --out "$WORK/pair"
  run $B stereo "$WORK/pair/left.png" "$WORK/pair/right.png" --disparity \
    "$WORK/pair/disparity.npy" --blur-rate 0.57 --backend cpu --dump-maps --out "$WORK/stereo"
  # the record: the anaglyph at 1/3 size, and 1:1 crops where the near rectangle's right edge
  # opens a disocclusion (anaglyph, and the right eye's noise with the disoccluded strip)
  .venv/bin/python - "$WORK" "$OUT/stereo" <<'PY'
import sys
from pathlib import Path
import numpy as np
from PIL import Image
from fovexp import read_image, write_image
work, out = Path(sys.argv[1]), Path(sys.argv[2])
out.mkdir(parents=True, exist_ok=True)
ana = read_image(work / "stereo" / "anaglyph.png")
small = Image.fromarray(np.round(ana * 255).astype(np.uint8)).resize((1280, 720), Image.LANCZOS)
small.save(out / "anaglyph-1280.png")
d = np.load(work / "pair" / "disparity.npy")
ys, xs = np.nonzero(d == d.max())
y0, x1 = int(ys.mean()) - 135, int(xs.max()) + 1 - 240
crop = (slice(y0, y0 + 270), slice(x1, x1 + 480))
write_image(out / "anaglyph-crop.png", ana[crop])
noise = np.load(work / "stereo" / "noise-right.npy")[crop]
hole = read_image(work / "stereo" / "disocclusion.png")[crop] > 0.5
scale = 0.5 / max(float(np.abs(noise).max()), 1e-6)
rgb = np.repeat((0.5 + scale * noise)[..., None], 3, axis=2)
rgb[hole, 0] = np.clip(rgb[hole, 0] + 0.35, 0, 1)  # the disoccluded strip tinted red
write_image(out / "noise-right-crop.png", rgb.astype(np.float32))
print(f"stereo record: {out}")
PY
fi
