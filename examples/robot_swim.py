"""The two-fin robot swimming its optimised gait, and the same gait with rigid fins.

    python examples/robot_swim.py

eta = (D1 - D2) / D1 over the steady cycles: D1 the distance forward in the power strokes, D2 the distance back in
the recovery strokes. The origami fins fold in the recovery stroke; rigid fins cannot, and barely swim.
"""

import finrft

robot = finrft.preset("physical", finrft.RobotScene)
for fin in ("origami", "rigid"):
    scene = robot.replace(**{"fin.kind": fin})
    summary = finrft.swim(scene, cycles=scene.gait.cycles).summary()
    print(f"{fin:8s} eta = {100 * summary['eta_steady']:+.2f} % over the steady cycles")
