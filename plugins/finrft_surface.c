// finrft.surface: a MuJoCo engine plugin (passive force) applying a granular surface law to the surface elements
// of a body: Li, Zhang & Goldman 2013 in 3D (Treers, Cao & Stuart 2021) or in the plane of motion, or the 3D-RFT
// of Agarwal, Goldman & Kamrin 2023, optionally with DRFT's rate-dependent term on top, all regularised by one
// ramp. The C twin of finrft/laws/li2013.py, li2013_planar.py, rft3d.py, drft.py, of `regularised` in
// finrft/laws/__init__.py and of the Python backend in finrft/attach.py: same formulas, same folding, same planes.
//
// One instance per body (finrft.attach makes them). Config, all required for its law:
//   law           "li2013", "li2013-planar" or "rft3d" (kLaws)
//   coefficients  li2013: the fit's nine coefficients A00 A10 B11 B01 B-11 C11 C01 C-11 D10, N/m^3;
//                 rft3d: the fit's c1, c2, c3 (20 each, dimensionless)
//   zeta          li2013, li2013-planar: > 0, the medium's scale
//   xi            rft3d: > 0, the medium's scale xi_n, N/m^3
//   mu_surf       rft3d: >= 0, the intruder's surface friction
//   surface_z     m, height of the flat free surface
//   surface       optional (absent or "flat": the horizontal plane z = surface_z): "plane" or "hfield", the kind
//                 of free surface (plugins/surfaces/), with
//   surface_point, surface_normal   plane: a point of it (m) and its normal out of the sand, 3 numbers each
//   hfield        hfield: "nrow ncol sx sy cx cy cz R00 .. R22 h00 h01 ..": the grid's size, centre, frame
//                 (row-major, its axes as columns) and heights (m, row by row), as finrft_hfield_depth takes them
// Depths are measured along the model's gravity (opt.gravity, read again at every use) from the surface, and the
// laws take their angles against it (finrft_surface_frame): under gravity along -z over the flat surface, exactly
// the numbers of the plane z = surface_z and the laws' own frame.
//   v_reg         optional, >= 0 m/s (absent: 0, none): every element's force times tanh(max(n . v, 0) / v_reg)
//   drft_lambda   optional, >= 0 (absent: 0, off): DRFT's dimensionless lambda
//   bulk_density  with drft_lambda > 0: > 0, the medium's density rho_c, kg/m^3
//   elements      "cx cy cz nx ny nz area ..." per element: centre and outward unit normal in the body frame, m^2
//   geoms         optional: "k type sx sy sz px py pz qw qx qy qz ..." per geom the elements were cut from (its
//                 place among the body's geoms, then as the model held it then); a model whose geom differs (resized
//                 in the spec, or in geom_size after compile) stops with an error rather than apply the old force
//
// No static state: everything lives in the per-mjData struct, so instances and threads never share memory; the
// compute callback allocates nothing, unless it is stepped with another model than its instance's (rollout).

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#include "finrft.h"

#define NCOEF 9
#define NTERMS 20
#define NCOEF_RFT3D (3 * NTERMS)
// Below this fraction of the speed, a velocity's horizontal part is taken as none (as VERTICAL in li2013.py).
#define VERTICAL 1e-12

// |(x, y)|: the law's vectors are unit or physical sizes, far from hypot's overflow, and hypot was a tenth of a
// robot's step.
static inline double norm2(double x, double y) { return sqrt(x * x + y * y); }

// (alpha_x, alpha_z), N/m^3, at the angles beta and gamma given by their cosines and sines: see
// finrft/laws/li2013.py for the signs and the folding. The series' terms come from cos 2beta and sin 2beta by the
// angle-sum formulas, so a call costs no trigonometric function: the laws are called several times per element per
// Newton step, and sin, cos and atan2 were a third of a wheel's step. gamma beyond +-pi/2 needs no folding here: the
// mirror (beta -> -beta, gamma -> pi - gamma, alpha_x -> -alpha_x) changes the sign of cos gamma and sin 2beta, and
// every term of alpha_x holds one of them, every term of alpha_z none or both, so the folded sums are these to the
// last bit (a branch on the sign of cos gamma, mispredicted on elements that face every way, was a tenth of a call).
// alpha_double takes beta by cos 2beta and sin 2beta (c2, s2), alpha_unit by its cosine and sine.
static inline void alpha_double(const double coef[NCOEF], double zeta, double c2, double s2, double cg, double sg,
                                double out[2]) {
  double sum_sin = s2 * cg + c2 * sg, diff_sin = c2 * sg - s2 * cg;  // sin(2b + g), sin(-2b + g)
  double sum_cos = c2 * cg - s2 * sg, diff_cos = c2 * cg + s2 * sg;  // cos(2b + g), cos(-2b + g)
  double az = coef[0] + coef[1] * c2 + coef[2] * sum_sin + coef[3] * sg + coef[4] * diff_sin;
  double ax = coef[5] * sum_cos + coef[6] * cg + coef[7] * diff_cos + coef[8] * s2;
  out[0] = zeta * ax;
  out[1] = zeta * az;
}

static inline void alpha_unit(const double coef[NCOEF], double zeta, double cb, double sb, double cg, double sg,
                              double out[2]) {
  alpha_double(coef, zeta, cb * cb - sb * sb, 2 * sb * cb, cg, sg, out);
}

// The cosine and sine of atan2(y, x) (1 and 0 at the origin, as atan2(0, 0) = 0).
static void unit_angle(double y, double x, double* c, double* s) {
  double size = norm2(x, y), inverse = size > 0 ? 1 / size : 0;
  *c = size > 0 ? x * inverse : 1;
  *s = y * inverse;
}

// (alpha_x, alpha_z), N/m^3, for any beta and gamma.
FINRFT_EXPORT void finrft_li2013_alpha(const double coef[NCOEF], double zeta, double beta, double gamma,
                                       double out[2]) {
  alpha_unit(coef, zeta, cos(beta), sin(beta), cos(gamma), sin(gamma), out);
}

// Li's alpha at the face's angle beta = atan2(face_y, face_x) and the motion's gamma = atan2(motion_y, motion_x).
static void li2013_alpha_at(const double coef[NCOEF], double zeta, double face_y, double face_x, double motion_y,
                            double motion_x, double out[2]) {
  double cb, sb, cg, sg;
  unit_angle(face_y, face_x, &cb, &sb);
  unit_angle(motion_y, motion_x, &cg, &sg);
  alpha_unit(coef, zeta, cb, sb, cg, sg, out);
}

// The force on one element (world frame, z up): outward unit normal n, velocity v, depth below the surface,
// area. As element_forces in li2013_planar.py.
FINRFT_EXPORT void finrft_li2013_planar_element_force(const double coef[NCOEF], double zeta, const double n[3],
                                               const double v[3], double depth, double area,
                                               double force[3]) {
  force[0] = force[1] = force[2] = 0;
  if (!(depth > 0) || !(n[0] * v[0] + n[1] * v[1] + n[2] * v[2] > 0)) return;
  double horizontal = norm2(v[0], v[1]);
  double r[2] = {1, 0};
  if (horizontal > VERTICAL * sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])) {
    r[0] = v[0] / horizontal;
    r[1] = v[1] / horizontal;
  } else {
    double sideways = norm2(n[0], n[1]);
    if (sideways > 0) {
      r[0] = n[0] / sideways;
      r[1] = n[1] / sideways;
    }
  }
  double n_r = n[0] * r[0] + n[1] * r[1];
  double v_r = v[0] * r[0] + v[1] * r[1];
  double a[2];
  li2013_alpha_at(coef, zeta, -n_r, n[2], -v[2], v_r, a);
  double scale = area * depth * norm2(n_r, n[2]);
  force[0] = -scale * a[0] * r[0];
  force[1] = -scale * a[0] * r[1];
  force[2] = scale * a[1];
}

// Treers et al.'s weights of the two parts of a unit velocity, as F1_FIT, F23_FIT in li2013.py: f1 = a (tanh(b s -
// c) + tanh(c)) / d and f23 = a (atanh(b s - c) + atanh(c)) / d, each sum in one closed form of u = b s (one exp,
// one log where the two tanh or atanh calls were half a call of the law; expm1 and log1p, whose precision near 0
// only the weights' own 1e-16 would see, cost twice glibc's exp and log):
//   tanh(u - c) + tanh(c) = sinh(u) / (cosh(u - c) cosh c) = E / (cosh c (e^-c E + 2 cosh c)), E = e^(2 u) - 1,
//   atanh(u - c) + atanh(c) = log(1 + 2 u / ((1 + c - u) (1 - c))) / 2.
// Each returns the weight and, into *slope when not NULL, its derivative in s.
#define F1_A 0.440850096954369
#define F1_B 3.62263982880971
#define F1_C 1.60910808139526
#define F1_D 0.832324700111401
#define F23_A 1.99392673405210
#define F23_B 1.61146827229181
#define F23_C 0.973746396532650
#define F23_D 5.81083560370960
// weight_within(1), the weight of a velocity wholly within the plane (1 to 4e-16): a log a call saved
#define F23_ONE 1.0000000000000004

static double weight_across(double size, double* slope) {
  double grow = exp(2 * F1_B * size), below = exp(-F1_C) * (grow - 1) + 2 * cosh(F1_C);
  if (slope) *slope = F1_A / (F1_D * cosh(F1_C)) * 2 * cosh(F1_C) * 2 * F1_B * grow / (below * below);
  return F1_A / (F1_D * cosh(F1_C)) * (grow - 1) / below;
}

static double weight_within(double size, double* slope) {
  double u = F23_B * size, rest = 1 + F23_C - u, q = 2 / (1 - F23_C) * u / rest;
  if (slope) *slope = F23_A / (2 * F23_D) * F23_B * 2 / (1 - F23_C) * (1 + F23_C) / (rest * rest) / (1 + q);
  return F23_A / (2 * F23_D) * log(1 + q);
}

// The unit horizontal direction of a, else of b, else x (as _horizontal_unit in li2013.py).
static void horizontal_unit(const double a[3], const double b[3], double e[2]) {
  double size = norm2(a[0], a[1]);
  const double* pick = a;
  if (!(size > 0)) {
    size = norm2(b[0], b[1]);
    pick = b;
  }
  e[0] = 1;
  e[1] = 0;
  if (size > 0) {
    double inverse = 1 / size;
    e[0] = pick[0] * inverse;
    e[1] = pick[1] * inverse;
  }
}

// Treers et al.'s stress per unit depth in the vertical plane of the horizontal unit vector e2 (as _stress in
// li2013.py) is f1(|v1|) sign(v^.e1) across + f23 within, f1 the weight of the unit velocity's part across the
// plane and f23 of its part within it: its two parts, across = -alpha_1 e1 (2) and within = (-alpha_x e2, alpha_z)
// (3), beta the face's angle (by cos 2beta and sin 2beta) and gamma the motion's there (by its cosine and sine).
// The parts come before the weights: the weights' exp and log are calls, and what the parts are computed from would
// otherwise be held across them (saved to memory and loaded again).
static inline void plane_parts(const double coef[NCOEF], double zeta, const double e2[2], double c2, double s2,
                               double cg, double sg, double across[2], double within[3]) {
  double a[2];
  // alpha_1 = alpha_x(0, 0), alpha_unit's sum at beta = gamma = 0 without its call
  double alpha_1 = zeta * (coef[5] + coef[6] + coef[7]);
  alpha_double(coef, zeta, c2, s2, cg, sg, a);
  across[0] = -alpha_1 * e2[1];
  across[1] = alpha_1 * e2[0];
  within[0] = -a[0] * e2[0];
  within[1] = -a[0] * e2[1];
  within[2] = a[1];
}

// The force on one element (world frame, z up) of Li's law in 3D (Treers, Cao & Stuart 2021): outward unit normal
// n, velocity v, depth below the surface, area. As element_forces in li2013.py, the blend of nearly horizontal
// faces included, by algebra on n and v: the law depends on the direction of v alone, so its ratios are taken on v
// as it is, with as few divisions as possible (a call was a chain of three square roots, six divisions, an exp and
// a log, the law's price on a robot's step).
//   In the normal's plane, e2 = n_h / |n_h|: with P = |n_h| |v|, v^.e1 = (v_h x n_h)_z / P and the size of v^'s
//   part within the plane is |(v_h.n_h, v_z |n_h|)| / P; gamma's cosine and sine are that vector's over its size,
//   and beta = atan2(-|n_h|, n_z), so cos 2beta = n_z^2 - |n_h|^2 and sin 2beta = -2 |n_h| n_z (|n| = 1).
//   In the velocity's own plane, e2 = v_h / |v_h| (n's or x when v is vertical): v has no part across it and all
//   of it within (f1's weight 0, f23's f23(1)), and gamma's cosine and sine are |v_h| / |v| and -v_z / |v|.
// The own plane's part comes first, so that nothing of it is held across the normal plane's weights.
static inline void li2013_element_force(const double coef[NCOEF], double zeta, const double n[3], const double v[3],
                                        double depth, double area, double force[3]) {
  double out[3] = {0, 0, 0};
  if (depth > 0 && n[0] * v[0] + n[1] * v[1] + n[2] * v[2] > 0) {
    double speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), flat = n[0] * n[0] + n[1] * n[1];
    // (a product: the constant's inverse is folded, where a division by it cost one of the call's divisions)
    double sideways = sqrt(flat), tilt = sideways * (1 / sqrt(1 - (1 - 1e-3) * (1 - 1e-3)));
    if (tilt > 1) tilt = 1;
    double w = tilt * tilt * (3 - 2 * tilt), scale = area * depth;
    if (w < 1) {
      double across[2], within[3], e2[2], cb, sb, inverse = 1 / speed;
      horizontal_unit(v, n, e2);
      unit_angle(-(n[0] * e2[0] + n[1] * e2[1]), n[2], &cb, &sb);
      plane_parts(coef, zeta, e2, cb * cb - sb * sb, 2 * sb * cb, (v[0] * e2[0] + v[1] * e2[1]) * inverse,
                  -v[2] * inverse, across, within);
      for (int i = 0; i < 3; i++) out[i] = (1 - w) * scale * F23_ONE * within[i];
    }
    if (w > 0) {
      double inverse = 1 / (sideways * speed), turn = speed * inverse;  // turn = 1 / |n_h|
      double v1 = (v[0] * n[1] - v[1] * n[0]) * inverse, along = v[0] * n[0] + v[1] * n[1];
      // |(along, lift)| from |n_h|^2, not from its square root: one step less before the log
      double lift = v[2] * sideways, size = sqrt(along * along + v[2] * v[2] * flat), cg = 1, sg = 0;
      if (size > 0) {
        double unit = 1 / size;
        cg = along * unit;
        sg = -lift * unit;
      }
      double e2[2] = {n[0] * turn, n[1] * turn}, across[2], within[3];
      plane_parts(coef, zeta, e2, n[2] * n[2] - flat, -2 * sideways * n[2], cg, sg, across, within);
      // f1 sign(v^.e1): f1(0) = 0, so the sign of 0 is none's
      double f1 = w * scale * copysign(weight_across(fabs(v1), NULL), v1);
      double f23 = w * scale * weight_within(size * inverse, NULL);
      for (int i = 0; i < 2; i++) out[i] += f1 * across[i] + f23 * within[i];
      out[2] += f23 * within[2];
    }
  }
  for (int i = 0; i < 3; i++) force[i] = out[i];
}

FINRFT_EXPORT void finrft_li2013_element_force(const double coef[NCOEF], double zeta, const double n[3],
                                               const double v[3], double depth, double area, double force[3]) {
  li2013_element_force(coef, zeta, n, v, depth, area, force);
}

// alpha_unit and its partial derivatives d[a][j] of alpha_x (a = 0), alpha_z (a = 1) in (cb, sb, cg, sg), from
// the angle-sum forms regrouped by c2 = cos 2beta and s2 = sin 2beta (as _alpha_slope in li2013.py).
static void alpha_unit_slope(const double coef[NCOEF], double zeta, double cb, double sb, double cg, double sg,
                             double out[2], double d[2][4]) {
  double m = cg < 0 ? -1 : 1;
  sb *= m;
  cg *= m;
  double c2 = cb * cb - sb * sb, s2 = 2 * sb * cb;
  double bp = coef[2] + coef[4], bm = coef[2] - coef[4], cp = coef[5] + coef[7], cm = coef[7] - coef[5];
  double ax = cp * c2 * cg + cm * s2 * sg + coef[6] * cg + coef[8] * s2;
  double az = coef[0] + coef[1] * c2 + bm * s2 * cg + bp * c2 * sg + coef[3] * sg;
  double x_c2 = cp * cg, x_s2 = cm * sg + coef[8], z_c2 = coef[1] + bp * sg, z_s2 = bm * cg;
  // back to the unfolded angles: alpha_x = m alpha_x', sin beta' = m sin beta, cos gamma' = m cos gamma
  d[0][0] = zeta * m * 2 * (x_c2 * cb + x_s2 * sb);
  d[0][1] = zeta * 2 * (x_s2 * cb - x_c2 * sb);
  d[0][2] = zeta * (cp * c2 + coef[6]);
  d[0][3] = zeta * m * cm * s2;
  d[1][0] = zeta * 2 * (z_c2 * cb + z_s2 * sb);
  d[1][1] = zeta * m * 2 * (z_s2 * cb - z_c2 * sb);
  d[1][2] = zeta * m * bm * s2;
  d[1][3] = zeta * (bp * c2 + coef[3]);
  out[0] = zeta * m * ax;
  out[1] = zeta * az;
}

// The stress per unit depth of _stress in li2013.py (plane_stress's, on any plane) and its derivative ds (3 x 3,
// row-major: ds[3 i + k] = d stress_i / d u_k) in the unit velocity u, e2's own derivative being de2 (2 x 3; NULL:
// e2 is the normal's, fixed). As _stress_slope in li2013.py.
static void li2013_stress_slope(const double coef[NCOEF], double zeta, const double n[3], const double u[3],
                                const double e2[2], const double de2[2][3], double stress[3], double ds[9]) {
  // With e2 fixed (de2 NULL) every term of its derivative is an exact 0 and beta's is none: they are left out, the
  // same numbers for about half the arithmetic (the normal's plane is every tilted face's).
  double e1[2] = {e2[1], -e2[0]};
  double de1[2][3] = {{0, 0, 0}, {0, 0, 0}}, d_across[3] = {e1[0], e1[1], 0}, d_along[3] = {e2[0], e2[1], 0},
         d_within[3] = {0, 0, 0}, dy[3] = {0, 0, 0};
  if (de2) {
    for (int k = 0; k < 3; k++) {
      de1[0][k] = de2[1][k];
      de1[1][k] = -de2[0][k];
      d_across[k] = u[0] * de1[0][k] + u[1] * de1[1][k];
      d_along[k] = u[0] * de2[0][k] + u[1] * de2[1][k];
      dy[k] = -(n[0] * de2[0][k] + n[1] * de2[1][k]);
    }
    d_across[0] += e1[0];
    d_across[1] += e1[1];
    d_along[0] += e2[0];
    d_along[1] += e2[1];
  }
  double across = u[0] * e1[0] + u[1] * e1[1];
  double along = u[0] * e2[0] + u[1] * e2[1];
  double within = norm2(along, u[2]);
  double df1, df23, f1 = weight_across(fabs(across), &df1), f23 = weight_within(within, &df23);
  double y = -(n[0] * e2[0] + n[1] * e2[1]), size = norm2(n[2], y);
  double cb = 1, sb = 0, cg = 1, sg = 0, d_cb[3] = {0, 0, 0}, d_sb[3] = {0, 0, 0}, d_cg[3] = {0, 0, 0},
         d_sg[3] = {0, 0, 0};
  if (size > 0) {
    double inverse = 1 / size;
    cb = n[2] * inverse;
    sb = y * inverse;
    for (int k = 0; de2 && k < 3; k++) {
      d_cb[k] = -cb * sb * inverse * dy[k];
      d_sb[k] = cb * cb * inverse * dy[k];
    }
  }
  if (within > 0) {
    double inverse = 1 / within;
    cg = along * inverse;
    sg = -u[2] * inverse;
    for (int k = 0; k < 3; k++) d_within[k] = (along * d_along[k] + (k == 2 ? u[2] : 0)) * inverse;
    for (int k = 0; k < 3; k++) {
      d_cg[k] = (d_along[k] - cg * d_within[k]) * inverse;
      d_sg[k] = ((k == 2 ? -1 : 0) - sg * d_within[k]) * inverse;
    }
  }
  double a[2], partial[2][4], da[2][3];
  alpha_unit_slope(coef, zeta, cb, sb, cg, sg, a, partial);
  for (int i = 0; i < 2; i++) {
    for (int k = 0; k < 3; k++) {
      da[i][k] = partial[i][2] * d_cg[k] + partial[i][3] * d_sg[k];
      if (de2) da[i][k] += partial[i][0] * d_cb[k] + partial[i][1] * d_sb[k];
    }
  }
  double alpha_1 = zeta * (coef[5] + coef[6] + coef[7]);
  double side = f1 * alpha_1 * (across > 0 ? 1 : across < 0 ? -1 : 0);
  for (int i = 0; i < 2; i++) stress[i] = -side * e1[i] - f23 * a[0] * e2[i];
  stress[2] = f23 * a[1];
  // f1(|a|) sign(a) is odd: its slope is f1'(|a|)
  for (int k = 0; k < 3; k++) {
    double d_side = df1 * alpha_1 * d_across[k], d_f23 = df23 * d_within[k];
    for (int i = 0; i < 2; i++) {
      ds[3 * i + k] = -d_side * e1[i] - (d_f23 * a[0] + f23 * da[0][k]) * e2[i];
      if (de2) ds[3 * i + k] -= side * de1[i][k] + f23 * a[0] * de2[i][k];
    }
    ds[6 + k] = d_f23 * a[1] + f23 * da[1][k];
  }
}

// out = scale s (I - u u^T) / speed: a rate-independent law's derivative in v from the one in its direction u.
static void direction_slope(const double s[9], const double u[3], double speed, double scale, double out[9]) {
  double factor = scale / speed;
  for (int i = 0; i < 3; i++) {
    double su = s[3 * i] * u[0] + s[3 * i + 1] * u[1] + s[3 * i + 2] * u[2];
    for (int k = 0; k < 3; k++) out[3 * i + k] = factor * (s[3 * i + k] - su * u[k]);
  }
}

// finrft_li2013_element_force and its derivative in the velocity, slope (3 x 3, row-major: slope[3 i + k] =
// dF_i / dv_k), analytic (as element_slopes in li2013.py): 0 where the force is.
FINRFT_EXPORT void finrft_li2013_element_slope(const double coef[NCOEF], double zeta, const double n[3],
                                               const double v[3], double depth, double area, double force[3],
                                               double slope[9]) {
  for (int i = 0; i < 9; i++) slope[i] = 0;
  force[0] = force[1] = force[2] = 0;
  if (!(depth > 0) || !(n[0] * v[0] + n[1] * v[1] + n[2] * v[2] > 0)) return;
  double speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), inverse = 1 / speed;
  double u[3] = {v[0] * inverse, v[1] * inverse, v[2] * inverse};
  double tilt = norm2(n[0], n[1]) / sqrt(1 - (1 - 1e-3) * (1 - 1e-3));
  if (tilt > 1) tilt = 1;
  double w = tilt * tilt * (3 - 2 * tilt);
  double e2[2], stress[3] = {0, 0, 0}, ds[9] = {0};
  if (w > 0) {
    horizontal_unit(n, v, e2);
    li2013_stress_slope(coef, zeta, n, u, e2, NULL, stress, ds);
  }
  if (w < 1) {
    // the velocity's own plane turns with it: e2 = u_h / |u_h|, de2/du_h = (I - e2 e2^T) / |u_h|
    double own[3], own_slope[9], turning[2][3] = {{0, 0, 0}, {0, 0, 0}}, size = norm2(u[0], u[1]);
    horizontal_unit(v, n, e2);
    if (size > 0) {
      for (int i = 0; i < 2; i++) {
        for (int k = 0; k < 2; k++) turning[i][k] = ((i == k) - e2[i] * e2[k]) / size;
      }
    }
    li2013_stress_slope(coef, zeta, n, u, e2, turning, own, own_slope);
    for (int i = 0; i < 3; i++) stress[i] = w * stress[i] + (1 - w) * own[i];
    for (int i = 0; i < 9; i++) ds[i] = w * ds[i] + (1 - w) * own_slope[i];
  }
  for (int i = 0; i < 3; i++) force[i] = area * depth * stress[i];
  direction_slope(ds, u, speed, area * depth, slope);
}

// The 20 monomials of the 3D-RFT fit, in the order of terms() in rft3d.py.
static void rft3d_terms(double p1, double p2, double p3, double t[NTERMS]) {
  const double values[NTERMS] = {1,           p1,           p2,           p3,           p1 * p1,
                                 p2 * p2,     p3 * p3,      p1 * p2,      p2 * p3,      p3 * p1,
                                 p1 * p1 * p1, p2 * p2 * p2, p3 * p3 * p3, p1 * p2 * p2, p2 * p1 * p1,
                                 p2 * p3 * p3, p3 * p2 * p2, p3 * p1 * p1, p1 * p3 * p3, p1 * p2 * p3};
  memcpy(t, values, sizeof(values));
}

// sum_i c_i t_i over the 20 terms, in two interleaved sums: one chain of 20 additions was most of a call's time.
static inline double rft3d_sum(const double c[NTERMS], const double t[NTERMS]) {
  double even = 0, odd = 0;
  for (int i = 0; i < NTERMS; i += 2) {
    even += c[i] * t[i];
    odd += c[i + 1] * t[i + 1];
  }
  return even + odd;
}

// The 3D-RFT force on one element (world frame, z up): coefficients c1, c2, c3, the medium's scale xi (N/m^3),
// the surface friction, outward unit normal n, velocity v, depth below the surface, area. As element_forces in
// rft3d.py.
FINRFT_EXPORT void finrft_rft3d_element_force(const double coef[NCOEF_RFT3D], double xi, double mu_surf,
                                              const double n[3], const double v[3], double depth,
                                              double area, double force[3]) {
  force[0] = force[1] = force[2] = 0;
  if (!(depth > 0) || !(n[0] * v[0] + n[1] * v[1] + n[2] * v[2] > 0)) return;
  double speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), inverse = 1 / speed;
  double u[3] = {v[0] * inverse, v[1] * inverse, v[2] * inverse};
  double side = n[2] < 0 ? 1 : -1;  // the plate's lower face
  double low[3] = {side * n[0], side * n[1], side * n[2]};
  double t[NTERMS], f[3];
  rft3d_terms(-u[2], -low[2], low[0] * u[0] + low[1] * u[1] + low[2] * u[2], t);
  for (int k = 0; k < 3; k++) f[k] = rft3d_sum(coef + NTERMS * k, t);
  double stress[3], normal_part[3], tangential[3];
  for (int i = 0; i < 3; i++) stress[i] = f[0] * low[i] + f[1] * u[i];
  stress[2] -= f[2];
  double along = stress[0] * n[0] + stress[1] * n[1] + stress[2] * n[2];
  for (int i = 0; i < 3; i++) {
    normal_part[i] = along * n[i];
    tangential[i] = stress[i] - normal_part[i];
  }
  double cap = mu_surf * sqrt(normal_part[0] * normal_part[0] + normal_part[1] * normal_part[1] +
                              normal_part[2] * normal_part[2]);
  double size = sqrt(tangential[0] * tangential[0] + tangential[1] * tangential[1] + tangential[2] * tangential[2]);
  double kept = size > cap ? cap / size : 1;
  double scale = xi * area * depth;
  for (int i = 0; i < 3; i++) force[i] = scale * (normal_part[i] + kept * tangential[i]);
}

// The derivatives of sum_i c_i T_i (rft3d_terms' order) in p1 and in p3, c one of c1, c2, c3: only the terms that
// hold p1 (p3), each written out (a product by a zero derivative is not skipped where it could be a NaN's).
static void rft3d_term_slopes(const double c[NTERMS], double p1, double p2, double p3, double* d1, double* d3) {
  *d1 = c[1] + 2 * p1 * c[4] + p2 * c[7] + p3 * c[9] + 3 * p1 * p1 * c[10] + p2 * p2 * c[13] + 2 * p1 * p2 * c[14] +
        2 * p1 * p3 * c[17] + p3 * p3 * c[18] + p2 * p3 * c[19];
  *d3 = c[3] + 2 * p3 * c[6] + p2 * c[8] + p1 * c[9] + 3 * p3 * p3 * c[12] + 2 * p2 * p3 * c[15] + p2 * p2 * c[16] +
        p1 * p1 * c[17] + 2 * p1 * p3 * c[18] + p1 * p2 * c[19];
}

// finrft_rft3d_element_force and its derivative in the velocity, slope (3 x 3, row-major: slope[3 i + k] =
// dF_i / dv_k), analytic (as element_slopes in rft3d.py): 0 where the force is.
FINRFT_EXPORT void finrft_rft3d_element_slope(const double coef[NCOEF_RFT3D], double xi, double mu_surf,
                                              const double n[3], const double v[3], double depth, double area,
                                              double force[3], double slope[9]) {
  for (int i = 0; i < 9; i++) slope[i] = 0;
  force[0] = force[1] = force[2] = 0;
  if (!(depth > 0) || !(n[0] * v[0] + n[1] * v[1] + n[2] * v[2] > 0)) return;
  double speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), inverse = 1 / speed;
  double u[3] = {v[0] * inverse, v[1] * inverse, v[2] * inverse};
  double side = n[2] < 0 ? 1 : -1;
  double low[3] = {side * n[0], side * n[1], side * n[2]};
  double p1 = -u[2], p2 = -low[2], p3 = low[0] * u[0] + low[1] * u[1] + low[2] * u[2];
  double t[NTERMS], f[3], a[3], b[3];
  rft3d_terms(p1, p2, p3, t);
  for (int k = 0; k < 3; k++) {
    f[k] = rft3d_sum(coef + NTERMS * k, t);
    rft3d_term_slopes(coef + NTERMS * k, p1, p2, p3, a + k, b + k);
  }
  // d f_k / du = -a_k z + b_k low; stress = f_0 low + f_1 u - f_2 z
  double df[3][3], stress[3], ds[9];
  for (int k = 0; k < 3; k++) {
    for (int j = 0; j < 3; j++) df[k][j] = b[k] * low[j] - (j == 2 ? a[k] : 0);
  }
  for (int i = 0; i < 3; i++) {
    stress[i] = f[0] * low[i] + f[1] * u[i];
    for (int j = 0; j < 3; j++) {
      ds[3 * i + j] = low[i] * df[0][j] + u[i] * df[1][j] + (i == j ? f[1] : 0) - (i == 2 ? df[2][j] : 0);
    }
  }
  stress[2] -= f[2];
  double along = stress[0] * n[0] + stress[1] * n[1] + stress[2] * n[2], tangential[3], d_along[3], td[3];
  for (int i = 0; i < 3; i++) tangential[i] = stress[i] - along * n[i];
  for (int j = 0; j < 3; j++) {
    d_along[j] = n[0] * ds[j] + n[1] * ds[3 + j] + n[2] * ds[6 + j];
    td[j] = tangential[0] * ds[j] + tangential[1] * ds[3 + j] + tangential[2] * ds[6 + j];
  }
  double cap = mu_surf * fabs(along);
  double size = sqrt(finrft_dot3(tangential, tangential));
  double kept = size > cap ? cap / size : 1, d_kept[3] = {0, 0, 0};
  if (size > cap) {
    // d kept = (mu_surf sign(s_n) d s_n - kept t . d s / |t|) / |t|, t being across n
    double sign = along > 0 ? 1 : along < 0 ? -1 : 0;
    for (int j = 0; j < 3; j++) d_kept[j] = (mu_surf * sign * d_along[j] - kept * td[j] / size) / size;
  }
  double d_out[9];
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      double d_normal = n[i] * d_along[j];
      d_out[3 * i + j] = d_normal + kept * (ds[3 * i + j] - d_normal) + tangential[i] * d_kept[j];
    }
  }
  double scale = xi * area * depth;
  for (int i = 0; i < 3; i++) force[i] = scale * (along * n[i] + kept * tangential[i]);
  direction_slope(d_out, u, speed, scale, slope);
}

// DRFT's dynamic inertial force on one element (world frame): -lambda rho_c (n . v)^2 n area on a leading element
// below the surface, else 0. As element_forces in drft.py.
FINRFT_EXPORT void finrft_drft_element_force(double drft_lambda, double rho_c, const double n[3],
                                             const double v[3], double depth, double area,
                                             double force[3]) {
  force[0] = force[1] = force[2] = 0;
  double v_n = n[0] * v[0] + n[1] * v[1] + n[2] * v[2];
  if (!(depth > 0) || !(v_n > 0)) return;
  double pressure = drft_lambda * rho_c * v_n * v_n * area;
  for (int i = 0; i < 3; i++) force[i] = -pressure * n[i];
}

// The two long texts last, the elements (read once) after the grid (read three times): MuJoCo finds a key's value by
// walking past every value before it.
static const char* kSurfaceAttributes[] = {"law",          "coefficients",   "zeta",        "xi",
                                           "mu_surf",      "surface_z",      "v_reg",       "drft_lambda",
                                           "bulk_density", "geoms",          "surface",     "surface_point",
                                           "surface_normal", "pile_factor",  "hfield",      "elements"};

static void surface_free(FinrftSurface* p) {
  if (!p) return;
  free(p->element);
  free(p->geom);
  if (p->field.kind != FINRFT_FIELD_DEFORMING) free(p->field.heights);  // a deforming one's are d->plugin_state
  free(p->field.original);
  free(p->scratch);
  free(p);
}

// Parse whitespace-separated finite numbers; returns the count, or -1 on anything else. values may be NULL to
// count only.
static int read_numbers(const char* text, double* values, int capacity) {
  int count = 0;
  const char* cursor = text;
  for (;;) {
    char* end = NULL;
    double value = strtod(cursor, &end);
    if (end == cursor) break;
    if (!isfinite(value)) return -1;
    if (values && count < capacity) values[count] = value;
    count++;
    cursor = end;
  }
  while (*cursor == ' ' || *cursor == '\t' || *cursor == '\n') cursor++;
  return *cursor ? -1 : count;
}

static int read_scalar(const mjModel* m, int instance, const char* key, double* out) {
  const char* text = mj_getPluginConfig(m, instance, key);
  if (!text || read_numbers(text, out, 1) != 1) {
    mju_warning("finrft.surface: config '%s' must be one number", key);
    return -1;
  }
  return 0;
}

// A deforming surface's view of the elements, once: their largest distance from the body's origin, their largest
// |coordinate| along each of its axes, and their centres by coordinate (p->scratch + 4 n: every x, every y, every z),
// for loops over the elements that the compiler vectorises.
static void deforming_elements(FinrftSurface* p) {
  double* centres = p->scratch + 4 * p->n;
  for (int i = 0; i < p->n; i++) {
    const double* e = p->element + 7 * i;
    p->reach = fmax(p->reach, mju_norm3(e));
    for (int k = 0; k < 3; k++) {
      p->extent[k] = fmax(p->extent[k], fabs(e[k]));
      centres[k * p->n + i] = e[k];
    }
  }
}

// A surface law's scale keys read into the instance; 0, or -1 after a warning.
static int read_zeta(const mjModel* m, int instance, FinrftSurface* p) {
  if (read_scalar(m, instance, "zeta", &p->zeta)) return -1;
  if (p->zeta > 0) return 0;
  mju_warning("finrft.surface: config 'zeta' must be > 0");
  return -1;
}

static int read_xi(const mjModel* m, int instance, FinrftSurface* p) {
  if (read_scalar(m, instance, "xi", &p->xi) || read_scalar(m, instance, "mu_surf", &p->mu_surf)) return -1;
  if (p->xi > 0 && p->mu_surf >= 0) return 0;
  mju_warning("finrft.surface: config 'xi' must be > 0 and 'mu_surf' >= 0");
  return -1;
}

// The kinds of free surface by name (finrft.surfaces; FINRFT_FIELD_* in finrft.h, in this order).
static const char* kFields[] = {"flat", "plane", "hfield", "deforming"};
#define NFIELDS ((int)(sizeof(kFields) / sizeof(kFields[0])))

// The hook of a kind of free surface: its depths through its own function of plugins/surfaces/. A kind with state
// (the deforming one) adds its FINRFT_FIELD_ value and name (kFields), reads its grid in read_field, and here calls
// finrft_deforming_depth on heights it keeps per mjData: in the instance (FinrftSurface is per mjData) when one body
// meets the sand, else in d->plugin_state of one instance that all share (surface_nstate its size, so that
// mj_getState and checkpoints carry it), pointed at by f->heights in finrft_surface_instance; it updates them
// (finrft_deforming_sweep, _relax) once per step, in surface_compute after the force is applied.
int finrft_field_depth(const FinrftField* f, const double g[3], int n, const double* points, double* depth) {
  switch (f->kind) {
    case FINRFT_FIELD_FLAT:
      return finrft_flat_depth(f->surface_z, g, n, points, depth);
    case FINRFT_FIELD_PLANE:
      return finrft_plane_depth(f->point, f->normal, g, n, points, depth);
    case FINRFT_FIELD_HFIELD:
      return finrft_hfield_depth(f->nrow, f->ncol, f->heights, f->size, f->centre, f->frame, g, n, points, depth);
    case FINRFT_FIELD_DEFORMING:
      return finrft_deforming_depth(f->nrow, f->ncol, f->heights, f->original, f->pile_factor, f->size, f->centre,
                                    f->frame, g, n, points, depth);
    default:
      return FINRFT_SURFACE_BAD_INPUT;
  }
}

// A config key of exactly `count` numbers into out; 0, or -1 after a warning.
static int read_vector(const mjModel* m, int instance, const char* key, double* out, int count) {
  const char* text = mj_getPluginConfig(m, instance, key);
  if (!text || read_numbers(text, out, count) != count) {
    mju_warning("finrft.surface: config '%s' must be %d numbers", key, count);
    return -1;
  }
  return 0;
}

// The free surface of config `surface` (and surface_z) into p->field; 0, or -1 after a warning.
static int read_field(const mjModel* m, int instance, FinrftSurface* p) {
  FinrftField* f = &p->field;
  f->surface_z = p->surface_z;
  const char* kind = mj_getPluginConfig(m, instance, "surface");
  f->kind = FINRFT_FIELD_FLAT;
  if (kind && *kind) {
    while (f->kind < NFIELDS && strcmp(kind, kFields[f->kind])) f->kind++;
    if (f->kind == NFIELDS) {
      mju_warning("finrft.surface: config 'surface' must be 'flat', 'plane', 'hfield' or 'deforming', got '%s'",
                  kind);
      return -1;
    }
  }
  if (f->kind == FINRFT_FIELD_PLANE) {
    return read_vector(m, instance, "surface_point", f->point, 3) ||
           read_vector(m, instance, "surface_normal", f->normal, 3) ? -1 : 0;
  }
  if (f->kind == FINRFT_FIELD_DEFORMING) {
    const char* pile = mj_getPluginConfig(m, instance, "pile_factor");
    if (pile && *pile && (read_scalar(m, instance, "pile_factor", &f->pile_factor) || !(f->pile_factor >= 0))) {
      mju_warning("finrft.surface: config 'pile_factor' must be >= 0");
      return -1;
    }
  }
  if (f->kind != FINRFT_FIELD_HFIELD && f->kind != FINRFT_FIELD_DEFORMING) return 0;
  const char* text = mj_getPluginConfig(m, instance, "hfield");
  // read once (a grid's text is long): a number takes at least a character and a separator
  int capacity = text ? (int)(strlen(text) / 2 + 1) : 0;
  double* all = capacity ? (double*)malloc(capacity * sizeof(double)) : NULL;
  if (text && !all) return -1;
  int count = all ? read_numbers(text, all, capacity) : -1;
  if (count < 16 || all[0] < 2 || all[1] < 2 || all[0] != floor(all[0]) || all[1] != floor(all[1]) ||
      count != 16 + all[0] * all[1]) {
    free(all);
    mju_warning("finrft.surface: config 'hfield' must be nrow ncol (at least 2 each), size (2), centre (3), frame "
                "(9) and nrow x ncol heights");
    return -1;
  }
  f->nrow = (int)all[0];
  f->ncol = (int)all[1];
  memcpy(f->size, all + 2, 2 * sizeof(double));
  memcpy(f->centre, all + 4, 3 * sizeof(double));
  memcpy(f->frame, all + 7, 9 * sizeof(double));
  memmove(all, all + 16, (count - 16) * sizeof(double));
  double* heights = (double*)realloc(all, (count - 16) * sizeof(double));  // the heights only
  if (heights) all = heights;
  if (f->kind == FINRFT_FIELD_DEFORMING) {
    f->original = all;  // its heights, the level, are state: in d->plugin_state (finrft_surface_instance)
  } else {
    f->heights = all;
  }
  return 0;
}

static void li2013_force(const FinrftSurface* p, const double n[3], const double v[3], double depth, double area,
                         double f[3]) {
  li2013_element_force(p->coef, p->zeta, n, v, depth, area, f);
}

static void li2013_planar_force(const FinrftSurface* p, const double n[3], const double v[3], double depth,
                                double area, double f[3]) {
  finrft_li2013_planar_element_force(p->coef, p->zeta, n, v, depth, area, f);
}

static void rft3d_force(const FinrftSurface* p, const double n[3], const double v[3], double depth, double area,
                        double f[3]) {
  finrft_rft3d_element_force(p->coef, p->xi, p->mu_surf, n, v, depth, area, f);
}

static void li2013_slope(const FinrftSurface* p, const double n[3], const double v[3], double depth, double area,
                         double f[3], double k[9]) {
  finrft_li2013_element_slope(p->coef, p->zeta, n, v, depth, area, f, k);
}

static void rft3d_slope(const FinrftSurface* p, const double n[3], const double v[3], double depth, double area,
                        double f[3], double k[9]) {
  finrft_rft3d_element_slope(p->coef, p->xi, p->mu_surf, n, v, depth, area, f, k);
}

// The surface laws by name (the registry finrft.laws of KIND "surface"): coefficient count, scale keys, force,
// and the force with its analytic velocity Jacobian (NULL: the implicit steps difference the force instead).
static const struct {
  const char* name;
  int ncoef;
  int (*read)(const mjModel* m, int instance, FinrftSurface* p);
  void (*force)(const FinrftSurface* p, const double n[3], const double v[3], double depth, double area,
                double f[3]);
  void (*slope)(const FinrftSurface* p, const double n[3], const double v[3], double depth, double area,
                double f[3], double k[9]);
} kLaws[] = {{"li2013", NCOEF, read_zeta, li2013_force, li2013_slope},
             {"li2013-planar", NCOEF, read_zeta, li2013_planar_force, NULL},
             {"rft3d", NCOEF_RFT3D, read_xi, rft3d_force, rft3d_slope}};
#define NLAWS ((int)(sizeof(kLaws) / sizeof(kLaws[0])))

// The law named `law` (kLaws) on n elements (normal, velocity: 3 n each; depth, area: n), `repeat` passes over
// them, each element's force into force (3 n), called as the plugin calls it (an upright instance's framed_force):
// what `finrft bench laws` times, one call a round, so that no caller's overhead counts per element. coef holds the
// law's coefficients (kLaws' ncoef), scale its zeta (li2013) or xi (rft3d). 0, or -1 for an unknown law.
FINRFT_EXPORT int finrft_law_forces(const char* law, const double* coef, double scale, double mu_surf, int n,
                                    const double* normal, const double* velocity, const double* depth,
                                    const double* area, int repeat, double* force) {
  int index = 0;
  while (index < NLAWS && strcmp(law, kLaws[index].name)) index++;
  if (index == NLAWS) return -1;
  FinrftSurface p;
  memset(&p, 0, sizeof(p));
  p.law = index;
  memcpy(p.coef, coef, kLaws[index].ncoef * sizeof(double));
  p.zeta = p.xi = scale;
  p.mu_surf = mu_surf;
  for (int r = 0; r < repeat; r++) {
    for (int i = 0; i < n; i++) {
      kLaws[index].force(&p, normal + 3 * i, velocity + 3 * i, depth[i], area[i], force + 3 * i);
    }
  }
  return 0;
}

static int surface_init(const mjModel* m, mjData* d, int instance) {
  const char* law = mj_getPluginConfig(m, instance, "law");
  int index = 0;
  while (index < NLAWS && !(law && !strcmp(law, kLaws[index].name))) index++;
  if (index == NLAWS) {
    mju_warning("finrft.surface: config 'law' must be 'li2013', 'li2013-planar' or 'rft3d', got '%s'",
                law ? law : "");
    return -1;
  }
  FinrftSurface* p = (FinrftSurface*)calloc(1, sizeof(FinrftSurface));
  if (!p) return -1;
  p->law = index;
  int ncoef = kLaws[index].ncoef;
  const char* coef = mj_getPluginConfig(m, instance, "coefficients");
  if (!coef || read_numbers(coef, p->coef, ncoef) != ncoef) {
    mju_warning("finrft.surface: config 'coefficients' must hold %d numbers for law '%s'", ncoef, law);
    surface_free(p);
    return -1;
  }
  if (read_scalar(m, instance, "surface_z", &p->surface_z) || kLaws[index].read(m, instance, p) ||
      read_field(m, instance, p)) {
    surface_free(p);
    return -1;
  }
  const char* v_reg = mj_getPluginConfig(m, instance, "v_reg");
  if (v_reg && *v_reg && (read_scalar(m, instance, "v_reg", &p->v_reg) || !(p->v_reg >= 0))) {
    mju_warning("finrft.surface: config 'v_reg' must be >= 0");
    surface_free(p);
    return -1;
  }
  const char* drft = mj_getPluginConfig(m, instance, "drft_lambda");
  if (drft && *drft) {
    if (read_scalar(m, instance, "drft_lambda", &p->drft_lambda)) {
      surface_free(p);
      return -1;
    }
    if (!(p->drft_lambda >= 0) ||
        (p->drft_lambda > 0 && (read_scalar(m, instance, "bulk_density", &p->bulk_density) ||
                                !(p->bulk_density > 0)))) {
      mju_warning("finrft.surface: config 'drft_lambda' must be >= 0, and when > 0 'bulk_density' must be > 0");
      surface_free(p);
      return -1;
    }
  }
  p->body = -1;
  for (int b = 0; b < m->nbody; b++) {
    if (m->body_plugin[b] != instance) continue;
    if (p->body >= 0) {
      mju_warning("finrft.surface: an instance serves one body");
      surface_free(p);
      return -1;
    }
    p->body = b;
  }
  const char* text = mj_getPluginConfig(m, instance, "elements");
  int count = text ? read_numbers(text, NULL, 0) : -1;
  if (p->body < 0 || count <= 0 || count % 7) {
    mju_warning("finrft.surface: config 'elements' must hold 7 numbers per element (centre, normal, area) and "
                "the instance must be bound to one body");
    surface_free(p);
    return -1;
  }
  p->n = count / 7;
  p->element = (double*)malloc(count * sizeof(double));
  if (!p->element) {
    surface_free(p);
    return -1;
  }
  read_numbers(text, p->element, count);
  int deforming = p->field.kind == FINRFT_FIELD_DEFORMING;
  p->scratch = (double*)malloc((deforming ? 7 : 4) * p->n * sizeof(double));
  if (!p->scratch) {
    surface_free(p);
    return -1;
  }
  if (deforming) deforming_elements(p);
  const char* geoms = mj_getPluginConfig(m, instance, "geoms");
  count = geoms && *geoms ? read_numbers(geoms, NULL, 0) : 0;
  if (count < 0 || count % 12) {
    mju_warning("finrft.surface: config 'geoms' must hold 12 numbers per geom");
    surface_free(p);
    return -1;
  }
  p->ngeom = count / 12;
  p->geom = count ? (double*)malloc(count * sizeof(double)) : NULL;
  if (count && !p->geom) {
    surface_free(p);
    return -1;
  }
  if (count) read_numbers(geoms, p->geom, count);
  p->model = m;
  d->plugin_data[instance] = (uintptr_t)p;
  return 0;
}

// A deforming surface's level (nrow x ncol heights, m) is the instance's state, in d->plugin_state: mj_getState
// and mj_setState carry it, and an instance made again for another model (or an MjData copied) keeps it.
static int surface_nstate(const mjModel* m, int instance) {
  const char* kind = mj_getPluginConfig(m, instance, "surface");
  const char* text = mj_getPluginConfig(m, instance, "hfield");
  if (!kind || strcmp(kind, "deforming") || !text) return 0;
  // the grid's first two numbers, without reading its heights (read_field checks the rest)
  char *end = NULL, *next = NULL;
  double nrow = strtod(text, &end), ncol = strtod(end, &next);
  if (end == text || next == end) return 0;
  return nrow >= 2 && ncol >= 2 ? (int)nrow * (int)ncol : 0;
}

static void surface_destroy(mjData* d, int instance) {
  surface_free((FinrftSurface*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

// A deforming surface starts at its original heights.
static void surface_reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data, int instance) {
  const FinrftSurface* p = (const FinrftSurface*)plugin_data;
  if (p && p->field.kind == FINRFT_FIELD_DEFORMING && m->plugin_statenum[instance] == p->field.nrow * p->field.ncol) {
    memcpy(plugin_state, p->field.original, p->field.nrow * p->field.ncol * sizeof(double));
  }
}

// The first geom of the instance's body that differs from what its elements were cut from (config `geoms`), as
// its place in p->geom; -1 when none does. Checked at every use: geom_size may change between steps.
static int geom_changed(const mjModel* m, const FinrftSurface* p) {
  for (int j = 0; j < p->ngeom; j++) {
    const double* cut = p->geom + 12 * j;
    int k = (int)cut[0], g = m->body_geomadr[p->body] + k;
    if (k >= m->body_geomnum[p->body] || m->geom_type[g] != (int)cut[1]) return j;
    for (int i = 0; i < 3; i++)
      if (m->geom_size[3 * g + i] != cut[2 + i] || m->geom_pos[3 * g + i] != cut[5 + i]) return j;
    for (int i = 0; i < 4; i++)
      if (m->geom_quat[4 * g + i] != cut[8 + i]) return j;
  }
  return -1;
}

// The model's gravity into the instance, its law frame and whether it is level (as SurfaceForces.level and
// .frame in attach.py); -1 when the surface cannot be measured under it.
static int refresh_gravity(const mjModel* m, FinrftSurface* p) {
  const mjtNum* g = m->opt.gravity;
  if (p->measured && p->gravity[0] == g[0] && p->gravity[1] == g[1] && p->gravity[2] == g[2]) return 0;
  double up[3];
  for (int i = 0; i < 3; i++) p->gravity[i] = g[i];
  // (no gravity over the flat surface is level too, as it always was: depth from z)
  p->upright = g[0] == 0 && g[1] == 0 && g[2] <= 0;
  p->level = p->field.kind == FINRFT_FIELD_FLAT && p->upright;
  p->measured = p->level || !(finrft_surface_up(p->gravity, up) ||
                              finrft_field_depth(&p->field, p->gravity, 0, NULL, NULL));
  if (!p->measured) return -1;
  if (!p->upright) finrft_surface_frame(up, p->frame);
  return 0;
}

// The instance for the model `d` is stepped with, made again when it was made for another: as finrft_instance.
const FinrftSurface* finrft_surface_instance(const mjModel* m, mjData* d, int instance) {
  const FinrftSurface* p = (const FinrftSurface*)d->plugin_data[instance];
  if (!p || p->model != m) {
    surface_destroy(d, instance);
    if (surface_init(m, d, instance)) {
      finrft_poison(m, d);
      return NULL;
    }
    p = (const FinrftSurface*)d->plugin_data[instance];
  }
  if (p->field.kind == FINRFT_FIELD_DEFORMING) {
    if (m->plugin_statenum[instance] != p->field.nrow * p->field.ncol) {
      mju_error("finrft.surface: a deforming surface's model holds no state of its grid's size");
    }
    ((FinrftSurface*)p)->field.heights = d->plugin_state + m->plugin_stateadr[instance];
  }
  if (refresh_gravity(m, (FinrftSurface*)p)) {
    mju_error("finrft.surface: the free surface cannot be measured under gravity (%g, %g, %g): it must face "
              "against gravity (a heightfield's grid level with it), and gravity be nonzero",
              m->opt.gravity[0], m->opt.gravity[1], m->opt.gravity[2]);
  }
  int changed = geom_changed(m, p);
  if (changed >= 0) {
    // as geom_changed in finrft/attach.py
    int k = (int)p->geom[12 * changed], g = m->body_geomadr[p->body] + k;
    const char* geom = k < m->body_geomnum[p->body] ? mj_id2name(m, mjOBJ_GEOM, g) : NULL;
    const char* body = mj_id2name(m, mjOBJ_BODY, p->body);
    char label[24];
    if (!geom || !*geom) {
      snprintf(label, sizeof(label), "#%d", k);
      geom = label;
    }
    mju_error("geom '%s' of body '%s' changed its type, size, position or orientation since finrft.attach cut it "
              "into elements, which keep the old geom's force: call attach on a spec that has the geoms' final "
              "sizes (one spec per size when randomising), then compile it", geom, body ? body : "");
  }
  return p;
}

// The law's force in its frame (finrft_surface_frame): n and v seen in it, the force given back in the world's
// (as Attached.law_forces with a frame); the law's own call when upright.
static void framed_force(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                         mjtNum area, mjtNum f[3]) {
  if (p->upright) {
    kLaws[p->law].force(p, normal, v, depth, area, f);
    return;
  }
  mjtNum n_law[3], v_law[3], f_law[3];
  mju_mulMatVec3(n_law, p->frame, normal);
  mju_mulMatVec3(v_law, p->frame, v);
  kLaws[p->law].force(p, n_law, v_law, depth, area, f_law);
  mju_mulMatTVec3(f, p->frame, f_law);
}

void finrft_surface_law_force(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                              mjtNum area, mjtNum f[3]) {
  framed_force(p, normal, v, depth, area, f);
}

// One element's force (world frame): the law's, plus DRFT's term, times the ramp tanh(max(n . v, 0) / v_reg), 0
// below FINRFT_RAMP_FLOOR (as Attached.element_forces in attach.py and `regularised` in finrft/laws/__init__.py).
void finrft_surface_element_force(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                                  mjtNum area, mjtNum f[3]) {
  mjtNum v_n = finrft_dot3(normal, v);
  if (p->v_reg > 0 && !(v_n > FINRFT_RAMP_FLOOR * p->v_reg)) {
    f[0] = f[1] = f[2] = 0;
    return;
  }
  framed_force(p, normal, v, depth, area, f);
  if (p->drft_lambda > 0) {
    mjtNum inertial[3];
    finrft_drft_element_force(p->drft_lambda, p->bulk_density, normal, v, depth, area, inertial);
    for (int i = 0; i < 3; i++) f[i] += inertial[i];
  }
  if (p->v_reg > 0) {
    // tanh is 1 in double from 19.1 on: the same number without the call, for an element well above v_reg
    mjtNum ratio = (v_n > 0 ? v_n : 0) / p->v_reg;
    if (ratio < 20) {
      mjtNum ramp = tanh(ratio);
      for (int i = 0; i < 3; i++) f[i] *= ramp;
    }
  }
}

int finrft_surface_has_slope(const FinrftSurface* p) {
  return kLaws[p->law].slope != NULL;
}

// finrft_surface_element_force and its derivative in v, k (3 x 3, row-major), analytic (as
// Attached.element_slopes): d(r F)/dv = r dF/dv + r'(n . v) F n^T, DRFT's term's -2 lambda rho (n . v) area n n^T
// in F's.
int finrft_surface_element_slope(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                                 mjtNum area, mjtNum f[3], mjtNum k[9]) {
  mjtNum v_n = finrft_dot3(normal, v);
  if (p->v_reg > 0 && !(v_n > FINRFT_RAMP_FLOOR * p->v_reg)) {
    f[0] = f[1] = f[2] = 0;
    for (int i = 0; i < 9; i++) k[i] = 0;
    return 0;
  }
  if (p->upright) {
    kLaws[p->law].slope(p, normal, v, depth, area, f, k);
  } else {
    // in the law's frame F: f = F^T f', k = F^T k' F
    mjtNum n_law[3], v_law[3], f_law[3], k_law[9], kf[9];
    mju_mulMatVec3(n_law, p->frame, normal);
    mju_mulMatVec3(v_law, p->frame, v);
    kLaws[p->law].slope(p, n_law, v_law, depth, area, f_law, k_law);
    mju_mulMatTVec3(f, p->frame, f_law);
    mju_mulMatMat(kf, k_law, p->frame, 3, 3, 3);
    mju_mulMatTMat(k, p->frame, kf, 3, 3, 3);
  }
  if (p->drft_lambda > 0 && depth > 0 && v_n > 0) {
    mjtNum inertial[3], rate = 2 * p->drft_lambda * p->bulk_density * v_n * area;
    finrft_drft_element_force(p->drft_lambda, p->bulk_density, normal, v, depth, area, inertial);
    mju_addTo3(f, inertial);
    for (int i = 0; i < 3; i++) {
      for (int j = 0; j < 3; j++) k[3 * i + j] -= rate * normal[i] * normal[j];
    }
  }
  if (p->v_reg > 0) {
    mjtNum ratio = (v_n > 0 ? v_n : 0) / p->v_reg;
    if (ratio < 20) {
      mjtNum ramp = tanh(ratio), rate = (1 - ramp * ramp) / p->v_reg;
      for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) k[3 * i + j] = ramp * k[3 * i + j] + rate * f[i] * normal[j];
      }
      mju_scl3(f, f, ramp);
    }
  }
  return 1;
}

// An element that trails has force and slope 0, so a linearly implicit step at its velocity sees nothing of the force
// it takes as it leads again, and a light body settling chatters: within the ramp's width of leading, its slope is
// the secant F(v_s) n^T / (v_reg - n . v) to v_s = v + (v_reg - n . v) n, where it leads by v_reg: s = F(v_s) /
// (v_reg - n . v) into secant.
int finrft_surface_trailing_slope(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                                  mjtNum area, mjtNum secant[3]) {
  mjtNum v_n = finrft_dot3(normal, v);
  if (!(p->v_reg > 0) || !(v_n > -p->v_reg) || v_n > FINRFT_RAMP_FLOOR * p->v_reg) return 0;
  mjtNum gap = p->v_reg - v_n, ahead[3], f[3];
  for (int i = 0; i < 3; i++) ahead[i] = v[i] + gap * normal[i];
  finrft_surface_element_force(p, normal, ahead, depth, area, f);
  for (int i = 0; i < 3; i++) secant[i] = f[i] / gap;
  return 1;
}

// The depth below a level surface at surface_z of the element whose centre (body frame) is e, the body's origin at
// height z and the last row of its rotation r6 r7 r8: the arm's z alone, as mju_mulMatVec3 sums it, so that the
// elements above the surface (most of a legged robot's) cost no more. Numbers, not the instance and mjData: a
// caller that writes through a pointer keeps them in locals rather than reloading them for every element.
static inline double level_depth(double surface_z, double z, double r6, double r7, double r8, const double e[3]) {
  return surface_z - (z + (r6 * e[0] + r7 * e[1] + r8 * e[2]));
}

// ---- The deforming surface's elements ----

// Every element's depth below a deforming surface's level, into p->scratch + 3 n: an element's height in the grid's
// frame costs three products, and only those below the highest grid point under the body's box are interpolated
// (finrft_deforming_body_depths); the rest (most of a wheel's) get a depth <= 0, no force. As finrft_deforming_depth
// where the depth is positive.
static const double* deforming_element_depths(const FinrftSurface* p, const mjData* d) {
  const FinrftField* f = &p->field;
  const mjtNum* origin = d->xpos + 3 * p->body;
  const mjtNum* R = d->xmat + 9 * p->body;
  double* depth = p->scratch + 3 * p->n;
  FinrftDeformingGrid grid;
  finrft_deforming_grid(&grid, f->nrow, f->ncol, f->heights, f->original, f->pile_factor, f->size, f->centre,
                        f->frame);
  // the body's origin in the grid's frame, and its axes turned into the grid's: frame^T R
  double at[3], turn[9];
  finrft_grid_local(&grid.grid, origin, at);
  for (int j = 0; j < 3; j++) {
    for (int k = 0; k < 3; k++) {
      turn[3 * j + k] = f->frame[j] * R[k] + f->frame[3 + j] * R[3 + k] + f->frame[6 + j] * R[6 + k];
    }
  }
  finrft_deforming_body_depths(&grid, at, turn, p->extent, p->n, p->scratch + 4 * p->n, depth);
  return depth;
}
// ---- end of the deforming surface's elements ----

// Every element's depth along gravity below the free surface at the positions of d, into p->scratch + 3 n (the
// world centres before them); NULL when level, where level_depth takes each. The instance's surface was checked
// under this gravity (refresh_gravity), so its kind's function cannot refuse it.
static const double* element_depths(const FinrftSurface* p, const mjData* d) {
  if (p->level) return NULL;
  if (p->field.kind == FINRFT_FIELD_DEFORMING) return deforming_element_depths(p, d);
  const mjtNum* origin = d->xpos + 3 * p->body;
  const mjtNum* R = d->xmat + 9 * p->body;
  double* centre = p->scratch;
  for (int i = 0; i < p->n; i++) {
    mju_mulMatVec3(centre + 3 * i, R, p->element + 7 * i);
    mju_addTo3(centre + 3 * i, origin);
  }
  finrft_field_depth(&p->field, p->gravity, p->n, centre, p->scratch + 3 * p->n);
  return p->scratch + 3 * p->n;
}

void finrft_surface_wrench(const FinrftSurface* p, const mjData* d, const mjtNum twist[6], mjtNum wrench[6]) {
  const mjtNum* origin = d->xpos + 3 * p->body;
  const mjtNum* R = d->xmat + 9 * p->body;
  mju_zero(wrench, 6);
  const double* depths = element_depths(p, d);
  for (int i = 0; i < p->n; i++) {
    const double* e = p->element + 7 * i;
    mjtNum arm[3], normal[3], v[3], f[3], moment[3];
    double depth = depths ? depths[i] : level_depth(p->surface_z, origin[2], R[6], R[7], R[8], e);
    if (!(depth > 0)) continue;
    finrft_mul_mat_vec3(arm, R, e);
    finrft_mul_mat_vec3(normal, R, e + 3);
    finrft_cross(v, twist, arm);
    for (int k = 0; k < 3; k++) v[k] += twist[3 + k];
    finrft_surface_element_force(p, normal, v, depth, e[6], f);
    finrft_cross(moment, arm, f);
    for (int k = 0; k < 3; k++) {
      wrench[3 + k] += f[k];
      wrench[k] += moment[k];
    }
  }
}

int finrft_surface_submerged(const FinrftSurface* p, const mjData* d, mjtNum* out) {
  const mjtNum* origin = d->xpos + 3 * p->body;
  const mjtNum* R = d->xmat + 9 * p->body;
  int count = 0;
  const double* depths = element_depths(p, d);
  // level_depth's numbers held in locals: writing `out` may alias them, and reloading them for every element was
  // half the scan of a legged robot's elements, most of them above the surface
  const double surface_z = p->surface_z, z = origin[2], r6 = R[6], r7 = R[7], r8 = R[8];
  for (int i = 0; i < p->n; i++) {
    const double* e = p->element + 7 * i;
    double depth = depths ? depths[i] : level_depth(surface_z, z, r6, r7, r8, e);
    if (!(depth > 0)) continue;
    mjtNum* o = out + FINRFT_SUBMERGED * count;
    o[6] = depth;
    finrft_mul_mat_vec3(o, R, e);
    finrft_mul_mat_vec3(o + 3, R, e + 3);
    o[7] = e[6];
    count++;
  }
  return count;
}

// The wrench of finrft.surface instance `instance` on its body at the state of d, and the body's id (-1: the
// instance could not be made); the passive force's and the exported reader's one sum.
static int body_wrench(const mjModel* m, mjData* d, int instance, mjtNum wrench[6]) {
  const FinrftSurface* p = finrft_surface_instance(m, d, instance);
  if (!p) return -1;
  mjtNum twist[6];
  mj_objectVelocity(m, d, mjOBJ_XBODY, p->body, twist, 0);
  finrft_surface_wrench(p, d, twist, wrench);
  return p->body;
}

// The medium's wrench (torque about the body's origin, then force; world frame) on the body of instance
// `instance` at the state of d (after mj_forward), as the passive force applies it: finrft.attach's reader of the
// forces with the native backend (the recordings read finrft_surface_applied_wrench). The body's id, or -1 when the
// instance is not a finrft.surface one.
FINRFT_EXPORT int finrft_surface_body_wrench(const mjModel* m, mjData* d, int instance, mjtNum wrench[6]) {
  int slot = -1;
  mjp_getPlugin(FINRFT_SURFACE_PLUGIN, &slot);
  if (instance < 0 || instance >= m->nplugin || m->plugin[instance] != slot) return -1;
  return body_wrench(m, d, instance, wrench);
}

// The wrench (as finrft_surface_body_wrench) the passive force of instance `instance` applied in the last forward
// pass of d: what a recording after mj_forward reads, without summing the elements again. The body's id; -1 when
// the instance is not a finrft.surface one, -2 when that pass applied none (a stepper had it paused, or none ran).
FINRFT_EXPORT int finrft_surface_applied_wrench(const mjModel* m, mjData* d, int instance, mjtNum wrench[6]) {
  int slot = -1;
  mjp_getPlugin(FINRFT_SURFACE_PLUGIN, &slot);
  if (instance < 0 || instance >= m->nplugin || m->plugin[instance] != slot) return -1;
  const FinrftSurface* p = finrft_surface_instance(m, d, instance);
  if (!p) return -1;
  // with springs and dampers both disabled MuJoCo skips the passive forces, plugins' too, and `applied` is old
  int passive_off = (m->opt.disableflags & mjDSBL_SPRING) && (m->opt.disableflags & mjDSBL_DAMPER);
  if (!p->has_applied || passive_off) return -2;
  mju_copy(wrench, p->applied, 6);
  return p->body;
}

// The deforming surface's level (nrow x ncol heights, m; finrft.surfaces.deforming.DeformingSurface.level) that
// instance `instance` measures its elements' depths from in d from now on: its state, which a run steps between
// steps (finrft_deforming_sweep, _relax) and sets here. 0; -1 when the instance is not a finrft.surface one on a
// deforming surface of that grid.
FINRFT_EXPORT int finrft_surface_set_level(const mjModel* m, mjData* d, int instance, int nrow, int ncol,
                                           const double* level) {
  int slot = -1;
  mjp_getPlugin(FINRFT_SURFACE_PLUGIN, &slot);
  if (instance < 0 || instance >= m->nplugin || m->plugin[instance] != slot) return -1;
  FinrftSurface* p = (FinrftSurface*)finrft_surface_instance(m, d, instance);
  if (!p || p->field.kind != FINRFT_FIELD_DEFORMING || p->field.nrow != nrow || p->field.ncol != ncol) return -1;
  memcpy(d->plugin_state + m->plugin_stateadr[instance], level, nrow * ncol * sizeof(double));
  return 0;
}

// ---- The deforming surface's step ----
// A run's step of its deforming surface `s` (finrft.surfaces.deforming.DeformingSurface.step_model): once an element
// of the bodies of the finrft.surface `instances` may have moved `move` (m) since the last step (their origins'
// travel and their turn times their elements' reach, from the poses in d before the kinematics are made again; the
// last step's in `pose`, 7 per instance, NaN before the first), every element at the state of d sweeps the sand
// (finrft_deforming_step; the first step imprints the bodies) and the level is set in each instance's state. 1 when
// it stepped, with the volume displaced in *removed (m^3); 0 when not; -1 when an instance is not a finrft.surface one
// on a deforming surface of s's grid, or the step refused its input.
FINRFT_EXPORT int finrft_surface_deforming_step(const mjModel* m, mjData* d, FinrftDeforming* s, int ninstance,
                                                const int* instances, double* pose, double move, double* removed) {
  int slot = -1, n = 0;
  mjp_getPlugin(FINRFT_SURFACE_PLUGIN, &slot);
  const FinrftSurface* ps[ninstance > 0 ? ninstance : 1];
  for (int k = 0; k < ninstance; k++) {
    int instance = instances[k];
    if (instance < 0 || instance >= m->nplugin || m->plugin[instance] != slot) return -1;
    const FinrftSurface* p = finrft_surface_instance(m, d, instance);
    if (!p || p->field.kind != FINRFT_FIELD_DEFORMING || p->field.nrow != s->nrow || p->field.ncol != s->ncol) {
      return -1;
    }
    ps[k] = p;
    n += p->n;
  }
  *removed = 0;
  int first = isnan(pose[0]), still = !first;
  for (int k = 0; k < ninstance && still; k++) {
    const double* x = d->xpos + 3 * ps[k]->body;
    const double* q = d->xquat + 4 * ps[k]->body;
    double* last = pose + 7 * k;
    double dot = fabs(q[0] * last[3] + q[1] * last[4] + q[2] * last[5] + q[3] * last[6]);
    double turn = 2 * acos(dot < 1 ? dot : 1);
    double travel = sqrt((x[0] - last[0]) * (x[0] - last[0]) + (x[1] - last[1]) * (x[1] - last[1]) +
                         (x[2] - last[2]) * (x[2] - last[2]));
    if (!(travel + turn * ps[k]->reach < move)) still = 0;
  }
  if (still) return 0;
  for (int k = 0; k < ninstance; k++) {
    mju_copy3(pose + 7 * k, d->xpos + 3 * ps[k]->body);
    mju_copy4(pose + 7 * k + 3, d->xquat + 4 * ps[k]->body);
  }
  // every element's world centre, velocity and area at the state of d (as body_elements in deforming.py)
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_comVel(m, d);
  double* buffer = (double*)malloc(sizeof(double) * 10 * (n > 0 ? n : 1));
  if (!buffer) return -1;
  double *points = buffer, *velocities = buffer + 3 * n, *areas = buffer + 6 * n, *normals = buffer + 7 * n;
  int j = 0;
  for (int k = 0; k < ninstance; k++) {
    const FinrftSurface* p = ps[k];
    const mjtNum* origin = d->xpos + 3 * p->body;
    const mjtNum* R = d->xmat + 9 * p->body;
    mjtNum twist[6];
    mj_objectVelocity(m, d, mjOBJ_XBODY, p->body, twist, 0);
    for (int i = 0; i < p->n; i++, j++) {
      const double* e = p->element + 7 * i;
      double arm[3], spin[3];  // (mju_mulMatVec3, mju_add3 and mju_cross inline: the same numbers)
      finrft_mul_mat_vec3(arm, R, e);
      finrft_cross(spin, twist, arm);
      for (int k = 0; k < 3; k++) {
        points[3 * j + k] = arm[k] + origin[k];
        velocities[3 * j + k] = twist[3 + k] + spin[k];
      }
      areas[j] = e[6];
      if (s->facing) finrft_mul_mat_vec3(normals + 3 * j, R, e + 3);  // read by the facing rule alone
    }
  }
  int failed = finrft_deforming_step(s, m->opt.gravity, n, points, areas, velocities, s->facing ? normals : NULL,
                                     first, removed);
  free(buffer);
  if (failed) return -1;
  for (int k = 0; k < ninstance; k++) {
    memcpy(d->plugin_state + m->plugin_stateadr[instances[k]], s->level, s->nrow * s->ncol * sizeof(double));
  }
  return 1;
}
// ---- end of the deforming surface's step ----

// Every element's force, summed into one force and one torque about the body's origin, applied once.
static void surface_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  if (!(capability_bit & mjPLUGIN_PASSIVE)) return;
  FinrftSurface* p = (FinrftSurface*)finrft_surface_instance(m, d, instance);
  if (!p) return;
  p->has_applied = 0;
  if (p->paused) return;
  int body = body_wrench(m, d, instance, p->applied);
  if (body < 0) return;
  mj_applyFT(m, d, p->applied + 3, p->applied, d->xpos + 3 * body, body, d->qfrc_passive);
  p->has_applied = 1;
}

void finrft_register_surface(void) {
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = "finrft.surface";
  plugin.capabilityflags |= mjPLUGIN_PASSIVE;
  plugin.nattribute = sizeof(kSurfaceAttributes) / sizeof(kSurfaceAttributes[0]);
  plugin.attributes = kSurfaceAttributes;
  plugin.nstate = surface_nstate;
  plugin.init = surface_init;
  plugin.destroy = surface_destroy;
  plugin.reset = surface_reset;
  plugin.compute = surface_compute;
  mjp_registerPlugin(&plugin);
}
