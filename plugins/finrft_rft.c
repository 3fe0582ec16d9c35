// finrft.rft: a MuJoCo engine plugin (passive force) applying granular resistive force theory to plate segments.
//
// The C twin of finrft/rft.py and of the Python coupling in finrft/coupling.py: same laws, same formulas.
// Every site on a body bound to an instance is a segment midpoint: its x axis runs along the segment and its
// y axis is the segment's in-plane normal. Every hinge on a bound body gets the penalty stop when
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
      if (m->body_plugin[m->jnt_bodyid[j]] != instance || m->jnt_type[j] != mjJNT_HINGE) continue;
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

static void rft_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  if (!(capability_bit & mjPLUGIN_PASSIVE)) return;
  const RFTData* p = (const RFTData*)d->plugin_data[instance];
  if (!p) return;
  mjtNum twist[6], x[3], y[3], force[3], torque[3] = {0, 0, 0};
  for (int i = 0; i < p->nseg; i++) {
    int s = p->site[i];
    const mjtNum* R = d->site_xmat + 9 * s;
    mj_objectVelocity(m, d, mjOBJ_SITE, s, twist, 0);
    x[0] = R[0]; x[1] = R[3]; x[2] = R[6];
    y[0] = R[1]; y[1] = R[4]; y[2] = R[7];
    segment_force(p, twist + 3, x, y, force);
    mj_applyFT(m, d, force, torque, d->site_xpos + 3 * s, p->body[i], d->qfrc_passive);
  }
  if (p->stop_stiffness > 0) {
    for (int h = 0; h < p->nhinge; h++) {
      mjtNum q = d->qpos[p->hinge_qpos[h]] - m->qpos_spring[p->hinge_qpos[h]];
      d->qfrc_passive[p->hinge_dof[h]] -= p->stop_stiffness * (q + fabs(q)) * q;
    }
  }
}

mjPLUGIN_LIB_INIT(finrft_rft) {
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
