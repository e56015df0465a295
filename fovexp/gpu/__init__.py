"""The GPU backend (OpenGL 4.5 compute shaders through moderngl): see :mod:`.backend`; per-stage
GPU times: :func:`profile_stages` (:mod:`.profiling`)."""

from .backend import GpuEnhancer
from .profiling import StageProfile, profile_stages
from .programs import create_context, detach_thread, is_software, release_context, renderer_name

__all__ = [
    "GpuEnhancer", "StageProfile", "create_context", "detach_thread", "is_software",
    "profile_stages", "release_context", "renderer_name",
]
