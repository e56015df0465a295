"""Why ours' inter-frame SSIM falls below full resolution's under the paper's clipping rule
(issue 26; benchmarks/EVALUATION.md, 6.2): the same 3-frame 4K pan at blur-rate 0.57, ours
under each clipping rule given on the command line, through the evaluation's own
``temporal.analyse``.

    python benchmarks/temporal_cause.py paper off widened

Prints and writes (``--out``, default out/temporal_cause.json) each rule's mean SSIM of full
resolution, foveated, contrast and ours, and the seconds it took.
"""

from __future__ import annotations

import gc
import json
import sys
import time
from pathlib import Path

from fovexp import EngineOptions, make_enhancer
from fovexp.cli import main
from fovexp.evaluation import temporal
from fovexp.evaluation.outputs import Setup


def measure(rules: list[str], work: Path) -> dict[str, dict[str, float]]:
    pan = work / "pan"
    if not pan.exists():
        assert main(["stimuli", "pan", "--size", "3840x2160", "--frames", "3", "--step", "8",
                     "--out", str(pan)]) == 0
    out = {}
    for rule in rules:
        t0 = time.time()

        class RuleSetup(Setup):
            clipping = rule

            def enhancer(self):  # noqa: ANN202
                return make_enhancer(self.display, preset=self.preset, backend=self.backend,
                                     options=EngineOptions(clipping=self.clipping))

        res = temporal.analyse(pan, RuleSetup.make("lg-oled55cx", backend="cpu"), [0.57],
                               reseed=False)
        out[rule] = {"full": res.mean("full"), "foveated": res.mean("foveated", 0.57),
                     "contrast": res.mean("contrast", 0.57), "ours": res.mean("ours", 0.57),
                     "s": round(time.time() - t0)}
        print(rule, out[rule], flush=True)
        del res
        gc.collect()  # 4K enhancers: their stage caches hold cycles
    return out


if __name__ == "__main__":
    args = sys.argv[1:]
    dest = Path("out/temporal_cause.json")
    if "--out" in args:
        k = args.index("--out")
        dest, args = Path(args[k + 1]), args[:k] + args[k + 2:]
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(measure(args or ["paper", "off", "widened"], dest.parent),
                            indent=1))
