"""Drag the origami plate out and back from Python, and compare its two strokes.

    python examples/plate_drag.py

The first stroke (toward +y) is the origami plate's soft, recovery direction: its hinges bend away from their stops.
On the way back (the power stroke) it lies flat against them. The drive force is what holds the motion; its
impulse over a cycle is the one the medium gives the plate.
"""

import finrft

scene = finrft.preset("physical")                              # SI units throughout
drive = finrft.Drive(speed=0.03, stroke=0.1, cycles=3)         # 30 mm/s, 100 mm out and back, three times
run = finrft.simulate(scene, drive)

summary = run.summary()                                        # what `finrft drag --json` prints
print(f"final segment angles: {[round(a, 2) for a in summary['final_segment_angle_deg']]} deg")
print(f"mean drive force, recovery stroke: {summary['mean_recovery_force_N']:+.4f} N")
print(f"mean drive force, power stroke:    {summary['mean_power_force_N']:+.4f} N")
print(f"net impulse per cycle: {summary['net_impulse_Ns']:+.5f} N s (positive: thrust toward +y)")
print(f"estimated error: {summary['error_estimate']}")
