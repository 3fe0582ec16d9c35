"""A scene from a TOML file, changed from Python, run, and written to HDF5.

    python examples/scene_from_toml.py [OUT.h5]
"""

import sys
from pathlib import Path

import finrft

scene = finrft.load_scene(Path(__file__).with_name("plate.toml"))
print(finrft.to_toml(scene).splitlines()[0])
for stiffness in (0.02, 0.05, 0.2):
    run = finrft.simulate(scene.replace(**{"plate.stiffness": stiffness}), finrft.Drive(speed=0.03, stroke=0.1))
    angles = [round(a, 1) for a in run.summary()["final_segment_angle_deg"]]
    print(f"k = {stiffness:4.2f} N m/rad: final segment angles {angles} deg")
if len(sys.argv) > 1:
    finrft.write_h5(run, sys.argv[1])
    print(f"wrote {sys.argv[1]}")
