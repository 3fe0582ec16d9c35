"""The medium resolved once, at model build: every segment law and body drag of a chain scene, in newtons.

A scene says what its user gave: intensive law coefficients (``[rft]``, per unit area and depth, N/m^3), the
geometry (segment length, ``medium.height`` and ``medium.depth``) and the medium. `resolve` turns them into the
forces of each face, for the model builder, the independent reference and the summaries alike; nothing derived is
written back into the scene.

A segment's law is its ``[rft]`` coefficients times its face's area and mean depth (`finrft.laws.segment_scale`).
When the scene's ``[medium]`` gives the bulk density, internal and surface friction, the faces' forces follow from
3D-RFT on vertical faces whose top edges are at ``medium.depth`` (`finrft.media.plate_forces`, Agarwal, Goldman &
Kamrin 2023):

- each chain segment: the sand-swimming law fitted to it (segment_length x medium.height) when ``[rft]`` leaves
  c_s, c_f and gamma0 at 0;
- each of the robot's arms: the same law fitted to arm.length x arm.height;
- the robot's body: 3D-RFT's force on the box body.width x body.length x body.height moving along its axis, plus the
  cart's rolling resistance body.cart; the half robot carries half. In 3D-RFT only the leading front face resists:
  the sides slide along themselves and take nothing.

Without those (the paper presets), the arm takes the authors' paper law f_perp_base + f_perp_per_length x length
and the body its ``body.drag``.

The body's top and bottom faces are left out: horizontal faces sliding horizontally feel only the surface friction
times the overburden, mu_surf rho g z W L (0.18 N on the top face under 10 mm of beads, 1.0 N on the bottom one at
55 mm, with the preset's estimates), which 3D-RFT on vertical faces does not describe.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import laws, media
from .laws import SegmentLaw, sandswim


@dataclass(frozen=True)
class Resolved:
    """A chain scene's forces, resolved: the law of one chain segment (N), and for the robot the law of one arm (N)
    and the whole robot's body drag (N); ``scale`` is a chain segment's area x mean depth (m^3)."""

    chain: SegmentLaw
    scale: float
    arm: SegmentLaw | None = None
    body_drag: float | None = None

    def figures(self) -> dict[str, Any]:
        """The derived figures results and summaries report: each law's per-segment coefficients (N)."""
        out: dict[str, Any] = {"segment_scale_m3": self.scale, "segment_law": _numbers(self.chain)}
        if self.arm is not None:
            out["arm_law"] = _numbers(self.arm)
        if self.body_drag is not None:
            out["body_drag_N"] = self.body_drag
        return out


def _numbers(law: SegmentLaw) -> dict[str, Any]:
    return {"law": law.law, **{key: float(value) for key, value in law.parameters.items()
                               if isinstance(value, (int, float))}}


def properties(scene: Any) -> tuple[float, float, float] | None:
    """The medium's bulk density, internal and surface friction when the scene's [medium] gives them (the forces
    then come from it), None otherwise (the paper presets: each law's coefficients as given)."""
    return media.immersion_properties(scene.medium)


def chain_of(scene: Any) -> Any:
    """The scene's chain of segments: the plate, or the robot's fin."""
    return scene.fin if hasattr(scene, "fin") else scene.plate


def from_medium(scene: Any) -> bool:
    """Whether the scene's sandswim law takes c_s, c_f and gamma0 from its [medium] (all three left at 0)."""
    return scene.rft.law == "sandswim" and sandswim.from_medium(scene.rft)


def segment_scale(scene: Any) -> float:
    """A chain segment's face area x mean depth (m^3), which its law's intensive coefficients are multiplied by."""
    return laws.segment_scale(chain_of(scene).segment_length, scene.medium.height, scene.medium.depth)


def chain_law(scene: Any) -> tuple[SegmentLaw, float]:
    """The law of one segment of the scene's chain (N) and the segment's scale (m^3)."""
    m, length = scene.medium, chain_of(scene).segment_length
    scale = segment_scale(scene)
    if from_medium(scene):
        fit = media.sandswim_coefficients(length, m.depth, m.height, *properties(scene))
        return SegmentLaw("sandswim", scene.rft.v_reg, {"c_s": fit.c_s, "c_f": fit.c_f, "gamma0": fit.gamma0}), scale
    return laws.per_segment(scene.rft, length, m.height, m.depth), scale


def segment_law(scene: Any) -> SegmentLaw | None:
    """The law of one segment of a chain scene (N), None for a scene without ``[rft]`` (a surface law's)."""
    return chain_law(scene)[0] if getattr(scene, "rft", None) is not None else None


def arm_law(scene: Any) -> SegmentLaw:
    """The law of one arm: the sand-swimming law fitted to 3D-RFT on the arm's face, or without a medium the
    authors' paper law whose normal coefficient grows with the arm's length."""
    a, m = scene.arm, scene.medium
    if properties(scene) is None:
        return SegmentLaw("paper", scene.rft.v_reg, {"f_perp": a.f_perp_base + a.f_perp_per_length * a.length,
                                                     "f_par": a.f_par})
    fit = media.sandswim_coefficients(a.length, m.depth, a.height, *properties(scene))
    return SegmentLaw("sandswim", scene.rft.v_reg, {"c_s": fit.c_s, "c_f": fit.c_f, "gamma0": fit.gamma0})


def body_resistance(scene: Any) -> dict[str, float]:
    """The whole robot's body resistance (N) from the medium: ``faces`` (3D-RFT on the body moving along its axis),
    ``cart`` (rolling) and their ``total``."""
    b = scene.body
    faces = _along_axis(b.length, scene.medium.depth, b.height, b.width, properties(scene))
    return {"faces": faces, "cart": b.cart, "total": faces + b.cart}


def body_drag(scene: Any) -> float:
    """The whole robot's body drag (N): body.drag, or from the medium the body's faces and the cart."""
    return scene.body.drag if properties(scene) is None else body_resistance(scene)["total"]


def resolve(scene: Any) -> Resolved:
    """A chain scene's forces (`Resolved`): done once per model build, by every consumer."""
    chain, scale = chain_law(scene)
    if hasattr(scene, "arm"):  # the robot (finrft.experiments.swim): its arms and body too
        return Resolved(chain, scale, arm_law(scene), body_drag(scene))
    return Resolved(chain, scale)


@functools.lru_cache(maxsize=256)
def _along_axis(length: float, depth: float, height: float, width: float,
                medium: tuple[float, float, float]) -> float:
    """3D-RFT's resistance (N) of a box moving along its axis: every gait evaluation builds the robot with it, and
    it costs a tenth of one."""
    _, along = media.plate_forces(np.zeros(1), length, depth, height, *medium, thickness=width)
    return float(along[0])
