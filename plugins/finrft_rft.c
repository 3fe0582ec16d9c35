// finrft.rft: a MuJoCo engine plugin (passive force) applying granular resistive force theory to plate segments.
//
// The C twin of finrft/rft.py and of the Python coupling in finrft/coupling.py: same laws, same formulas.
// Every site on a body bound to an instance is a segment midpoint: its x axis runs along the segment and its
// y axis is the segment's in-plane normal. Every hinge about z on a bound body gets the penalty stop when
// stop_stiffness > 0, acting on its deflection from the spring's rest angle (qpos_spring).
//
// Config (all values are strings in MJCF; every key is required, `table` only for the table law):
//   law            "paper" (default) or "table"
//   f_perp, f_par  paper law coefficients, N per segment
//   v_reg          > 0, m/s: the force fades out below this speed as tanh(|v| / v_reg)
//   table          table law: "attack_deg f_perp_N f_par_N ..." triples, attack increasing over 0..90 degrees
//   stop_stiffness >= 0, N m/rad: penalty stop torque -k_stop (q + |q|) q on each hinge deflection q
//
// No static state: everything lives in the per-mjData struct, so instances and threads never share memory.
//
// The library also exports the "implicit" and "newton" methods, finrft_implicit_step: MuJoCo's implicitfast step
// with the RFT force (which MuJoCo cannot differentiate in a plugin) linearised in velocity, or taken at the new
// velocity, penalty stops at the new positions, by Newton's method; and the "adaptive" method,
// finrft_adaptive_advance: implicit steps whose size follows a step-doubling error estimate.

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

typedef struct {
  int law_table;
  mjtNum f_perp, f_par, v_reg, stop_stiffness;
  int ntable;
  mjtNum* attack;  // radians
  mjtNum* table_perp;
  mjtNum* table_par;
  int nseg;
  int* site;
  int* body;
  int nhinge;
  int* hinge_qpos;
  int* hinge_dof;
} RFTData;

static const char* kAttributes[] = {"law", "f_perp", "f_par", "v_reg", "table", "stop_stiffness"};

static void free_data(RFTData* p) {
  if (!p) return;
  free(p->attack);
  free(p->table_perp);
  free(p->table_par);
  free(p->site);
  free(p->body);
  free(p->hinge_qpos);
  free(p->hinge_dof);
  free(p);
}

// Parse a required config value as one finite number; returns 0 on success.
static int read_number(const mjModel* m, int instance, const char* key, mjtNum* out) {
  const char* text = mj_getPluginConfig(m, instance, key);
  if (!text || !text[0]) {
    mju_warning("finrft.rft: config '%s' is missing", key);
    return -1;
  }
  char* end = NULL;
  double value = strtod(text, &end);
  while (end && (*end == ' ' || *end == '\t')) end++;
  if (end == text || (end && *end) || !isfinite(value)) {
    mju_warning("finrft.rft: config '%s' must be a number, got '%s'", key, text);
    return -1;
  }
  *out = value;
  return 0;
}

static int read_table(const mjModel* m, int instance, RFTData* p) {
  const char* text = mj_getPluginConfig(m, instance, "table");
  if (!text || !text[0]) {
    mju_warning("finrft.rft: law 'table' needs config 'table' (attack_deg f_perp_N f_par_N triples)");
    return -1;
  }
  int capacity = 16, count = 0;
  mjtNum* values = (mjtNum*)malloc(capacity * sizeof(mjtNum));
  const char* cursor = text;
  while (values) {
    char* end = NULL;
    double value = strtod(cursor, &end);
    if (end == cursor) break;
    if (!isfinite(value)) {
      free(values);
      mju_warning("finrft.rft: config 'table' holds a non-finite value");
      return -1;
    }
    if (count == capacity) {
      capacity *= 2;
      mjtNum* grown = (mjtNum*)realloc(values, capacity * sizeof(mjtNum));
      if (!grown) break;
      values = grown;
    }
    values[count++] = value;
    cursor = end;
  }
  while (cursor && (*cursor == ' ' || *cursor == '\t' || *cursor == '\n')) cursor++;
  int bad = !values || (cursor && *cursor) || count < 6 || count % 3;
  int n = count / 3;
  for (int i = 1; !bad && i < n; i++) bad = values[3 * i] <= values[3 * (i - 1)];
  if (!bad) bad = values[0] > 0 || values[3 * (n - 1)] < 90;
  if (bad) {
    free(values);
    mju_warning("finrft.rft: config 'table' must hold numeric triples 'attack_deg f_perp_N f_par_N' with the "
                "angle increasing over 0..90 degrees");
    return -1;
  }
  p->ntable = n;
  p->attack = (mjtNum*)malloc(n * sizeof(mjtNum));
  p->table_perp = (mjtNum*)malloc(n * sizeof(mjtNum));
  p->table_par = (mjtNum*)malloc(n * sizeof(mjtNum));
  for (int i = 0; i < n; i++) {
    p->attack[i] = values[3 * i] * (mjPI / 180.0);
    p->table_perp[i] = values[3 * i + 1];
    p->table_par[i] = values[3 * i + 2];
  }
  free(values);
  return 0;
}

// Linear interpolation with the end values held outside the range, in numpy.interp's arithmetic.
static mjtNum interp(mjtNum x, const mjtNum* xs, const mjtNum* ys, int n) {
  if (x <= xs[0]) return ys[0];
  if (x >= xs[n - 1]) return ys[n - 1];
  int lo = 0, hi = n - 1;
  while (hi - lo > 1) {
    int mid = (lo + hi) / 2;
    if (xs[mid] <= x) lo = mid; else hi = mid;
  }
  mjtNum slope = (ys[hi] - ys[lo]) / (xs[hi] - xs[lo]);
  return slope * (x - xs[lo]) + ys[lo];
}

static int rft_nstate(const mjModel* m, int instance) {
  return 0;
}

static int rft_init(const mjModel* m, mjData* d, int instance) {
  RFTData* p = (RFTData*)calloc(1, sizeof(RFTData));
  if (!p) return -1;
  const char* law = mj_getPluginConfig(m, instance, "law");
  if (!law || (strcmp(law, "paper") && strcmp(law, "table"))) {
    mju_warning("finrft.rft: config 'law' must be 'paper' or 'table', got '%s'", law ? law : "");
    free_data(p);
    return -1;
  }
  p->law_table = !strcmp(law, "table");
  if (read_number(m, instance, "f_perp", &p->f_perp) || read_number(m, instance, "f_par", &p->f_par) ||
      read_number(m, instance, "v_reg", &p->v_reg) ||
      read_number(m, instance, "stop_stiffness", &p->stop_stiffness) ||
      (p->law_table && read_table(m, instance, p))) {
    free_data(p);
    return -1;
  }
  if (p->v_reg <= 0) {
    mju_warning("finrft.rft: config 'v_reg' must be > 0 m/s");
    free_data(p);
    return -1;
  }
  if (p->stop_stiffness < 0) {
    mju_warning("finrft.rft: config 'stop_stiffness' must be >= 0 N m/rad");
    free_data(p);
    return -1;
  }
  // Segments and hinges on the bodies bound to this instance, counted then collected.
  for (int pass = 0; pass < 2; pass++) {
    int nseg = 0, nhinge = 0;
    for (int s = 0; s < m->nsite; s++) {
      if (m->body_plugin[m->site_bodyid[s]] != instance) continue;
      if (pass) {
        p->site[nseg] = s;
        p->body[nseg] = m->site_bodyid[s];
      }
      nseg++;
    }
    for (int j = 0; j < m->njnt; j++) {
      // the plate's own hinges turn about z; a spatial chain's out-of-plane hinges carry no stop
      if (m->body_plugin[m->jnt_bodyid[j]] != instance || m->jnt_type[j] != mjJNT_HINGE ||
          fabs(m->jnt_axis[3 * j + 2]) < 0.5) continue;
      if (pass) {
        p->hinge_qpos[nhinge] = m->jnt_qposadr[j];
        p->hinge_dof[nhinge] = m->jnt_dofadr[j];
      }
      nhinge++;
    }
    if (!pass) {
      p->nseg = nseg;
      p->nhinge = nhinge;
      p->site = (int*)malloc((nseg + 1) * sizeof(int));
      p->body = (int*)malloc((nseg + 1) * sizeof(int));
      p->hinge_qpos = (int*)malloc((nhinge + 1) * sizeof(int));
      p->hinge_dof = (int*)malloc((nhinge + 1) * sizeof(int));
      if (!p->site || !p->body || !p->hinge_qpos || !p->hinge_dof) {
        free_data(p);
        return -1;
      }
    }
  }
  d->plugin_data[instance] = (uintptr_t)p;
  return 0;
}

static void rft_destroy(mjData* d, int instance) {
  free_data((RFTData*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

static void rft_reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data, int instance) {}

// The force on one segment: v its midpoint velocity, x and y its axis and normal (world frame).
static void segment_force(const RFTData* p, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                          mjtNum force[3]) {
  mjtNum speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  mjtNum safe = speed > 0 ? speed : 1;
  mjtNum ramp = tanh(speed / p->v_reg);
  mjtNum vx = (v[0] * x[0] + v[1] * x[1] + v[2] * x[2]) / safe;
  mjtNum vy = (v[0] * y[0] + v[1] * y[1] + v[2] * y[2]) / safe;
  mjtNum cy, cx;
  if (p->law_table) {
    mjtNum attack = atan2(fabs(vy), fabs(vx));
    cy = interp(attack, p->attack, p->table_perp, p->ntable) * ((vy > 0) - (vy < 0));
    cx = interp(attack, p->attack, p->table_par, p->ntable) * ((vx > 0) - (vx < 0));
  } else {
    cy = p->f_perp * vy;
    cx = p->f_par * vx;
  }
  for (int k = 0; k < 3; k++) force[k] = -ramp * (cy * y[k] + cx * x[k]);
}

// A segment's axis x and normal y (world frame): its site's x and y axes.
static void site_axes(const mjData* d, int s, mjtNum x[3], mjtNum y[3]) {
  const mjtNum* R = d->site_xmat + 9 * s;
  x[0] = R[0]; x[1] = R[3]; x[2] = R[6];
  y[0] = R[1]; y[1] = R[4]; y[2] = R[7];
}

// A segment's midpoint velocity (world frame) and its axis x and normal y: the law's inputs.
static void site_state(const mjModel* m, const mjData* d, int s, mjtNum v[3], mjtNum x[3], mjtNum y[3]) {
  mjtNum twist[6];
  mj_objectVelocity(m, d, mjOBJ_SITE, s, twist, 0);
  v[0] = twist[3]; v[1] = twist[4]; v[2] = twist[5];
  site_axes(d, s, x, y);
}

static void rft_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  if (!(capability_bit & mjPLUGIN_PASSIVE)) return;
  const RFTData* p = (const RFTData*)d->plugin_data[instance];
  if (!p) return;
  mjtNum v[3], x[3], y[3], force[3], torque[3] = {0, 0, 0};
  for (int i = 0; i < p->nseg; i++) {
    int s = p->site[i];
    site_state(m, d, s, v, x, y);
    segment_force(p, v, x, y, force);
    mj_applyFT(m, d, force, torque, d->site_xpos + 3 * s, p->body[i], d->qfrc_passive);
  }
  if (p->stop_stiffness > 0) {
    for (int h = 0; h < p->nhinge; h++) {
      mjtNum q = d->qpos[p->hinge_qpos[h]] - m->qpos_spring[p->hinge_qpos[h]];
      d->qfrc_passive[p->hinge_dof[h]] -= p->stop_stiffness * (q + fabs(q)) * q;
    }
  }
}

// ---------------------------------------------------------------------------------------------------------
// The "implicit" and "newton" methods. MuJoCo's implicitfast step treats the joint damping D (and the velocity
// derivative of affine actuator bias) implicitly; on top of that the RFT force is taken at the new velocity: the
// velocity change dv solves
//     G(dv) = (M - dt D) dv - dt (f(v) - F(v) + F(v + dv)) = 0,
// f every force MuJoCo computed at v, F the RFT force summed over every segment of every finrft.rft instance,
// F(u) = sum_i J_i^T F_i(J_i u). A rate-independent law is a near-discontinuity in velocity, so a linearisation
// at v (the first Newton iterate: the "implicit" method) overshoots on light segments; the "newton" method
// iterates, with a backtracking line search on |G|, to the root, the penalty stops taken at the new positions.
// dF_i/dv comes from central differences of the same law, so both laws need no derivative of their own. Then, as
// MuJoCo's implicitfast: activations, qvel += dv, positions, time.

// dF/dv (3 x 3, row-major) of one segment at velocity v, by central differences.
static void segment_jacobian(const RFTData* p, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                             mjtNum jac[9]) {
  mjtNum h = 1e-6 * (sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) + p->v_reg);
  for (int k = 0; k < 3; k++) {
    mjtNum up[3] = {v[0], v[1], v[2]}, down[3] = {v[0], v[1], v[2]}, fu[3], fd[3];
    up[k] += h;
    down[k] -= h;
    segment_force(p, up, x, y, fu);
    segment_force(p, down, x, y, fd);
    for (int r = 0; r < 3; r++) jac[3 * r + k] = (fu[r] - fd[r]) / (2 * h);
  }
}

// Solve a dense n x n system in place by Gaussian elimination with partial pivoting; 0 on success.
static int solve_dense(mjtNum* a, mjtNum* b, int n) {
  for (int c = 0; c < n; c++) {
    int pivot = c;
    for (int r = c + 1; r < n; r++) if (fabs(a[r * n + c]) > fabs(a[pivot * n + c])) pivot = r;
    if (a[pivot * n + c] == 0) return -1;
    if (pivot != c) {
      for (int k = 0; k < n; k++) {
        mjtNum t = a[c * n + k]; a[c * n + k] = a[pivot * n + k]; a[pivot * n + k] = t;
      }
      mjtNum t = b[c]; b[c] = b[pivot]; b[pivot] = t;
    }
    for (int r = c + 1; r < n; r++) {
      mjtNum f = a[r * n + c] / a[c * n + c];
      if (f == 0) continue;
      for (int k = c; k < n; k++) a[r * n + k] -= f * a[c * n + k];
      b[r] -= f * b[c];
    }
  }
  for (int r = n - 1; r >= 0; r--) {
    for (int k = r + 1; k < n; k++) b[r] -= a[r * n + k] * b[k];
    b[r] /= a[r * n + r];
  }
  return 0;
}

// The forces the implicit methods take at the new velocity: every RFT segment of the model (its law, site
// Jacobian and axes at the current positions) and every penalty stop (its hinge and deflection now).
typedef struct {
  int n, nv, nstop;
  const RFTData** law;  // n
  mjtNum* jacp;         // n x 3 x nv
  mjtNum* axes;         // n x 6: x axis, then normal y
  int* stop_dof;        // nstop
  mjtNum* stop_k;       // nstop, N m/rad
  mjtNum* stop_q;       // nstop, deflection from the rest angle
} Segments;

static int segments_alloc(const mjModel* m, const mjData* d, int slot, Segments* s) {
  s->n = s->nstop = 0;
  s->nv = m->nv;
  for (int inst = 0; inst < m->nplugin; inst++) {
    const RFTData* p = (const RFTData*)d->plugin_data[inst];
    if (m->plugin[inst] != slot || !p) continue;
    s->n += p->nseg;
    if (p->stop_stiffness > 0) s->nstop += p->nhinge;
  }
  s->law = (const RFTData**)malloc((s->n + 1) * sizeof(RFTData*));
  s->jacp = (mjtNum*)malloc((3 * (size_t)s->n * m->nv + 1) * sizeof(mjtNum));
  s->axes = (mjtNum*)malloc((6 * (size_t)s->n + 1) * sizeof(mjtNum));
  s->stop_dof = (int*)malloc((s->nstop + 1) * sizeof(int));
  s->stop_k = (mjtNum*)malloc((s->nstop + 1) * sizeof(mjtNum));
  s->stop_q = (mjtNum*)malloc((s->nstop + 1) * sizeof(mjtNum));
  return s->law && s->jacp && s->axes && s->stop_dof && s->stop_k && s->stop_q ? 0 : -1;
}

static void segments_free(Segments* s) {
  free(s->law);
  free(s->jacp);
  free(s->axes);
  free(s->stop_dof);
  free(s->stop_k);
  free(s->stop_q);
}

// Fill in the Jacobians, axes and deflections at the current positions (after mj_forward).
static void segments_update(const mjModel* m, mjData* d, int slot, Segments* s) {
  int i = 0, h = 0;
  for (int inst = 0; inst < m->nplugin; inst++) {
    const RFTData* p = (const RFTData*)d->plugin_data[inst];
    if (m->plugin[inst] != slot || !p) continue;
    for (int k = 0; k < p->nseg; k++, i++) {
      s->law[i] = p;
      site_axes(d, p->site[k], s->axes + 6 * i, s->axes + 6 * i + 3);
      mj_jacSite(m, d, s->jacp + 3 * (size_t)s->nv * i, NULL, p->site[k]);
    }
    for (int k = 0; p->stop_stiffness > 0 && k < p->nhinge; k++, h++) {
      s->stop_dof[h] = p->hinge_dof[k];
      s->stop_k[h] = p->stop_stiffness;
      s->stop_q[h] = d->qpos[p->hinge_qpos[k]] - m->qpos_spring[p->hinge_qpos[k]];
    }
  }
}

// At generalised velocity u: the RFT force plus the penalty stops' torque at the deflection they reach after
// `ahead` seconds at u (nv), and, when slope is not NULL, its derivative in u (nv x nv).
static void segments_force(const Segments* s, const mjtNum* u, mjtNum ahead, mjtNum* force, mjtNum* slope) {
  int nv = s->nv;
  mju_zero(force, nv);
  if (slope) mju_zero(slope, nv * nv);
  for (int i = 0; i < s->n; i++) {
    const mjtNum* jac = s->jacp + 3 * (size_t)nv * i;
    const mjtNum *x = s->axes + 6 * i, *y = s->axes + 6 * i + 3;
    mjtNum v[3], f[3], c[9], cj[3];
    mju_mulMatVec(v, jac, u, 3, nv);
    segment_force(s->law[i], v, x, y, f);
    for (int col = 0; col < nv; col++) force[col] += jac[col] * f[0] + jac[nv + col] * f[1] + jac[2 * nv + col] * f[2];
    if (!slope) continue;
    segment_jacobian(s->law[i], v, x, y, c);
    for (int col = 0; col < nv; col++) {
      for (int r = 0; r < 3; r++) cj[r] = c[3 * r] * jac[col] + c[3 * r + 1] * jac[nv + col] + c[3 * r + 2] * jac[2 * nv + col];
      for (int row = 0; row < nv; row++) {
        slope[row * nv + col] += jac[row] * cj[0] + jac[nv + row] * cj[1] + jac[2 * nv + row] * cj[2];
      }
    }
  }
  for (int h = 0; h < s->nstop; h++) {
    int dof = s->stop_dof[h];
    mjtNum q = s->stop_q[h] + ahead * u[dof];
    force[dof] -= s->stop_k[h] * (q + fabs(q)) * q;
    if (slope && q > 0) slope[dof * nv + dof] -= 4 * s->stop_k[h] * q * ahead;
  }
}

#define NEWTON_TOLERANCE 1e-10
#define NOT_CONVERGED 3

// Workspace of the Newton solve, all of size nv or nv x nv.
typedef struct {
  mjtNum *matrix, *jacobian, *slope, *other, *force, *dv, *step, *g, *trial, *candidate, *u;
} Newton;

// G(dv) into out: matrix dv - dt (other + F(qvel + dv)), the stops dt ahead; returns |G|.
static mjtNum newton_residual(const Segments* s, Newton* w, const mjtNum* qvel, const mjtNum* dv, mjtNum dt,
                              mjtNum* out) {
  int nv = s->nv;
  for (int i = 0; i < nv; i++) w->u[i] = qvel[i] + dv[i];
  segments_force(s, w->u, dt, w->force, NULL);
  mju_mulMatVec(out, w->matrix, dv, nv, nv);
  for (int i = 0; i < nv; i++) out[i] -= dt * (w->other[i] + w->force[i]);
  return mju_norm(out, nv);
}

// The velocity change of one step into w->dv; rhs = M qacc at v. With iterations == 1 the linearly implicit step
// in the RFT force (the first Newton iterate, no line search, stops as MuJoCo computed them); otherwise the root
// of G, with the stops' torque taken at the new positions too, by Newton's method, or NOT_CONVERGED.
static int newton_solve(const Segments* s, Newton* w, const mjtNum* qvel, const mjtNum* rhs, mjtNum dt,
                        int iterations) {
  int nv = s->nv;
  mjtNum ahead = iterations > 1 ? dt : 0;
  segments_force(s, qvel, ahead, w->force, w->slope);
  // other: every force but F, taken out at the stops' present deflection (w->trial is free until the search)
  if (ahead > 0) segments_force(s, qvel, 0, w->trial, NULL);
  const mjtNum* now = ahead > 0 ? w->trial : w->force;
  for (int i = 0; i < nv; i++) w->other[i] = rhs[i] - now[i];
  for (int i = 0; i < nv; i++) {
    w->dv[i] = 0;
    w->g[i] = -dt * (w->other[i] + w->force[i]);
  }
  mjtNum norm = mju_norm(w->g, nv);
  for (int it = 0; it < iterations; it++) {
    for (int i = 0; i < nv * nv; i++) w->jacobian[i] = w->matrix[i] - dt * w->slope[i];
    for (int i = 0; i < nv; i++) w->step[i] = -w->g[i];
    if (solve_dense(w->jacobian, w->step, nv)) return NOT_CONVERGED;
    if (iterations == 1) {
      mju_copy(w->dv, w->step, nv);
      return 0;
    }
    mjtNum alpha = 1, trial_norm;
    for (;;) {
      for (int i = 0; i < nv; i++) w->candidate[i] = w->dv[i] + alpha * w->step[i];
      trial_norm = newton_residual(s, w, qvel, w->candidate, dt, w->trial);
      if (trial_norm <= (1 - 1e-4 * alpha) * norm || alpha < 1e-6) break;
      alpha /= 2;
    }
    mjtNum change = 0, scale = 0;
    for (int i = 0; i < nv; i++) {
      w->dv[i] += alpha * w->step[i];
      w->g[i] = w->trial[i];
      change = mju_max(change, fabs(alpha * w->step[i]));
      scale = mju_max(scale, fabs(qvel[i] + w->dv[i]));
    }
    norm = trial_norm;
    if (change <= NEWTON_TOLERANCE * (1 + scale)) return 0;
    for (int i = 0; i < nv; i++) w->u[i] = qvel[i] + w->dv[i];
    segments_force(s, w->u, dt, w->force, w->slope);
  }
  return NOT_CONVERGED;
}

#if defined(_WIN32)
#define FINRFT_EXPORT __declspec(dllexport)
#else
#define FINRFT_EXPORT __attribute__((visibility("default")))
#endif

// The MuJoCo header version this library was compiled against, whose ABI it fits, as text that finrft/native.py
// reads from the file: it must know before loading the library whether the installed MuJoCo can load it.
#define FINRFT_TEXT(x) #x
#define FINRFT_VALUE_TEXT(x) FINRFT_TEXT(x)
FINRFT_EXPORT const char finrft_mujoco_header[] = "finrft_mujoco_header=" FINRFT_VALUE_TEXT(mjVERSION_HEADER);

// Where Newton's method finds no root (forces that feed energy in, such as f_par < 0, can leave the implicit
// equation without one near v), the newton method halves the step, down to dt / 2^NEWTON_HALVINGS.
#define NEWTON_HALVINGS 10

typedef struct {
  int slot;
  Segments segments;
  Newton w;
  mjtNum* rhs;
  int64_t* counts;  // NULL, or where to add the steps taken and rejected (halved by the newton method)
} Workspace;

// One implicit step of size dt; 0, 1 when the state stopped being finite, or NOT_CONVERGED.
static int implicit_step(const mjModel* m, mjData* d, mjtNum dt, int iterations, Workspace* ws, int halvings) {
  int nv = m->nv;
  Newton* w = &ws->w;
  mj_forward(m, d);
  mj_mulM(m, d, ws->rhs, d->qacc);
  mj_fullM(m, d, w->matrix);
  for (int i = 0; i < nv; i++) w->matrix[i * nv + i] += dt * m->dof_damping[i];
  for (int a = 0; a < m->nu; a++) {
    if (m->actuator_trntype[a] != mjTRN_JOINT || m->actuator_biastype[a] != mjBIAS_AFFINE) continue;
    int dof = m->jnt_dofadr[m->actuator_trnid[2 * a]];
    mjtNum gear = m->actuator_gear[6 * a];
    w->matrix[dof * nv + dof] -= dt * gear * gear * m->actuator_biasprm[mjNBIAS * a + 2];
  }
  segments_update(m, d, ws->slot, &ws->segments);
  if (newton_solve(&ws->segments, w, d->qvel, ws->rhs, dt, iterations)) {
    if (iterations == 1 || halvings == NEWTON_HALVINGS) return NOT_CONVERGED;
    if (ws->counts) ws->counts[1]++;
    int failed = implicit_step(m, d, dt / 2, iterations, ws, halvings + 1);
    return failed ? failed : implicit_step(m, d, dt / 2, iterations, ws, halvings + 1);
  }
  for (int a = 0; a < m->nu; a++) {
    int adr = m->actuator_actadr[a];
    if (adr < 0) continue;
    for (int j = adr; j < adr + m->actuator_actnum[a]; j++) {
      d->act[j] += dt * d->act_dot[j];
      if (m->actuator_actlimited[a]) {
        d->act[j] = mju_clip(d->act[j], m->actuator_actrange[2 * a], m->actuator_actrange[2 * a + 1]);
      }
    }
  }
  int failed = 0;
  for (int i = 0; i < nv; i++) {
    d->qvel[i] += w->dv[i];
    if (!isfinite(d->qvel[i])) failed = 1;
  }
  if (ws->counts) ws->counts[0]++;
  mju_copy(d->qacc_warmstart, d->qacc, nv);
  mj_integratePos(m, d->qpos, d->qvel, dt);
  d->time += dt;
  return failed;
}

// nstep implicit steps of size dt; returns 0, 1 when the state stopped being finite, or NOT_CONVERGED.
// counts (or NULL): the steps taken and rejected are added to counts[0] and counts[1].
static int implicit_steps(const mjModel* m, mjData* d, int nstep, mjtNum dt, int iterations, int64_t* counts) {
  int nv = m->nv;
  Workspace ws;
  ws.slot = -1;
  ws.counts = counts;
  mjp_getPlugin("finrft.rft", &ws.slot);
  mjtNum* block = (mjtNum*)malloc((3 * (size_t)nv * nv + 9 * (size_t)nv) * sizeof(mjtNum));
  int failed = (segments_alloc(m, d, ws.slot, &ws.segments) || !block) ? 1 : 0;
  if (block) {
    mjtNum* next = block;
    mjtNum** squares[] = {&ws.w.matrix, &ws.w.jacobian, &ws.w.slope};
    mjtNum** vectors[] = {&ws.w.other, &ws.w.force, &ws.w.dv, &ws.w.step, &ws.w.g, &ws.w.trial, &ws.w.candidate,
                          &ws.w.u, &ws.rhs};
    for (int i = 0; i < 3; i++, next += nv * nv) *squares[i] = next;
    for (int i = 0; i < 9; i++, next += nv) *vectors[i] = next;
  }
  for (int step = 0; step < nstep && !failed; step++) failed = implicit_step(m, d, dt, iterations, &ws, 0);
  segments_free(&ws.segments);
  free(block);
  return failed;
}

// The implicit (iterations == 1) and newton methods: nstep steps of the model's time step. counts (or NULL):
// the steps taken (a halved step counts as two) and rejected (halved) are added to counts[0] and counts[1].
FINRFT_EXPORT int finrft_implicit_step(const mjModel* m, mjData* d, int nstep, int iterations, int64_t* counts) {
  return implicit_steps(m, d, nstep, m->opt.timestep, iterations, counts);
}

// The adaptive method: implicit steps over `duration` seconds, each accepted when one step of h and two of h/2
// agree to `tol` (max over qpos, qvel of |difference| / (1e-3 + |value|)). The accepted positions and velocities
// are extrapolated, 2 (two halves) - (one step), which cancels the first-order error of the implicit step. The
// step grows or shrinks by 0.9 sqrt(tol / error) (within 0.2x..2x), never above hmax; *h carries it over calls.
// counts (or NULL): the steps accepted and rejected are added to counts[0] and counts[1].
// Returns 0, 1 when the state stops being finite, 2 when the step falls below 1e-9 s, or NOT_CONVERGED.
FINRFT_EXPORT int finrft_adaptive_advance(const mjModel* m, mjData* d, mjtNum duration, mjtNum hmax, mjtNum tol,
                                          mjtNum* h, int64_t* counts) {
  const int spec = mjSTATE_INTEGRATION;
  int size = mj_stateSize(m, spec);
  mjtNum* start = (mjtNum*)malloc(size * sizeof(mjtNum));
  mjtNum* full = (mjtNum*)malloc(size * sizeof(mjtNum));
  mjtNum* halves = (mjtNum*)malloc(size * sizeof(mjtNum));
  int failed = (!start || !full || !halves) ? 1 : 0;
  mjtNum end = d->time + duration;
  // the slice of the integration state holding qpos and qvel (after time)
  int first = 1, count = m->nq + m->nv;
  while (!failed && d->time < end - 1e-12) {
    mjtNum step = mju_min(mju_min(*h, hmax), end - d->time);
    mj_getState(m, d, start, spec);
    failed = implicit_steps(m, d, 1, step, 1, NULL);
    mj_getState(m, d, full, spec);
    mj_setState(m, d, start, spec);
    failed = failed ? failed : implicit_steps(m, d, 2, step / 2, 1, NULL);
    mj_getState(m, d, halves, spec);
    mjtNum error = 0;
    for (int i = first; i < first + count; i++) {
      error = mju_max(error, fabs(full[i] - halves[i]) / (1e-3 + fabs(halves[i])));
    }
    if (failed || !isfinite(error)) {
      failed = failed ? failed : 1;
    } else if (error <= tol) {
      for (int i = first; i < first + count; i++) halves[i] += halves[i] - full[i];
      mj_setState(m, d, halves, spec);
      *h = mju_min(hmax, step * mju_min(2.0, 0.9 * sqrt(tol / mju_max(error, 1e-300))));
      if (counts) counts[0]++;
    } else {
      mj_setState(m, d, start, spec);
      *h = step * mju_max(0.2, 0.9 * sqrt(tol / error));
      if (counts) counts[1]++;
      if (*h < 1e-9) failed = 2;
    }
  }
  free(start);
  free(full);
  free(halves);
  return failed;
}

void finrft_register_surface(void);  // plugins/finrft_li2013.c

mjPLUGIN_LIB_INIT(finrft_rft) {
  finrft_register_surface();
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = "finrft.rft";
  plugin.capabilityflags |= mjPLUGIN_PASSIVE;
  plugin.nattribute = sizeof(kAttributes) / sizeof(kAttributes[0]);
  plugin.attributes = kAttributes;
  plugin.nstate = rft_nstate;
  plugin.init = rft_init;
  plugin.destroy = rft_destroy;
  plugin.reset = rft_reset;
  plugin.compute = rft_compute;
  mjp_registerPlugin(&plugin);
}
