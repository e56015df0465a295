"""The one exception type that user-facing code turns into a clear message and exit status 2."""


class FovexpError(ValueError):
    """Bad input: a malformed file, an out-of-range parameter, a missing resource.

    The message names the problem (the file, the key, the value) in one line.
    """
