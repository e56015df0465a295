"""fovexp: noise-based enhancement for foveated rendering (Tariq, Tursun, Didyk 2022).

The public API (docs/API.md); the experiment runner and the analysis use only these names.
"""

from ._version import __version__
from .backends import BACKENDS, make_enhancer
from .config import parse_yaml, read_yaml
from .errors import FovexpError, validation_error
from .geometry import Display, ViewingGeometry, load_display
from .io import read_image, write_image
from .params import (
    METHODS,
    PAPER_TABLE2,
    PARAMETER_RANGES,
    EngineOptions,
    EnhanceParams,
    ParameterTable,
    make_options,
    make_params,
)
from .pipeline import MAP_NAMES, Enhancer, EnhanceResult, enhance
from .resources import find_protocol

__all__ = [
    "BACKENDS", "MAP_NAMES", "METHODS", "PAPER_TABLE2", "PARAMETER_RANGES", "Display",
    "EngineOptions", "EnhanceParams", "EnhanceResult", "Enhancer", "FovexpError",
    "ParameterTable", "ViewingGeometry", "enhance", "find_protocol", "load_display",
    "make_enhancer", "make_options", "make_params", "parse_yaml", "read_image", "read_yaml",
    "validation_error", "write_image", "__version__",
]
