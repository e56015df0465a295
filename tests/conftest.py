from engine_helpers import sponza  # noqa: F401  (fixture)
