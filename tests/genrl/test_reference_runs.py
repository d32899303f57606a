"""Fixed-seed GenRL runs with hindsight, refits and kept demonstrations end with the parameters recorded in
tests/genrl/data/reference_parameters.npz, bit for bit (see reference_runs.py)."""

from __future__ import annotations

import numpy as np
from reference_runs import REFERENCE, reference_parameters


def test_hindsight_refit_and_demonstration_runs_end_with_the_recorded_parameters_bit_for_bit():
    got = reference_parameters()
    with np.load(REFERENCE) as expected:
        assert sorted(got) == sorted(expected.files)
        for key in expected.files:
            np.testing.assert_array_equal(got[key], expected[key], err_msg=key)
