"""Granular RFT on a MuJoCo model of your own: finrft.attach adds the medium's force to the bodies you name.

    python examples/own_model.py

A 4 cm x 6 cm plate standing in the generic medium, its top edge at the surface, dragged normal to its face: the
force is alpha_z x width x depth^2 / 2 = 0.370 N/cm^3 x 4 cm x (6 cm)^2 / 2 = 26.64 N (Li, Zhang & Goldman 2013).
"""

import mujoco

import finrft

PLATE = """
<mujoco>
  <option gravity="0 0 0"/>
  <worldbody>
    <body name="plate">
      <joint name="drag" type="slide" axis="1 0 0"/>
      <geom type="box" size="0.0005 0.02 0.03" pos="0 0 -0.03" mass="10"/>
    </body>
  </worldbody>
</mujoco>
"""

spec = mujoco.MjSpec.from_string(PLATE)
attached = finrft.attach(spec, ["plate"], zeta=1.0)   # or medium="poppy_seeds_lp", a catalogued medium
model = spec.compile()
data = mujoco.MjData(model)
data.qvel[0] = 0.1                                    # 10 cm/s along +x
with attached.installed(model):                       # needed by the Python backend only
    mujoco.mj_step(model, data)
print(f"{attached.elements} surface elements, drag {data.qfrc_passive[0]:.2f} N (closed form: -26.64 N)")
