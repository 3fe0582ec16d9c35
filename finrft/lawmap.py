"""A force law's stress map for a catalogued medium (``finrft law NAME``): the law draws it (its module's
``stress_map(medium)``, see `finrft.laws`), this module checks it and plots it, one panel per field over the map's
two angles."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import laws, media
from .errors import SceneError


def law_module(name: str):
    """The module of a law that draws its stress map; SceneError naming those that do."""
    mapped = laws.mapped()
    if name not in mapped:
        raise SceneError(f"unknown law {name!r}: the laws with a stress map are {', '.join(mapped)}")
    return mapped[name]


def stress_map(name: str, medium: str = "generic") -> dict[str, np.ndarray]:
    """The stress map of law ``name`` in the catalogued ``medium``: flat arrays of one length, the two grid axes
    (``*_deg``) first, then the fields (units: the law module's ``MAP_UNITS``)."""
    module = law_module(name)
    data = {key: np.asarray(value, dtype=float) for key, value in module.stress_map(media.medium(medium)).items()}
    keys = list(data)
    shapes = {a.shape for a in data.values()}
    # The law's side of the contract: a broken law fails loudly here rather than drawing a wrong picture.
    if len(shapes) != 1 or len(shapes.pop()) != 1:
        raise TypeError(f"{name}.stress_map must give flat arrays of one length")
    if len(keys) < 3 or not all(k.endswith("_deg") for k in keys[:2]) or not set(keys[2:]) <= set(module.MAP_UNITS):
        raise TypeError(f"{name}.stress_map must give two *_deg axes, then fields whose units MAP_UNITS gives")
    return data


def note(name: str, medium: str = "generic") -> str:
    """The law's one line on what its map in ``medium`` shows (its module's optional ``map_note``), or ""."""
    module = law_module(name)
    return module.map_note(media.medium(medium)) if hasattr(module, "map_note") else ""


def _label(key: str) -> str:
    return f"{key.removesuffix('_deg')} (deg)"


def plot(name: str, medium: str, data: dict[str, np.ndarray], path: str | Path) -> None:
    """The map as a figure (PNG): one colour map per field over its two angles, its unit on the colour bar, the
    law and the medium in the title."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import CenteredNorm
    from matplotlib.ticker import MultipleLocator

    material = media.medium(medium)
    module = law_module(name)
    units = module.MAP_UNITS
    (xkey, x), (ykey, y), *fields = data.items()
    xs, xi = np.unique(x, return_inverse=True)
    ys, yi = np.unique(y, return_inverse=True)
    extra = note(name, medium)
    fig, axes = plt.subplots(1, len(fields), figsize=(5.2 * len(fields), 4.7 if extra else 4.4), squeeze=False)
    for ax, (key, values) in zip(axes[0], fields):
        grid = np.full((len(ys), len(xs)), np.nan)
        grid[yi, xi] = values
        # Diverging about zero: the sign of a stress (resisting or pulling) reads at a glance.
        mesh = ax.pcolormesh(xs, ys, grid, shading="nearest", cmap="RdBu_r", norm=CenteredNorm(0.0))
        if np.nanmin(grid) < 0 < np.nanmax(grid):
            ax.contour(xs, ys, grid, levels=[0.0], colors="k", linewidths=0.8)
        fig.colorbar(mesh, ax=ax, label=f"{key} ({units[key]})")
        ax.set(xlabel=_label(xkey), ylabel=_label(ykey), title=key, aspect="equal")
        for axis, values in ((ax.xaxis, xs), (ax.yaxis, ys)):  # about 7 ticks, on round numbers of degrees
            span = values.max() - values.min()
            axis.set_major_locator(MultipleLocator(next(s for s in (5, 10, 15, 30, 45, 90) if span <= 6 * s)))
    quantity = getattr(module, "MAP_QUANTITY", "stress per unit depth")
    fig.suptitle(f"{name} {quantity}, medium {material.name}: {material.description}"
                 + (f"\n{extra}" if extra else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=120)
    plt.close(fig)
