#!/usr/bin/env bash
# The paper's analyses of outputs (section 6) on the shipped (generated) scenes at 4K, as
# recorded in benchmarks/EVALUATION.md: each figure, CSV and note into benchmarks/evaluation/.
# Run from the clone's root after ./dev setup (and .ci/fovvdp for FovVDP); about two hours of
# CPU on the 2-core machine. Each step runs niced; ./benchmarks/evaluation.sh STEP runs one
# (scenes, spectra, temporal, fovvdp, validation, compression, stereo).
set -euo pipefail
cd "$(dirname "$0")/.."
B=.venv/bin/fovexp
OUT=benchmarks/evaluation
S=stimuli/generated/3840x2160
WORK=${FOVEXP_EVAL_WORK:-out/evaluation}
run() { nice -n 5 "$@"; }
want() { [ "${1:-all}" = all ] || [ "${1:-all}" = "$2" ]; }
mkdir -p "$OUT" "$WORK"

if want "${1:-all}" scenes; then
  run $B stimuli generate --size 3840x2160 --stimuli stimuli   # the 15 scenes at 4K
  run $B stimuli generate --size 480x270 --stimuli stimuli     # what the dry runs show
fi
if want "${1:-all}" spectra; then   # 6.1: the 5 calibration scenes, Table 2's blur-rates
  run $B evaluate spectra $S/scene-0{0,1,2,3,4}.png --backend cpu --out $OUT/spectra
fi
if want "${1:-all}" temporal; then  # 6.2: a 30-frame pan, 8 px per frame
  run $B stimuli pan --size 3840x2160 --frames 30 --step 8 --out "$WORK/pan"
  run $B evaluate temporal "$WORK/pan" --backend cpu --out $OUT/temporal
fi
if want "${1:-all}" fovvdp; then    # 6.1: the 10 validation scenes at the paper's 0.68
  run .venv-fovvdp/bin/fovexp evaluate fovvdp $S/scene-{05,06,07,08,09,10,11,12,13,14}.png \
    --blur-rate 0.68 --backend cpu --out $OUT/fovvdp
fi
if want "${1:-all}" validation; then  # 6.1 and 6.3: dry runs of both validations, analysed
  rm -rf "$WORK/results"
  for proto in validation validation-12; do
    for p in S01 S02 S03; do
      xvfb-run -a -s "-screen 0 1280x720x24" $B run $proto --participant $p --dry-run \
        --sim-speed 12 --practice 0 --results "$WORK/results" --stimuli stimuli
    done
  done
  run $B analyze "$WORK/results" --out "$WORK/report"
  cp "$WORK/report/figures/impulses-sampling.png" $OUT/impulses-sampling.png
  cp "$WORK/report/tables/impulses-"*.csv $OUT/
fi
if want "${1:-all}" compression; then  # 6.3: JPEG at the dry runs' blur-rates, native 4K scenes
  run $B evaluate compression "$WORK/results" --images $S --backend cpu --out $OUT/compression
fi
if want "${1:-all}" stereo; then    # 6.4: the stereo test pair at 4K
  run $B stimuli stereo --size 3840x2160 --out "$WORK/pair"
  run $B stereo "$WORK/pair/left.png" "$WORK/pair/right.png" --disparity \
    "$WORK/pair/disparity.npy" --blur-rate 0.57 --backend cpu --out "$WORK/stereo"
fi
