"""The GPU backend (OpenGL 4.5 compute shaders through moderngl): see :mod:`.backend`."""

from .backend import GpuEnhancer
from .programs import create_context, detach_thread, is_software, release_context, renderer_name

__all__ = [
    "GpuEnhancer", "create_context", "detach_thread", "is_software", "release_context",
    "renderer_name",
]
