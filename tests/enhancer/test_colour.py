"""Colour transfer functions (paper section 4.5; docs/METHOD.md, 5.1)."""

import numpy as np
import pytest

from fovexp.colour import encode, linearize


@pytest.mark.parametrize("transfer", ["power", "release"])
def test_transfer_round_trip(transfer):
    v = np.linspace(0, 1, 101, dtype=np.float32)
    assert np.abs(encode(linearize(v, 2.2, transfer), 2.2, transfer) - v).max() < 1e-5
