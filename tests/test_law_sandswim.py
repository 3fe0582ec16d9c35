"""The sand-swimming law's cases for the tests every segment law goes through (tests/test_rft.py: its C twin;
tests/test_dissipation.py: when it dissipates); its published shape is in tests/test_rft.py."""

import numpy as np


# Scene overrides for the twin test (N/m^3, rad).
def twin(tmp_path):
    return {"rft.c_s": 1.1e4, "rft.c_f": 4.5e3, "rft.gamma0": 0.4}


# Parameters of `force` that dissipate, and parameters that can feed energy in.
DISSIPATIVE = [{"c_s": 1.7, "c_f": 0.6, "gamma0": 0.35}, {"c_s": 0.9, "c_f": 1.2, "gamma0": np.pi / 2},
               {"c_s": 2.0, "c_f": 0.0, "gamma0": 0.1}]
FEEDING = [{"c_s": 1.0, "c_f": -0.1, "gamma0": 0.3}, {"c_s": -1.0, "c_f": 0.5, "gamma0": 0.3}]
