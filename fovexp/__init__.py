"""fovexp: noise-based enhancement for foveated rendering (Tariq, Tursun, Didyk 2022).

The public API (docs/API.md); the experiment runner and the analysis use only these names.
"""

from .errors import FovexpError, validation_error
from .geometry import Display, load_display
from .io import read_image, write_image
from .params import (
    METHODS,
    PAPER_TABLE2,
    PARAMETER_RANGES,
    EnhanceParams,
    ParameterTable,
    make_params,
)
from .pipeline import BACKENDS, MAP_NAMES, Enhancer, EnhanceResult, enhance, make_enhancer

__version__ = "0.1.0"

__all__ = [
    "BACKENDS", "MAP_NAMES", "METHODS", "PAPER_TABLE2", "PARAMETER_RANGES", "Display",
    "EnhanceParams", "EnhanceResult", "Enhancer", "FovexpError", "ParameterTable", "enhance",
    "load_display", "make_enhancer", "make_params", "read_image", "validation_error",
    "write_image", "__version__",
]
