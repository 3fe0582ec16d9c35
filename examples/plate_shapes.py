"""The origami plate bending as it is dragged out and back: its centre line, seen from above, at instants of one
cycle (the picture of the README).

    python examples/plate_shapes.py [OUT.png]      # default: plate_shapes.png
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import finrft  # noqa: E402

scene = finrft.preset("physical")
plate = scene.plate
run = finrft.simulate(scene, finrft.Drive(speed=0.03, stroke=0.1, cycles=1))
half = len(run.time) // 2

fig, axes = plt.subplots(1, 2, figsize=(9, 4.4), sharey=True)
for ax, (title, samples) in zip(axes, (("recovery stroke (toward +y): the hinges bend", range(0, half + 1, 20)),
                                       ("power stroke (back): flat against the stops", range(half, len(run.time), 20)))):
    for k, i in enumerate(samples):
        # The rod lies along +x from the driven base; each segment follows at its absolute angle.
        angles = run.segment_angle[i]  # rad, SI like every series
        x = np.concatenate([[0.0, plate.rod_length], plate.rod_length + np.cumsum(plate.segment_length * np.cos(angles))])
        y = run.displacement[i] + np.concatenate([[0.0, 0.0], np.cumsum(plate.segment_length * np.sin(angles))])
        shade = plt.cm.viridis(k / max(1, len(samples) - 1))
        ax.plot(1e3 * x, 1e3 * y, "-o", color=shade, markersize=3, lw=1.5)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x (mm)")
    ax.set_aspect("equal")
axes[0].set_ylabel("y (mm)")
fig.suptitle("finrft: the physical origami plate in granular medium, 30 mm/s, 100 mm out and back (top view)",
             fontsize=10)
fig.tight_layout()
out = sys.argv[1] if len(sys.argv) > 1 else "plate_shapes.png"
fig.savefig(out, dpi=110)
print(f"wrote {out}")
