"""The free surfaces (finrft.surfaces) and their C twins (plugins/surfaces/): depth along gravity, invariance
under a rotation of the whole scene, the kinds' agreement where they describe the same surface, and the deforming
surface's conservation of sand and relaxation to the angle of repose."""

import ctypes

import numpy as np
import pytest

from finrft import media, native, surfaces
from finrft.errors import SceneError
from finrft.surfaces import deforming, hfield, plane

G = np.array([0.0, 0.0, -9.81])
SIZE = (0.1, 0.08)
REPOSE = media.medium("wheel_sand_cmu").get("angle_of_repose").value  # the wheel group's sand


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _points(n: int = 200, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform([-0.12, -0.1, -0.06], [0.12, 0.1, 0.04], size=(n, 3))


def _grid_xy(nrow: int, ncol: int) -> tuple[np.ndarray, np.ndarray]:
    x = np.linspace(-SIZE[0], SIZE[0], ncol)
    y = np.linspace(-SIZE[1], SIZE[1], nrow)
    return np.meshgrid(x, y)  # (nrow, ncol): rows along y, MuJoCo's layout


def _plane_heights(point, normal, nrow=9, ncol=13):
    """The heights of a plane on the grid, measured along +z (gravity -z)."""
    x, y = _grid_xy(nrow, ncol)
    n = np.asarray(normal, float)
    return point[2] - (n[0] * (x - point[0]) + n[1] * (y - point[1])) / n[2]


def test_depth_is_measured_along_gravity():
    # a point 1 cm straight below a 30 deg slope's surface, with gravity along -z: 1 cm deep, not 1 cm x cos 30
    normal = (-np.sin(np.radians(30)), 0.0, np.cos(np.radians(30)))
    depth, up = surfaces.surface_depth("plane", [[0.05, 0.0, 0.05 * np.tan(np.radians(30)) - 0.01]], G,
                                       surface_point=(0, 0, 0), surface_normal=normal)
    assert depth == pytest.approx([0.01], abs=1e-15)
    assert np.allclose(up, [[0, 0, 1]])
    above, _ = surfaces.surface_depth("flat", [[0, 0, 0.02]], G, surface_z=0.01)
    assert above[0] == pytest.approx(-0.01)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rotating_the_scene_leaves_depths_unchanged(seed):
    R = _rotation(seed)
    p, m, n = _points(), np.array([0.01, -0.02, 0.005]), np.array([0.2, -0.1, 1.0])
    before = plane.depth(p, G, surface_point=m, surface_normal=n)
    after = plane.depth(p @ R.T, R @ G, surface_point=R @ m, surface_normal=R @ n)
    assert np.abs(after - before).max() < 1e-9
    heights = _plane_heights(m, n) + 0.003 * np.sin(np.arange(9 * 13).reshape(9, 13))
    centre = np.array([0.003, 0.002, -0.01])
    grid_before = hfield.depth(p, G, heights, SIZE, centre)
    grid_after = hfield.depth(p @ R.T, R @ G, heights, SIZE, R @ centre, R)
    assert np.abs(grid_after - grid_before).max() < 1e-9
    up = surfaces.surface_depth("plane", p @ R.T, R @ G, surface_point=R @ m, surface_normal=R @ n)[1]
    assert np.abs(up - R @ [0, 0, 1]).max() < 1e-12


def test_a_plane_that_is_flat_gives_flat_depths():
    p = _points()
    tilted_g = np.array([1.0, -2.0, -9.0])  # depth along a tilted gravity, still the same surface
    for g in (G, tilted_g):
        flat = surfaces.module("flat").depth(p, g, surface_z=0.013)
        same = plane.depth(p, g, surface_point=(0.4, -0.7, 0.013), surface_normal=(0, 0, 2.0))
        assert np.abs(flat - same).max() < 1e-12
    assert np.abs(surfaces.module("flat").depth(p, G, surface_z=0.013) - (0.013 - p[:, 2])).max() < 1e-15


def test_an_hfield_of_a_planes_heights_gives_its_depths():
    m, n = np.array([0.01, 0.02, -0.005]), np.array([0.3, -0.2, 1.0])
    p = _points()
    p = p[(np.abs(p[:, 0]) <= SIZE[0]) & (np.abs(p[:, 1]) <= SIZE[1])]  # bilinear holds the plane on the grid
    grid = hfield.depth(p, G, _plane_heights(m, n), SIZE)
    assert np.abs(grid - plane.depth(p, G, surface_point=m, surface_normal=n)).max() < 1e-12


def test_bad_surfaces_are_refused():
    with pytest.raises(SceneError, match="against gravity"):
        plane.depth(_points(3), G, surface_normal=(0, 0, -1))
    with pytest.raises(SceneError, match="level with gravity"):
        hfield.depth(_points(3), G, np.zeros((3, 3)), SIZE, frame=_rotation(0))
    with pytest.raises(SceneError, match="nonzero gravity"):
        plane.depth(_points(3), [0, 0, 0])
    with pytest.raises(SceneError, match="one area and one velocity per point"):
        deforming.sweep(np.zeros((3, 3)), _points(3), [1e-4], np.zeros((3, 3)), G, SIZE)
    with pytest.raises(SceneError, match="angle of repose"):
        deforming.relax(np.zeros((3, 3)), SIZE, np.radians(95))
    with pytest.raises(SceneError, match="tolerance"):
        deforming.relax(np.zeros((3, 3)), SIZE, REPOSE, tolerance=0.0)
    with pytest.raises(SceneError, match="unknown surface 'slope'"):
        surfaces.module("slope")


def test_the_wheel_groups_pile_rule():
    original = np.zeros((9, 13))
    raised = original + 0.01  # 1 cm of sand piled everywhere
    points = np.array([[0, 0, 0.004], [0, 0, -0.02], [0, 0, 0.02]])
    plain = deforming.depth(points, G, raised, SIZE)
    ruled = deforming.depth(points, G, raised, SIZE, original=original,
                            pile_factor=deforming.WHEEL_GROUP_PILE_FACTOR)
    assert plain == pytest.approx([0.006, 0.03, -0.01])
    # in the pile: its depth times 0.2843; below the original: the lesser depth; above both: none
    assert ruled[:2] == pytest.approx([0.006 * 0.2843, 0.02]) and ruled[2] <= 0


def _wheel_pass(heights, x0, steps=1, shift=0.004):
    """A row of elements across a rut, 2 cm deep, moving along +x, shifted ``shift`` per step."""
    y = np.linspace(-0.02, 0.02, 9)
    for k in range(steps):
        points = np.c_[np.full(9, x0 + k * shift), y, np.full(9, -0.02)]
        yield heights, points, np.full(9, 2e-5), np.tile([0.1, 0.0, -0.01], (9, 1))


def test_a_sweep_conserves_sand_and_raises_a_berm_ahead():
    heights = np.zeros((33, 41))
    (h, points, areas, velocities), = _wheel_pass(heights, 0.0)
    swept, occupied = deforming.sweep(h, points, areas, velocities, G, SIZE)
    displaced = np.clip(heights - swept, 0.0, None).sum()  # x dx dy: the volume the elements displaced
    assert displaced > 0 and abs(swept.sum() - heights.sum()) <= 1e-6 * displaced
    assert swept.min() == pytest.approx(-0.02) and occupied.sum() >= 9
    x, _ = _grid_xy(33, 41)
    assert swept[x > 0.002].sum() > 0.4 * swept[swept > 0].sum()  # the front share lies ahead


def test_rotating_the_scene_leaves_the_deformed_surface_unchanged():
    R = _rotation(6)
    heights, turned = np.zeros((25, 31)), np.zeros((25, 31))
    # off the grid's half-way lines, where the nearest grid point is a tie that rounding breaks either way
    y = np.linspace(-0.0203, 0.0197, 9)
    for step in range(10):
        points = np.c_[np.full(9, -0.0513 + 0.0043 * step), y, np.full(9, -0.012)]
        velocities, areas = np.tile([0.1, 0.03, -0.01], (9, 1)), np.full(9, 3e-5)
        heights = deforming.update(heights, points, areas, velocities, G, SIZE, REPOSE).heights
        turned = deforming.update(turned, points @ R.T, areas, velocities @ R.T, R @ G, SIZE, REPOSE,
                                  frame=R).heights
    assert np.abs(heights).max() > 0.005 and np.abs(turned - heights).max() < 1e-9


def _slopes(h, size=SIZE):
    nrow, ncol = h.shape
    dx, dy = 2 * size[0] / (ncol - 1), 2 * size[1] / (nrow - 1)
    return max(np.abs(np.diff(h, axis=1)).max() / dx, np.abs(np.diff(h, axis=0)).max() / dy)


def test_relaxation_conserves_sand_and_ends_at_the_angle_of_repose():
    spike = np.zeros((33, 41))
    spike[16, 20] = 0.05  # a spike of sand, far steeper than repose
    rough = np.random.default_rng(7).uniform(0.0, 0.02, (33, 41))  # slopes up to 3, every cell
    for h in (spike, rough):
        relaxed = deforming.relax(h, SIZE, REPOSE)
        assert relaxed.converged
        assert abs(relaxed.heights.sum() - h.sum()) <= 1e-6 * np.abs(relaxed.heights - h).sum()
        assert _slopes(h) > 2 * np.tan(REPOSE) and _slopes(relaxed.heights) <= np.tan(REPOSE) + deforming.TOLERANCE
    assert deforming.relax(spike, SIZE, REPOSE).heights.max() < 0.05 / 4  # the spike did spread


def test_a_slope_below_repose_is_left_unchanged():
    x, y = _grid_xy(17, 21)
    h = np.tan(np.radians(25)) * x + 0.2 * np.tan(np.radians(25)) * y  # steepest 25.5 deg: below 29
    relaxed = deforming.relax(h, SIZE, REPOSE)
    assert relaxed.iterations == 0 and np.array_equal(relaxed.heights, h)


@pytest.fixture(scope="module")
def library():
    lib = ctypes.CDLL(str(native.library_path()))
    d, i, u8 = ctypes.POINTER(ctypes.c_double), ctypes.c_int, ctypes.POINTER(ctypes.c_ubyte)
    f = ctypes.c_double
    lib.finrft_flat_depth.argtypes = [f, d, i, d, d]
    lib.finrft_plane_depth.argtypes = [d, d, d, i, d, d]
    lib.finrft_hfield_depth.argtypes = [i, i, d, d, d, d, d, i, d, d]
    lib.finrft_deforming_depth.argtypes = [i, i, d, d, f, d, d, d, d, i, d, d]
    lib.finrft_deforming_sweep.argtypes = [i, i, d, d, d, d, d, i, d, d, d, f, u8]
    lib.finrft_deforming_relax.argtypes = [i, i, d, d, f, u8, f, i]
    return lib


def _p(a):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _c(values):
    return np.ascontiguousarray(values, dtype=float)


def test_c_twins_agree_on_fixed_surfaces(library):
    R, p = _rotation(3), _c(_points())
    g, m, n = _c(R @ G), _c(R @ [0.01, -0.02, 0.005]), _c(R @ [0.2, -0.1, 1.0])
    out = np.empty(len(p))
    assert library.finrft_flat_depth(0.013, _p(_c(G)), len(p), _p(p), _p(out)) == 0
    assert np.abs(out - surfaces.module("flat").depth(p, G, surface_z=0.013)).max() < 1e-9
    assert library.finrft_plane_depth(_p(m), _p(n), _p(g), len(p), _p(p), _p(out)) == 0
    assert np.abs(out - plane.depth(p, g, surface_point=m, surface_normal=n)).max() < 1e-9
    heights = _c(0.01 * np.cos(np.arange(9 * 13)).reshape(9, 13))
    centre, frame = _c(R @ [0.003, 0.002, -0.01]), _c(R)
    assert library.finrft_hfield_depth(9, 13, _p(heights), _p(_c(SIZE)), _p(centre), _p(frame), _p(g), len(p),
                                       _p(p), _p(out)) == 0
    assert np.abs(out - hfield.depth(p, g, heights, SIZE, centre, R)).max() < 1e-9
    original = _c(heights - 0.004)
    assert library.finrft_deforming_depth(9, 13, _p(heights), _p(original), 0.2843, _p(_c(SIZE)), _p(centre),
                                          _p(frame), _p(g), len(p), _p(p), _p(out)) == 0
    assert np.abs(out - deforming.depth(p, g, heights, SIZE, centre, R, original, 0.2843)).max() < 1e-9
    assert library.finrft_plane_depth(_p(m), _p(-n), _p(g), len(p), _p(p), _p(out)) != 0  # refused as the twin


def test_c_twin_of_the_deforming_surface_agrees_over_many_updates(library):
    nrow, ncol = 25, 31
    R = _rotation(4)
    g, centre, frame = _c(R @ G), _c(R @ [0.01, 0.0, 0.0]), _c(R)
    size = _c(SIZE)
    heights = np.zeros((nrow, ncol))
    twin = heights.copy()
    occupied = np.zeros(nrow * ncol, np.ubyte)
    rng = np.random.default_rng(5)
    for step in range(30):
        x = -0.06 + 0.004 * step
        local = np.c_[np.full(9, x), np.linspace(-0.02, 0.02, 9), np.full(9, -0.015)] + rng.normal(0, 1e-4, (9, 3))
        points, velocities = _c(local @ R.T + R @ [0.01, 0.0, 0.0]), _c(np.tile(R @ [0.1, 0.02, -0.01], (9, 1)))
        areas = _c(np.full(9, 3e-5))
        heights = deforming.update(heights, points, areas, velocities, g, SIZE, REPOSE, centre, R).heights
        assert library.finrft_deforming_sweep(nrow, ncol, _p(twin), _p(size), _p(centre), _p(frame), _p(g), 9,
                                              _p(points), _p(areas), _p(velocities), deforming.FRONT_SHARE,
                                              occupied.ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte))) == 0
        assert library.finrft_deforming_relax(nrow, ncol, _p(twin), _p(size), REPOSE,
                                              occupied.ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte)),
                                              deforming.TOLERANCE, deforming.MAX_ITERATIONS) >= 0
    assert np.abs(heights).max() > 0.01  # a rut and a berm were made
    spike = np.zeros((33, 41))
    spike[5, 30] = 0.05  # the C relaxation looks only where sand moved: the same heights as the whole grid's
    relaxed, twin_spike = deforming.relax(spike, SIZE, REPOSE), _c(spike)
    iterations = library.finrft_deforming_relax(33, 41, _p(twin_spike), _p(size), REPOSE, None, deforming.TOLERANCE,
                                                deforming.MAX_ITERATIONS)
    assert iterations == relaxed.iterations and np.abs(twin_spike - relaxed.heights).max() < 1e-12
    assert np.abs(twin - heights).max() < 1e-6
    assert abs(twin.sum()) <= 1e-6 * np.abs(twin).sum() and abs(heights.sum()) <= 1e-6 * np.abs(heights).sum()


def test_the_surfaces_are_installed_with_finrft():
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    packages = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    assert "finrft.surfaces" in packages
    assert sorted(Path(root, "plugins", "surfaces").glob("*.c"))  # compiled by setup.py's source list


def test_a_relaxed_region_stays_still_while_another_flows():
    # a slope within the tolerance above repose on one side, a spike on the other: only the spike's sand moves
    x, y = _grid_xy(33, 41)
    h = (np.tan(REPOSE) + 0.5 * deforming.TOLERANCE) * np.minimum(x + 0.03, 0.0)
    h[16, 35] = 0.05
    relaxed = deforming.relax(h, SIZE, REPOSE)
    assert relaxed.converged and relaxed.iterations > 3
    assert np.array_equal(relaxed.heights[:, x[0] < -0.035], h[:, x[0] < -0.035])


def test_the_c_step_of_a_run_agrees_with_its_twin():
    # a row of elements cutting a rut across the grid and leaving it: sweep, relaxation carried over from step to
    # step (the C step relaxes only where sand can still flow), the level under the body and the rut it leaves
    R = _rotation(8)
    surfaces_ = [deforming.DeformingSurface(np.zeros((31, 37)), SIZE, REPOSE, (0.01, 0.0, 0.0), R, native=native)
                 for native in (True, False)]
    y = np.linspace(-0.0203, 0.0197, 9)
    removed = np.zeros(2)
    for step in range(40):
        depth = -0.015 if step < 30 else 0.02  # out of the sand for the last ten
        local = np.c_[np.full(9, -0.0713 + 0.0043 * step), y, np.full(9, depth)]
        points, velocities = local @ R.T + R @ [0.01, 0.0, 0.0], np.tile(R @ [0.1, 0.02, -0.01], (9, 1))
        for k, s in enumerate(surfaces_):
            removed[k] += s.step(points, np.full(9, 3e-5), velocities, R @ G, imprint=step == 0)
    native, twin = surfaces_
    assert np.abs(native.heights).max() > 0.01 and removed[0] > 0
    assert np.abs(native.heights - twin.heights).max() < 1e-9 and np.abs(native.level - twin.level).max() < 1e-9
    assert abs(removed[0] - removed[1]) < 1e-9 * removed[0] and np.abs(native.original - twin.original).max() < 1e-9
    assert abs(native.volume() - twin.volume()) < 1e-6 * removed[0]


def _plough(surface: deforming.DeformingSurface, normal: tuple[float, float, float],
            steps: int = 25) -> tuple[float, float]:
    """A row of nine elements 15 mm deep dragged along +x across ``surface`` at 10 mm/s, each facing ``normal``:
    the volume (m^3) the surface lost from under them and its sand (`sand`) after the first step, the body's
    imprint."""
    y = np.linspace(-0.016, 0.016, 9)
    removed, imprinted = 0.0, 0.0
    for step in range(steps):
        points = np.c_[np.full(9, -0.05 + 0.002 * step), y, np.full(9, -0.015)]
        removed += surface.step(points, np.full(9, 1.6e-5), np.tile([0.01, 0.0, 0.0], (9, 1)), G,
                                imprint=step == 0, normals=np.tile(normal, (9, 1)))
        imprinted = surface.sand() if step == 0 else imprinted
    return removed, imprinted


def test_compaction_keeps_its_share_of_the_swept_sand_under_the_body():
    # one sweep (no relaxation): the sand lost from under the elements goes (1 - c) to the berm, c compacted
    x, y = _grid_xy(33, 41)
    heights = 0.002 * np.cos(60 * x) * np.sin(40 * y)
    points = np.c_[np.linspace(-0.03, 0.03, 13), np.linspace(-0.01, 0.02, 13), np.full(13, -0.012)]
    velocities = np.tile([0.01, -0.004, -0.002], (13, 1))
    for c in (0.0, 0.3, 1.0):
        compacted = np.zeros(heights.shape)
        swept, occupied = deforming.sweep(heights, points, np.full(13, 4e-5), velocities, G, SIZE, compaction=c,
                                          compacted=compacted)
        lost, berm = np.clip(heights - swept, 0, None).sum(), np.clip(swept - heights, 0, None).sum()
        assert lost > 0 and occupied.any() and (swept[~occupied] >= heights[~occupied]).all()
        assert berm == pytest.approx((1 - c) * lost, rel=1e-12) and compacted.sum() == pytest.approx(c * lost)


@pytest.mark.parametrize("native", [True, False])
def test_compaction_conserves_the_grains_not_the_volume(native):
    for c in (0.0, 0.3, 1.0):
        s = deforming.DeformingSurface(np.zeros((33, 41)), SIZE, REPOSE, native=native, compaction=c)
        displaced, imprinted = _plough(s, (1.0, 0.0, 0.0))  # the first step, the imprint, is no flow of sand
        # the grains are conserved: their volume at the bulk density, the heights' and the compacted
        assert displaced > 0 and abs(s.sand() - imprinted) <= 1e-9 * displaced
        assert s.volume() == pytest.approx(imprinted - s.cell * s.compacted.sum(), abs=1e-9 * displaced)
        assert (s.compacted.sum() > 0) == (c > 0)
        if c == 1.0:
            assert s.heights.max() <= 0  # all compacted: no berm


def test_a_facing_berm_goes_to_the_side_the_element_faces():
    # elements dragged along +x: with the berm rule "velocity" their sand goes ahead (+x) and to both sides alike;
    # facing +y (a wall dragged along its own plane, leading by a hair) its front share goes to +y, its side shares
    # ahead and behind, and -y gets only what relaxation spills there
    heights = {}
    for berm, normal in (("velocity", (0.0, 1.0, 0.0)), ("facing", (0.02, 1.0, 0.0))):
        s = deforming.DeformingSurface(np.zeros((33, 41)), SIZE, REPOSE, berm=berm)
        _plough(s, np.array(normal) / np.linalg.norm(normal))
        heights[berm] = s.heights
    x, y = _grid_xy(33, 41)
    berm = {k: np.clip(h, 0, None) for k, h in heights.items()}
    side = {k: (h[y > 0.02].sum(), h[y < -0.02].sum(), h[(x > 0.01) & (np.abs(y) < 0.016)].sum())
            for k, h in berm.items()}
    assert side["velocity"][0] == pytest.approx(side["velocity"][1], rel=0.05) and side["velocity"][2] > 0
    assert side["facing"][0] > 10 * side["facing"][1] and side["facing"][2] > 0


def test_the_c_twin_agrees_on_compaction_and_facing_berms():
    R = _rotation(9)
    surfaces_ = [deforming.DeformingSurface(np.zeros((31, 37)), SIZE, REPOSE, (0.01, 0.0, 0.0), R, native=native,
                                            compaction=0.35, berm="facing") for native in (True, False)]
    rng = np.random.default_rng(2)
    y = np.linspace(-0.0203, 0.0197, 9)
    for step in range(30):
        # depths apart: elements level to rounding at a shared grid point would give it either's direction
        local = np.c_[np.full(9, -0.0713 + 0.0043 * step), y, -0.015 + rng.normal(0, 1e-4, 9)]
        normals = rng.normal(size=(9, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        for s in surfaces_:
            s.step(local @ R.T + R @ [0.01, 0.0, 0.0], np.full(9, 3e-5), np.tile(R @ [0.1, 0.02, -0.01], (9, 1)),
                   R @ G, imprint=step == 0, normals=normals @ R.T)
    native, twin = surfaces_
    assert native.compacted.sum() > 0 and np.abs(native.heights).max() > 0.005
    assert np.abs(native.heights - twin.heights).max() < 1e-6 and np.abs(native.level - twin.level).max() < 1e-6
    assert np.abs(native.compacted - twin.compacted).max() < 1e-6


def test_bad_compaction_and_berm_rules_are_refused():
    with pytest.raises(SceneError, match="compaction"):
        deforming.DeformingSurface(np.zeros((5, 5)), SIZE, REPOSE, compaction=1.5)
    with pytest.raises(SceneError, match="berm"):
        deforming.DeformingSurface(np.zeros((5, 5)), SIZE, REPOSE, berm="sideways")
    s = deforming.DeformingSurface(np.zeros((5, 5)), SIZE, REPOSE, berm="facing")
    with pytest.raises(SceneError, match="normals"):
        s.step(np.zeros((1, 3)), np.ones(1), np.ones((1, 3)), G)


def test_bad_surface_steps_are_refused():
    with pytest.raises(SceneError, match="surface update"):
        deforming.DeformingSurface(np.zeros((5, 5)), SIZE, REPOSE, move=0.0)
    with pytest.raises(SceneError, match="tolerance"):
        deforming.DeformingSurface(np.zeros((5, 5)), SIZE, REPOSE, tolerance=float("nan"))
    # the C step looks at the heights once, at the imprint; after it, an element's point or velocity that is not a
    # number is refused before it can reach them
    s = deforming.DeformingSurface(np.zeros((9, 9)), SIZE, REPOSE)
    s.step(np.array([[0.0, 0.0, -0.001]]), np.ones(1) * 1e-6, np.array([[0.01, 0.0, 0.0]]), G, imprint=True)
    before = s.heights.copy()
    for bad in ("points", "velocities"):
        points, velocities = np.array([[0.0, 0.0, -0.002]]), np.array([[0.01, 0.0, 0.0]])
        (points if bad == "points" else velocities)[0, 0] = np.nan
        with pytest.raises(SceneError, match="refused"):
            s.step(points, np.ones(1) * 1e-6, velocities, G)
        assert np.array_equal(s.heights, before)
