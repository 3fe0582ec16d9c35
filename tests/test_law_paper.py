"""The paper law's cases for the tests every segment law goes through (tests/test_rft.py: its C twin;
tests/test_dissipation.py: when it dissipates); its closed forms are in tests/test_rft.py."""

# Scene overrides for the twin test (N/m^3).
def twin(tmp_path):
    return {"rft.f_perp": 1.3e4, "rft.f_par": -4.0e3}


# Parameters of `force` that dissipate, and parameters that can feed energy in.
DISSIPATIVE = [{"f_perp": 1.2, "f_par": 0.2}, {"f_perp": 1.2, "f_par": 0.0}, {"f_perp": 0.0, "f_par": 0.7}]
FEEDING = [{"f_perp": 1.2, "f_par": -0.2}, {"f_perp": -0.5, "f_par": 0.3}]
