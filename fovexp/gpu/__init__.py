"""The GPU backend (OpenGL 4.5 compute shaders through moderngl): see :mod:`.backend`."""

from .backend import GpuEnhancer
from .programs import create_context, is_software, renderer_name

__all__ = ["GpuEnhancer", "create_context", "is_software", "renderer_name"]
