"""fovexp: noise-based enhancement for foveated rendering (Tariq, Tursun, Didyk 2022).

The public API (docs/API.md); the experiment runner and the analysis use only these names.
Each is imported from its module when first used (PEP 562), so that ``import fovexp`` and
``fovexp --version`` do not load Numba, SciPy or pandas; ``from fovexp import Enhancer``
works as usual.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__

#: Public name -> the module of the package that defines it.
_PUBLIC: dict[str, str] = {
    "BACKENDS": "backends", "make_enhancer": "backends",
    "t_high_cpd": "acuity", "t_low_cpd": "acuity",
    "parse_yaml": "config", "read_yaml": "config",
    "FovexpError": "errors", "did_you_mean": "errors", "validation_error": "errors",
    "Display": "geometry", "ViewingGeometry": "geometry", "load_display": "geometry",
    "read_image": "io", "read_samples": "io", "write_bytes_atomic": "io", "write_image": "io",
    "METHODS": "params", "PAPER_TABLE2": "params", "PARAMETER_RANGES": "params",
    "EngineOptions": "params", "EnhanceParams": "params", "ParameterTable": "params",
    "check_parameter": "params", "make_options": "params", "make_params": "params",
    "MAP_NAMES": "pipeline", "Enhancer": "pipeline", "EnhanceResult": "pipeline",
    "enhance": "pipeline",
    "find_protocol": "resources", "shipped_protocols": "resources",
    "shipped_stimuli": "resources",
    "Steps": "progress", "progress_bar": "progress",
    "iter_frames": "sequence", "ssim": "sequence",
    "profile_stages": "gpu.profiling",
}

if TYPE_CHECKING:  # the same names for type checkers (tests/test_layers.py holds the
    # three lists equal)
    from .acuity import t_high_cpd, t_low_cpd
    from .backends import BACKENDS, make_enhancer
    from .config import parse_yaml, read_yaml
    from .errors import FovexpError, did_you_mean, validation_error
    from .geometry import Display, ViewingGeometry, load_display
    from .gpu.profiling import profile_stages
    from .io import read_image, read_samples, write_bytes_atomic, write_image
    from .params import (
        METHODS,
        PAPER_TABLE2,
        PARAMETER_RANGES,
        EngineOptions,
        EnhanceParams,
        ParameterTable,
        check_parameter,
        make_options,
        make_params,
    )
    from .pipeline import MAP_NAMES, Enhancer, EnhanceResult, enhance
    from .progress import Steps, progress_bar
    from .resources import find_protocol, shipped_protocols, shipped_stimuli
    from .sequence import iter_frames, ssim

__all__ = [
    "BACKENDS", "MAP_NAMES", "METHODS", "PAPER_TABLE2", "PARAMETER_RANGES", "Display",
    "EngineOptions", "EnhanceParams", "EnhanceResult", "Enhancer", "FovexpError",
    "ParameterTable", "ViewingGeometry", "check_parameter", "did_you_mean", "enhance",
    "find_protocol", "load_display", "make_enhancer", "make_options", "make_params",
    "parse_yaml", "profile_stages", "read_image", "read_samples", "read_yaml",
    "shipped_protocols",
    "shipped_stimuli", "validation_error", "write_bytes_atomic", "write_image", "__version__",
    "iter_frames", "ssim", "t_high_cpd", "t_low_cpd", "Steps", "progress_bar",
]


def __getattr__(name: str) -> Any:
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'fovexp' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # looked up once
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_PUBLIC})
