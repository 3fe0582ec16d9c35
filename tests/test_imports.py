"""A simulation does not import what only recordings, figures, data files or clusters need: they are heavy."""

import subprocess
import sys

HEAVY = ("rerun", "matplotlib", "h5py", "dask", "warp", "mujoco_warp")


def test_drag_imports_no_heavy_dependency(tmp_path):
    probe = ("import sys\n"
             "from finrft.cli import main\n"
             "assert main(['drag', '--distance', '5', '--json']) == 0\n"
             f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n")
    # Run elsewhere than the repository root, whose finrft/ would shadow the installed package.
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                         cwd=tmp_path).stdout
    assert out.splitlines()[-1] == "[]"
