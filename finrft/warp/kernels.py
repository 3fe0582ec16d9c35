"""The surface laws as Warp functions and the kernels that run them over worlds x elements: the Warp twin of
plugins/finrft_surface.c (finrft_li2013_element_force, finrft_rft3d_element_force, finrft_drft_element_force,
finrft_surface_element_force and finrft_surface_wrench), line for line, in float64.

MuJoCo Warp's state is float32; the laws are not: `body_states` widens each attached body's pose and twist to
float64 once per step, every element's force and the bodies' wrenches are summed in float64, and only
`apply_wrenches` narrows the generalized force into ``qfrc_passive``. So the laws, given the native run's float64
state, give its numbers to rounding (tests/test_warp.py).

The laws' numbers are not written here: the coefficients come in as arrays from the law's ``Coefficients``
(`finrft.laws.li2013`, `finrft.laws.rft3d`), and the constants below from those modules and `finrft.laws`, the one
source the C and numpy twins are tested against too.
"""

from __future__ import annotations

import math

import warp as wp

from .. import laws
from ..laws import li2013

f64 = wp.float64

# Treers et al.'s weights (li2013.F1_FIT, F23_FIT) folded as weight_across and weight_within fold them.
_A1, _B1, _C1, _D1 = li2013.F1_FIT
_A23, _B23, _C23, _D23 = li2013.F23_FIT
F1_SCALE = wp.constant(f64(_A1 / (_D1 * math.cosh(_C1))))
F1_TWO_B = wp.constant(f64(2 * _B1))
F1_EXP_C = wp.constant(f64(math.exp(-_C1)))
F1_TWO_COSH = wp.constant(f64(2 * math.cosh(_C1)))
F23_SCALE = wp.constant(f64(_A23 / (2 * _D23)))
F23_B = wp.constant(f64(_B23))
F23_REST = wp.constant(f64(1 + _C23))
F23_Q = wp.constant(f64(2 / (1 - _C23)))
# 1 / li2013.HORIZONTAL as the C code writes it
TILT = wp.constant(f64(1 / math.sqrt(1 - (1 - 1e-3) * (1 - 1e-3))))
RAMP_FLOOR = wp.constant(f64(laws.RAMP_FLOOR))
ZERO = wp.constant(f64(0.0))
ONE = wp.constant(f64(1.0))
TWO = wp.constant(f64(2.0))
THREE = wp.constant(f64(3.0))
TANH_ONE = wp.constant(f64(20.0))  # tanh is 1 in double from 19.1 on (as the C code)

LI2013, RFT3D = 0, 1  # the laws the kernels run, by number


@wp.func
def norm2(x: f64, y: f64) -> f64:
    return wp.sqrt(x * x + y * y)


@wp.func
def alpha_unit(coef: wp.array(dtype=f64), zeta: f64, cb: f64, sb_in: f64, cg_in: f64, sg: f64) -> wp.vec2d:
    """(alpha_x, alpha_z) at beta, gamma given by their cosines and sines (alpha_unit in the C twin)."""
    cg = cg_in
    sb = sb_in
    mirrored = cg < ZERO
    if mirrored:
        cg = -cg
        sb = -sb
    c2 = cb * cb - sb * sb
    s2 = TWO * sb * cb
    sum_sin = s2 * cg + c2 * sg
    diff_sin = c2 * sg - s2 * cg
    sum_cos = c2 * cg - s2 * sg
    diff_cos = c2 * cg + s2 * sg
    az = coef[0] + coef[1] * c2 + coef[2] * sum_sin + coef[3] * sg + coef[4] * diff_sin
    ax = coef[5] * sum_cos + coef[6] * cg + coef[7] * diff_cos + coef[8] * s2
    if mirrored:
        ax = -ax
    return wp.vec2d(zeta * ax, zeta * az)


@wp.func
def unit_angle(y: f64, x: f64) -> wp.vec2d:
    """The cosine and sine of atan2(y, x) (1 and 0 at the origin)."""
    size = norm2(x, y)
    inverse = ZERO
    c = ONE
    if size > ZERO:
        inverse = ONE / size
        c = x * inverse
    return wp.vec2d(c, y * inverse)


@wp.func
def weight_across(size: f64) -> f64:
    grow = wp.exp(F1_TWO_B * size)
    below = F1_EXP_C * (grow - ONE) + F1_TWO_COSH
    return F1_SCALE * (grow - ONE) / below


@wp.func
def weight_within(size: f64) -> f64:
    u = F23_B * size
    rest = F23_REST - u
    q = F23_Q * u / rest
    return F23_SCALE * wp.log(ONE + q)


@wp.func
def horizontal_unit(a: wp.vec3d, b: wp.vec3d) -> wp.vec2d:
    size = norm2(a[0], a[1])
    px = a[0]
    py = a[1]
    if not (size > ZERO):
        size = norm2(b[0], b[1])
        px = b[0]
        py = b[1]
    if size > ZERO:
        inverse = ONE / size
        return wp.vec2d(px * inverse, py * inverse)
    return wp.vec2d(ONE, ZERO)


@wp.func
def plane_stress(coef: wp.array(dtype=f64), zeta: f64, e2: wp.vec2d, side_in: f64, f23: f64, cb: f64, sb: f64,
                 cg: f64, sg: f64) -> wp.vec3d:
    e1 = wp.vec2d(e2[1], -e2[0])
    side = side_in * (zeta * (coef[5] + coef[6] + coef[7]))
    a = alpha_unit(coef, zeta, cb, sb, cg, sg)
    return wp.vec3d(-side * e1[0] - f23 * a[0] * e2[0], -side * e1[1] - f23 * a[0] * e2[1], f23 * a[1])


@wp.func
def li2013_force(coef: wp.array(dtype=f64), zeta: f64, n: wp.vec3d, v: wp.vec3d, depth: f64,
                 area: f64) -> wp.vec3d:
    """finrft_li2013_element_force: Li 2013 in 3D (Treers, Cao & Stuart 2021), its blend of flat faces included."""
    if not (depth > ZERO) or not (wp.dot(n, v) > ZERO):
        return wp.vec3d(ZERO, ZERO, ZERO)
    speed = wp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    sideways = norm2(n[0], n[1])
    tilt = sideways * TILT
    if tilt > ONE:
        tilt = ONE
    w = tilt * tilt * (THREE - TWO * tilt)
    stress = wp.vec3d(ZERO, ZERO, ZERO)
    if w > ZERO:
        inverse = ONE / (sideways * speed)
        across = (v[0] * n[1] - v[1] * n[0]) * inverse
        along = v[0] * n[0] + v[1] * n[1]
        lift = v[2] * sideways
        within = norm2(along, lift)
        cg = ONE
        sg = ZERO
        if within > ZERO:
            scale = ONE / within
            cg = along * scale
            sg = -lift * scale
        e2 = wp.vec2d(n[0] * speed * inverse, n[1] * speed * inverse)
        sign = ZERO
        if across > ZERO:
            sign = ONE
        elif across < ZERO:
            sign = -ONE
        side = weight_across(wp.abs(across)) * sign
        stress = plane_stress(coef, zeta, e2, side, weight_within(within * inverse), n[2], -sideways, cg, sg)
    if w < ONE:
        inverse = ONE / speed
        e2 = horizontal_unit(v, n)
        angle = unit_angle(-(n[0] * e2[0] + n[1] * e2[1]), n[2])
        own = plane_stress(coef, zeta, e2, ZERO, weight_within(ONE), angle[0], angle[1],
                           (v[0] * e2[0] + v[1] * e2[1]) * inverse, -v[2] * inverse)
        stress = w * stress + (ONE - w) * own
    return (area * depth) * stress


@wp.func
def rft3d_force(coef: wp.array(dtype=f64), xi: f64, mu_surf: f64, n: wp.vec3d, v: wp.vec3d, depth: f64,
                area: f64) -> wp.vec3d:
    """finrft_rft3d_element_force: the 3D-RFT of Agarwal, Goldman & Kamrin 2023 with its surface-friction cap."""
    if not (depth > ZERO) or not (wp.dot(n, v) > ZERO):
        return wp.vec3d(ZERO, ZERO, ZERO)
    speed = wp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    u = wp.vec3d(v[0] / speed, v[1] / speed, v[2] / speed)
    side = -ONE
    if n[2] < ZERO:
        side = ONE
    low = side * n
    p1 = -u[2]
    p2 = -low[2]
    p3 = low[0] * u[0] + low[1] * u[1] + low[2] * u[2]
    f = wp.vec3d(ZERO, ZERO, ZERO)
    for k in range(3):
        b = 20 * k
        # the 20 monomials in the order of rft3d.terms
        s = coef[b + 0] * ONE + coef[b + 1] * p1
        s += coef[b + 2] * p2
        s += coef[b + 3] * p3
        s += coef[b + 4] * (p1 * p1)
        s += coef[b + 5] * (p2 * p2)
        s += coef[b + 6] * (p3 * p3)
        s += coef[b + 7] * (p1 * p2)
        s += coef[b + 8] * (p2 * p3)
        s += coef[b + 9] * (p3 * p1)
        s += coef[b + 10] * (p1 * p1 * p1)
        s += coef[b + 11] * (p2 * p2 * p2)
        s += coef[b + 12] * (p3 * p3 * p3)
        s += coef[b + 13] * (p1 * p2 * p2)
        s += coef[b + 14] * (p2 * p1 * p1)
        s += coef[b + 15] * (p2 * p3 * p3)
        s += coef[b + 16] * (p3 * p2 * p2)
        s += coef[b + 17] * (p3 * p1 * p1)
        s += coef[b + 18] * (p1 * p3 * p3)
        s += coef[b + 19] * (p1 * p2 * p3)
        f[k] = s
    stress = f[0] * low + f[1] * u
    stress[2] = stress[2] - f[2]
    along = stress[0] * n[0] + stress[1] * n[1] + stress[2] * n[2]
    normal_part = along * n
    tangential = stress - normal_part
    cap = mu_surf * wp.length(normal_part)
    size = wp.length(tangential)
    kept = ONE
    if size > cap:
        kept = cap / size
    return (xi * area * depth) * (normal_part + kept * tangential)


@wp.func
def drft_force(drft_lambda: f64, rho_c: f64, n: wp.vec3d, v: wp.vec3d, depth: f64, area: f64) -> wp.vec3d:
    """finrft_drft_element_force: DRFT's -lambda rho_c (n . v)^2 n area on a leading element below the surface."""
    v_n = n[0] * v[0] + n[1] * v[1] + n[2] * v[2]
    if not (depth > ZERO) or not (v_n > ZERO):
        return wp.vec3d(ZERO, ZERO, ZERO)
    return -(drft_lambda * rho_c * v_n * v_n * area) * n


@wp.func
def element_force(law: int, coef: wp.array(dtype=f64), scale: f64, mu_surf: f64, drft_lambda: f64, rho_c: f64,
                  v_reg: f64, n: wp.vec3d, v: wp.vec3d, depth: f64, area: f64) -> wp.vec3d:
    """finrft_surface_element_force under gravity along -z: the law's force, plus DRFT's term, times the ramp
    tanh(max(n . v, 0) / v_reg), none up to n . v = RAMP_FLOOR v_reg."""
    v_n = wp.dot(n, v)
    if v_reg > ZERO and not (v_n > RAMP_FLOOR * v_reg):
        return wp.vec3d(ZERO, ZERO, ZERO)
    f = wp.vec3d(ZERO, ZERO, ZERO)
    if law == LI2013:
        f = li2013_force(coef, scale, n, v, depth, area)
    else:
        f = rft3d_force(coef, scale, mu_surf, n, v, depth, area)
    if drft_lambda > ZERO:
        f = f + drft_force(drft_lambda, rho_c, n, v, depth, area)
    if v_reg > ZERO:
        ratio = wp.max(v_n, ZERO) / v_reg
        if ratio < TANH_ONE:
            f = wp.tanh(ratio) * f
    return f


@wp.kernel
def body_states(body: wp.array(dtype=int), rootid: wp.array(dtype=int), xpos: wp.array2d(dtype=wp.vec3),
                xmat: wp.array2d(dtype=wp.mat33), cvel: wp.array2d(dtype=wp.spatial_vector),
                subtree_com: wp.array2d(dtype=wp.vec3), origin: wp.array2d(dtype=wp.vec3d),
                rotation: wp.array2d(dtype=wp.mat33d), twist: wp.array2d(dtype=wp.spatial_vectord)):
    """Each attached body's origin, rotation and twist (angular velocity, velocity of its origin; world frame, as
    mj_objectVelocity gives it) from MuJoCo Warp's float32 state, widened to float64."""
    world, b = wp.tid()
    i = body[b]
    p = wp.vec3d(xpos[world, i])
    velocity = cvel[world, i]
    angular = wp.vec3d(wp.spatial_top(velocity))
    linear = wp.vec3d(wp.spatial_bottom(velocity))
    arm = p - wp.vec3d(subtree_com[world, rootid[i]])
    origin[world, b] = p
    rotation[world, b] = wp.mat33d(xmat[world, i])
    lin = linear - wp.cross(arm, angular)
    twist[world, b] = wp.spatial_vectord(angular[0], angular[1], angular[2], lin[0], lin[1], lin[2])


@wp.func
def element_pose(R: wp.mat33d, o: wp.vec3d, c: wp.vec3d, normal: wp.vec3d, surface_z: f64):
    """An element's depth below the flat surface, its offset from the body's origin and its normal, world frame,
    from the body's rotation and origin and the element's centre and normal in the body's frame."""
    arm = R * c
    return surface_z - (o[2] + arm[2]), arm, R * normal


@wp.func
def point_velocity(t: wp.spatial_vectord, arm: wp.vec3d) -> wp.vec3d:
    """The velocity of the point at ``arm`` from a body's origin, of the body's twist (angular, linear)."""
    return wp.cross(wp.spatial_top(t), arm) + wp.spatial_bottom(t)


@wp.kernel
def element_wrenches(law: int, coef: wp.array(dtype=f64), v_reg: f64, element_body: wp.array(dtype=int),
                     centre: wp.array(dtype=wp.vec3d), normal: wp.array(dtype=wp.vec3d),
                     area: wp.array(dtype=f64), scale: wp.array(dtype=f64), mu_surf: wp.array(dtype=f64),
                     drft_lambda: wp.array(dtype=f64), rho_c: wp.array(dtype=f64), surface_z: wp.array(dtype=f64),
                     origin: wp.array2d(dtype=wp.vec3d), rotation: wp.array2d(dtype=wp.mat33d),
                     twist: wp.array2d(dtype=wp.spatial_vectord), wrench: wp.array2d(dtype=wp.spatial_vectord)):
    """Every element's force, summed per (world, body) into the torque about the body's origin and the force
    (finrft_surface_wrench; ``wrench`` zeroed before). Only elements below the surface do any work."""
    world, e = wp.tid()
    b = element_body[e]
    o = origin[world, b]
    depth, arm, n = element_pose(rotation[world, b], o, centre[e], normal[e], surface_z[world])
    if not (depth > ZERO):
        return
    v = point_velocity(twist[world, b], arm)
    f = element_force(law, coef, scale[world], mu_surf[world], drft_lambda[world], rho_c[world], v_reg, n, v,
                      depth, area[e])
    torque = wp.cross(arm, f)
    wp.atomic_add(wrench, world, b, wp.spatial_vectord(torque[0], torque[1], torque[2], f[0], f[1], f[2]))


@wp.kernel
def apply_wrenches(nbody: int, body: wp.array(dtype=int), rootid: wp.array(dtype=int),
                   isdofancestor: wp.array2d(dtype=int), subtree_com: wp.array2d(dtype=wp.vec3),
                   cdof: wp.array2d(dtype=wp.spatial_vector), origin: wp.array2d(dtype=wp.vec3d),
                   wrench: wp.array2d(dtype=wp.spatial_vectord), qfrc: wp.array2d(dtype=float)):
    """mj_applyFT of every attached body's wrench at its origin, into the generalized force of each dof: J^T of
    the dof's motion axis, summed over the bodies it moves (one thread per world and dof: no atomics)."""
    world, dof = wp.tid()
    total = ZERO
    for b in range(nbody):
        i = body[b]
        if isdofancestor[i, dof] == 0:
            continue
        axis = cdof[world, dof]
        w = wrench[world, b]
        force = wp.spatial_bottom(w)
        # the torque about the subtree's centre of mass, where cdof's axes are taken
        torque = wp.spatial_top(w) + wp.cross(origin[world, b] - wp.vec3d(subtree_com[world, rootid[i]]), force)
        total += wp.dot(wp.vec3d(wp.spatial_top(axis)), torque) + wp.dot(wp.vec3d(wp.spatial_bottom(axis)), force)
    qfrc[world, dof] = qfrc[world, dof] + float(total)


# ---------------------------------------------------------------------------------------------------------------
# The implicit step: each body's RFT damping, linearised at the step's start, taken into MuJoCo's implicit solve.

DIFFERENCE = wp.constant(f64(1e-7))  # the central differences' step, a share of |v| + v_reg
LEAST_STEP = wp.constant(f64(1e-12))  # m/s: the differences' step where both are 0


@wp.func
def element_slope(law: int, coef: wp.array(dtype=f64), scale: f64, mu_surf: f64, drft_lambda: f64, rho_c: f64,
                  v_reg: f64, n: wp.vec3d, v: wp.vec3d, depth: f64, area: f64, trailing: int) -> wp.mat33d:
    """d(element_force)/dv (row: the force's component): by central differences, every law alike. With
    ``trailing``, an element trailing by less than the ramp's width takes the secant to where it leads by v_reg,
    as the native linearly implicit step (finrft_surface_trailing_slope), so that a light body settling does not
    chatter; Newton's method takes the slope itself (0 there), as the native newton does."""
    v_n = wp.dot(n, v)
    if trailing != 0 and v_reg > ZERO and v_n > -v_reg and not (v_n > RAMP_FLOOR * v_reg):
        gap = v_reg - v_n
        ahead = element_force(law, coef, scale, mu_surf, drft_lambda, rho_c, v_reg, n, v + gap * n, depth, area)
        return wp.outer(ahead, n) / gap
    h = wp.max(DIFFERENCE * (wp.length(v) + v_reg), LEAST_STEP)
    k = wp.mat33d()
    for j in range(3):
        e = wp.vec3d(ZERO, ZERO, ZERO)
        e[j] = h
        up = element_force(law, coef, scale, mu_surf, drft_lambda, rho_c, v_reg, n, v + e, depth, area)
        down = element_force(law, coef, scale, mu_surf, drft_lambda, rho_c, v_reg, n, v - e, depth, area)
        for i in range(3):
            k[i, j] = (up[i] - down[i]) / (TWO * h)
    return k


@wp.kernel
def element_damping(law: int, coef: wp.array(dtype=f64), v_reg: f64, element_body: wp.array(dtype=int),
                    centre: wp.array(dtype=wp.vec3d), normal: wp.array(dtype=wp.vec3d), area: wp.array(dtype=f64),
                    scale: wp.array(dtype=f64), mu_surf: wp.array(dtype=f64), drft_lambda: wp.array(dtype=f64),
                    rho_c: wp.array(dtype=f64), surface_z: wp.array(dtype=f64), origin: wp.array2d(dtype=wp.vec3d),
                    rotation: wp.array2d(dtype=wp.mat33d), twist: wp.array2d(dtype=wp.spatial_vectord),
                    com: wp.array2d(dtype=wp.vec3d), trailing: int, damping: wp.array2d(dtype=wp.spatial_matrixd)):
    """Each body's linearised damping G = sum_e S_e^T k_e S_e (6 x 6, zeroed before) in the motion coordinates of
    MuJoCo's cdof (angular, linear; about the tree's centre of mass c): an element at r = p - c moves at
    v = S u = linear - [r]x angular, so J^T dF/dv J of a dof pair is s_i^T G s_j."""
    world, e = wp.tid()
    b = element_body[e]
    o = origin[world, b]
    depth, arm, n = element_pose(rotation[world, b], o, centre[e], normal[e], surface_z[world])
    if not (depth > ZERO):
        return
    v = point_velocity(twist[world, b], arm)
    k = element_slope(law, coef, scale[world], mu_surf[world], drft_lambda[world], rho_c[world], v_reg, n, v, depth,
                      area[e], trailing)
    r = o + arm - com[world, b]
    X = wp.skew(r)
    aa = -(X * k * X)
    al = X * k
    la = -(k * X)
    g = wp.spatial_matrixd()
    for i in range(3):
        for j in range(3):
            g[i, j] = aa[i, j]
            g[i, j + 3] = al[i, j]
            g[i + 3, j] = la[i, j]
            g[i + 3, j + 3] = k[i, j]
    wp.atomic_add(damping, world, b, g)


@wp.kernel
def tree_centres(body: wp.array(dtype=int), rootid: wp.array(dtype=int), subtree_com: wp.array2d(dtype=wp.vec3),
                 com: wp.array2d(dtype=wp.vec3d)):
    """The centre of mass of each attached body's tree, where MuJoCo's cdof takes its axes, in float64."""
    world, b = wp.tid()
    com[world, b] = wp.vec3d(subtree_com[world, rootid[body[b]]])


# ---------------------------------------------------------------------------------------------------------------
# The newton step: backward Euler in the medium's force, (M - dt D) dv = dt (f - F(v) + F(v + dv)), solved per world
# by Newton's method with a backtracking line search on the residual, as finrft_implicit_step's newton.

@wp.kernel
def trial_twists(nv: int, body: wp.array(dtype=int), isdofancestor: wp.array2d(dtype=int),
                 cdof: wp.array2d(dtype=wp.spatial_vector), origin: wp.array2d(dtype=wp.vec3d),
                 com: wp.array2d(dtype=wp.vec3d), qvel: wp.array2d(dtype=f64), dv: wp.array2d(dtype=f64),
                 twist: wp.array2d(dtype=wp.spatial_vectord)):
    """Each attached body's twist (angular velocity, velocity of its origin) at the velocities qvel + dv and the
    positions of the forward pass: sum over the dofs that move it of cdof times the dof's velocity."""
    world, b = wp.tid()
    angular = wp.vec3d(ZERO, ZERO, ZERO)
    linear = wp.vec3d(ZERO, ZERO, ZERO)
    for i in range(nv):
        if isdofancestor[body[b], i] != 0:
            axis = wp.spatial_vectord(cdof[world, i])
            u = qvel[world, i] + dv[world, i]
            angular += u * wp.spatial_top(axis)
            linear += u * wp.spatial_bottom(axis)
    linear += wp.cross(angular, origin[world, b] - com[world, b])
    twist[world, b] = wp.spatial_vectord(angular[0], angular[1], angular[2], linear[0], linear[1], linear[2])


@wp.kernel
def generalized_forces(nbody: int, body: wp.array(dtype=int), isdofancestor: wp.array2d(dtype=int),
                       cdof: wp.array2d(dtype=wp.spatial_vector), origin: wp.array2d(dtype=wp.vec3d),
                       com: wp.array2d(dtype=wp.vec3d), wrench: wp.array2d(dtype=wp.spatial_vectord),
                       out: wp.array2d(dtype=f64)):
    """J^T of every attached body's wrench, per dof, in float64 (`apply_wrenches` without the narrowing)."""
    world, dof = wp.tid()
    total = ZERO
    axis = wp.spatial_vectord(cdof[world, dof])
    for b in range(nbody):
        if isdofancestor[body[b], dof] == 0:
            continue
        w = wrench[world, b]
        force = wp.spatial_bottom(w)
        torque = wp.spatial_top(w) + wp.cross(origin[world, b] - com[world, b], force)
        total += wp.dot(wp.spatial_top(axis), torque) + wp.dot(wp.spatial_bottom(axis), force)
    out[world, dof] = total


@wp.func
def assemble(world: int, nv: int, nbody: int, body: wp.array(dtype=int), isdofancestor: wp.array2d(dtype=int),
             cdof: wp.array2d(dtype=wp.spatial_vector), fullm_i: wp.array(dtype=int), fullm_j: wp.array(dtype=int),
             elemid: wp.array2d(dtype=int), smooth: wp.array2d(dtype=float), timestep: f64,
             damping: wp.array2d(dtype=wp.spatial_matrixd), work: wp.array3d(dtype=f64)):
    """work[:, :nv] = M - dt D - dt J^T G J: MuJoCo Warp's M - dt D (``smooth``, M's sparse layout) and the
    bodies' RFT damping."""
    for i in range(nv):
        for j in range(nv):
            work[world, i, j] = ZERO
    for k in range(fullm_i.shape[0]):
        i = fullm_i[k]
        j = fullm_j[k]
        madr = elemid[i, j]
        if madr >= 0:
            work[world, i, j] = f64(smooth[world, madr])
            work[world, j, i] = f64(smooth[world, madr])
    for i in range(nv):
        si = wp.spatial_vectord(cdof[world, i])
        for j in range(nv):
            sj = wp.spatial_vectord(cdof[world, j])
            total = ZERO
            for b in range(nbody):
                if isdofancestor[body[b], i] != 0 and isdofancestor[body[b], j] != 0:
                    total += wp.dot(si, damping[world, b] * sj)
            work[world, i, j] = work[world, i, j] - timestep * total


@wp.func
def solve_in_place(world: int, nv: int, work: wp.array3d(dtype=f64)):
    """Gaussian elimination with partial pivoting of work[:, :nv] x = work[:, nv], x into work[:, nv]."""
    for col in range(nv):
        pivot = col
        for i in range(col + 1, nv):
            if wp.abs(work[world, i, col]) > wp.abs(work[world, pivot, col]):
                pivot = i
        if pivot != col:
            for j in range(nv + 1):
                swap = work[world, col, j]
                work[world, col, j] = work[world, pivot, j]
                work[world, pivot, j] = swap
        for i in range(col + 1, nv):
            factor = work[world, i, col] / work[world, col, col]
            for j in range(col, nv + 1):
                work[world, i, j] = work[world, i, j] - factor * work[world, col, j]
    for back in range(nv):
        i = nv - 1 - back
        total = work[world, i, nv]
        for j in range(i + 1, nv):
            total -= work[world, i, j] * work[world, j, nv]
        work[world, i, nv] = total / work[world, i, i]


@wp.kernel
def implicit_solve(nv: int, nbody: int, body: wp.array(dtype=int), isdofancestor: wp.array2d(dtype=int),
                   cdof: wp.array2d(dtype=wp.spatial_vector), fullm_i: wp.array(dtype=int),
                   fullm_j: wp.array(dtype=int), elemid: wp.array2d(dtype=int), smooth: wp.array2d(dtype=float),
                   timestep: f64, damping: wp.array2d(dtype=wp.spatial_matrixd), force: wp.array2d(dtype=float),
                   work: wp.array3d(dtype=f64), qacc: wp.array2d(dtype=float)):
    """qacc = (M - dt D - dt K)^-1 (M qacc of the forward pass), one world per thread, dense, in float64, K = J^T G
    J the bodies' RFT damping (`element_damping`), whole (not only its symmetric part)."""
    world = wp.tid()
    assemble(world, nv, nbody, body, isdofancestor, cdof, fullm_i, fullm_j, elemid, smooth, timestep, damping, work)
    for i in range(nv):
        work[world, i, nv] = f64(force[world, i])
    solve_in_place(world, nv, work)
    for i in range(nv):
        qacc[world, i] = float(work[world, i, nv])


@wp.kernel
def newton_start(medium: wp.array2d(dtype=f64), force: wp.array2d(dtype=float), qvel_in: wp.array2d(dtype=float),
                 rest: wp.array2d(dtype=f64), qvel: wp.array2d(dtype=f64), dv: wp.array2d(dtype=f64),
                 search: wp.array2d(dtype=f64)):
    """rest = f - J^T F(v) (the forward pass's force without the medium's), v in float64, dv = 0, a fresh search."""
    world, i = wp.tid()
    rest[world, i] = f64(force[world, i]) - medium[world, i]
    qvel[world, i] = f64(qvel_in[world, i])
    dv[world, i] = ZERO
    if i < 4:
        search[world, i] = ZERO


@wp.kernel
def newton_finish(timestep: f64, dv: wp.array2d(dtype=f64), accepted: wp.array2d(dtype=f64),
                  search: wp.array2d(dtype=f64), qacc: wp.array2d(dtype=float)):
    """qacc = dv / dt: the converged dv, else the last accepted one."""
    world, i = wp.tid()
    change = accepted[world, i]
    if search[world, 2] == ONE:
        change = dv[world, i]
    qacc[world, i] = float(change / timestep)


# |change| <= it (1 + |qvel|): finrft.integrate.NEWTON_TOLERANCE is 1e-10, but MuJoCo Warp keeps qvel in float32,
# whose rounding (6e-8) no smaller change survives
NEWTON_TOLERANCE = wp.constant(f64(1e-7))
NEWTON_RESIDUAL = wp.constant(f64(1e-3))  # as NEWTON_RESIDUAL in plugins/steppers.c
TINY = wp.constant(f64(1e-6))
LEAST_SHRINK = wp.constant(f64(1e-6))  # a line search shorter than this has failed (as the native's)
DESCENT = wp.constant(f64(1e-4))  # the share of the step's full decrease a search asks (Armijo's, as the native)


@wp.kernel
def newton_update(nv: int, nbody: int, body: wp.array(dtype=int), isdofancestor: wp.array2d(dtype=int),
                  cdof: wp.array2d(dtype=wp.spatial_vector), fullm_i: wp.array(dtype=int),
                  fullm_j: wp.array(dtype=int), elemid: wp.array2d(dtype=int), smooth: wp.array2d(dtype=float),
                  timestep: f64, damping: wp.array2d(dtype=wp.spatial_matrixd), rest: wp.array2d(dtype=f64),
                  medium: wp.array2d(dtype=f64), qvel: wp.array2d(dtype=f64), work: wp.array3d(dtype=f64),
                  dv: wp.array2d(dtype=f64), accepted: wp.array2d(dtype=f64), direction: wp.array2d(dtype=f64),
                  search: wp.array2d(dtype=f64)):
    """One round of Newton's method per world, at the candidate dv whose medium force J^T F(v + dv) is ``medium``
    and damping ``damping``: its residual r = (M - dt D) dv - dt (rest + medium), rest = f - F(v), against the last
    accepted one's; accepted (or the first), the next candidate is the Newton step dv - (M - dt D - dt K)^-1 r;
    else half the last step, down to LEAST_SHRINK. search[w] = (|r| accepted, step share, 1 converged or 2
    failed, 1 once a candidate was taken)."""
    world = wp.tid()
    if search[world, 2] > ZERO:
        return
    norm = ZERO
    largest = ZERO
    scale = ZERO
    for i in range(nv):
        total = ZERO
        for k in range(fullm_i.shape[0]):
            a = fullm_i[k]
            c = fullm_j[k]
            madr = elemid[a, c]
            if madr >= 0:
                if a == i:
                    total += f64(smooth[world, madr]) * dv[world, c]
                if c == i and a != c:
                    total += f64(smooth[world, madr]) * dv[world, a]
        r = total - timestep * (rest[world, i] + medium[world, i])
        work[world, i, nv] = -r
        norm += r * r
        largest = wp.max(largest, wp.abs(r))
        scale = wp.max(scale, wp.max(wp.abs(rest[world, i]), wp.abs(medium[world, i])))
    norm = wp.sqrt(norm)
    # the root, to the native step's tests: a residual of at most NEWTON_RESIDUAL of dt times the step's largest
    # force with a change below the tolerance, or one a million times smaller whatever the change (a kink of a
    # law, an element switching on, lets the change creep without end)
    small = largest <= NEWTON_RESIDUAL * timestep * scale
    if largest <= NEWTON_RESIDUAL * TINY * timestep * scale:
        search[world, 2] = ONE
        return
    share = search[world, 1]
    first = search[world, 3] == ZERO
    if not first and not (norm <= (ONE - DESCENT * share) * search[world, 0]):
        if share <= LEAST_SHRINK:
            # no descent left along the step (a kink of the law, an element switching on): the native step stops
            # here and halves itself; this one keeps the last accepted iterate
            search[world, 2] = TWO
            return
        share = share / TWO
        search[world, 1] = share
        for i in range(nv):
            dv[world, i] = accepted[world, i] + share * direction[world, i]
        return
    search[world, 0] = norm
    search[world, 3] = ONE
    for i in range(nv):
        accepted[world, i] = dv[world, i]
    assemble(world, nv, nbody, body, isdofancestor, cdof, fullm_i, fullm_j, elemid, smooth, timestep, damping, work)
    solve_in_place(world, nv, work)
    change = ZERO
    speed = ZERO
    for i in range(nv):
        direction[world, i] = work[world, i, nv]
        dv[world, i] = accepted[world, i] + work[world, i, nv]
        change = wp.max(change, wp.abs(work[world, i, nv]))
        speed = wp.max(speed, wp.abs(qvel[world, i] + dv[world, i]))
    search[world, 1] = ONE
    if small and change <= NEWTON_TOLERANCE * (ONE + speed):
        search[world, 2] = ONE
