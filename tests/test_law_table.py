"""The table law's cases for the tests every segment law goes through (tests/test_rft.py: its C twin;
tests/test_dissipation.py: when it dissipates); its reading and its agreement with the paper law are in
tests/test_rft.py."""

import numpy as np

from finrft.laws import table


def _table(perp, par, attack_deg=(0.0, 45.0, 90.0)):
    return {"table": table.ForceTable(np.array(attack_deg), np.array(perp, float), np.array(par, float))}


# Scene overrides for the twin test: a table that is not the paper law's, so that the table path is exercised on
# its own (N/m^3).
def twin(tmp_path):
    attack = np.linspace(0.0, 90.0, 7)
    path = tmp_path / "forces.csv"
    table.write_table(path, table.ForceTable(attack, 1.2e4 * np.sin(np.radians(attack)) ** 0.5,
                                             -3.0e3 * np.cos(np.radians(attack))))
    return {"rft.table": str(path)}


# Parameters of `force` that dissipate, and parameters that can feed energy in.
DISSIPATIVE = [_table([0.0, 1.0, 1.2], [0.3, 0.2, 0.0]), {"table": table.paper_table(1.2, 0.2, samples=19)},
               # negative F_par near 90 deg, outweighed there by F_perp sin(theta)
               _table([0.0, 1.0, 1.0], [0.2, 0.0, -0.1])]
FEEDING = [{"table": table.paper_table(1.2, -0.2, samples=19)}, _table([0.0, -0.3, 1.0], [0.3, 0.2, 0.0])]
