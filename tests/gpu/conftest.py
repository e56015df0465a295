"""The OpenGL context the GPU tests run in (Mesa llvmpipe through EGL in CI)."""

import os

import pytest

from fovexp import FovexpError


@pytest.fixture(scope="module")
def ctx():
    from fovexp.gpu import create_context, detach_thread, release_context

    try:
        ctx = create_context()
    except FovexpError as exc:
        if os.environ.get("FOVEXP_REQUIRE_GPU_BACKEND"):
            raise  # CI installs Mesa's EGL: there the backend must run
        pytest.skip(f"no OpenGL 4.5 context: {exc}")
    yield ctx
    release_context(ctx)
    detach_thread()  # the contexts other tests made here: PsychoPy windows follow (GLX)
