// finrft.rft: a MuJoCo engine plugin (passive force) applying granular resistive force theory to plate segments.
//
// The C twin of the Python coupling in finrft/coupling.py. Every site on a body bound to an instance is a segment
// midpoint: its x axis runs along the segment and its y axis is the segment's in-plane normal. Every hinge about z
// on a bound body gets the penalty stop when stop_stiffness > 0, acting on its deflection from the spring's rest
// angle (qpos_spring).
//
// Config (all values are strings in MJCF; every key is required):
//   law            the name of a law in plugins/laws/ (the twin of finrft/laws/NAME.py)
//   v_reg          > 0, m/s: the force fades out below this speed as tanh(|v| / v_reg)
//   ...            the law's own keys (paper: f_perp, f_par; table: table)
//   stop_stiffness >= 0, N m/rad: penalty stop torque -k_stop (q + |q|) q on each hinge deflection q
//
// No static state but the law and key tables made when the library loads: everything else lives in the
// per-mjData instance, so instances and threads never share memory.

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#include "finrft.h"

#define X(name) extern const FinrftLaw finrft_law_##name;
FINRFT_LAWS
#undef X

static const FinrftLaw* const kLaws[] = {
#define X(name) &finrft_law_##name,
    FINRFT_LAWS
#undef X
};
#define NLAWS ((int)(sizeof(kLaws) / sizeof(kLaws[0])))

// "law", "v_reg", "stop_stiffness" and every law's own keys, once each: filled when the library loads.
#define MAX_ATTRIBUTES 64
static const char* attributes[MAX_ATTRIBUTES];
static int nattribute;

// The MuJoCo header version this library was compiled against, whose ABI it fits, as text that finrft/native.py
// reads from the file: it must know before loading the library whether the installed MuJoCo can load it.
#define FINRFT_TEXT(x) #x
#define FINRFT_VALUE_TEXT(x) FINRFT_TEXT(x)
FINRFT_EXPORT const char finrft_mujoco_header[] = "finrft_mujoco_header=" FINRFT_VALUE_TEXT(mjVERSION_HEADER);

// MuJoCo's timer callback, swapped for `timer`; the one it had is returned. MuJoCo's Python bindings install a
// clock that every step calls about twenty times, a third of a small model's step: finrft.native.untimed clears it
// while finrft steps, and puts it back.
FINRFT_EXPORT mjfTime finrft_swap_timer(mjfTime timer) {
  mjfTime previous = mjcb_time;
  mjcb_time = timer;
  return previous;
}

int finrft_read_number(const mjModel* m, int instance, const char* key, mjtNum* out) {
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

static void free_instance(FinrftInstance* p) {
  if (!p) return;
  if (p->params) p->law->destroy(p->params);
  free(p->site);
  free(p->body);
  free(p->last_dof);
  free(p->hinge_qpos);
  free(p->hinge_dof);
  free(p);
}

static const FinrftLaw* find_law(const char* name) {
  for (int i = 0; name && i < NLAWS; i++) {
    if (!strcmp(name, kLaws[i]->name)) return kLaws[i];
  }
  return NULL;
}

static int rft_nstate(const mjModel* m, int instance) {
  return 0;
}

static int rft_init(const mjModel* m, mjData* d, int instance) {
  FinrftInstance* p = (FinrftInstance*)calloc(1, sizeof(FinrftInstance));
  if (!p) return -1;
  const char* law = mj_getPluginConfig(m, instance, "law");
  p->law = find_law(law);
  if (!p->law) {
    char names[256] = "";
    for (int i = 0; i < NLAWS; i++) {
      strncat(names, i ? ", " : "", sizeof(names) - strlen(names) - 1);
      strncat(names, kLaws[i]->name, sizeof(names) - strlen(names) - 1);
    }
    mju_warning("finrft.rft: config 'law' must be one of %s, got '%s'", names, law ? law : "");
    free_instance(p);
    return -1;
  }
  if (finrft_read_number(m, instance, "v_reg", &p->v_reg) ||
      finrft_read_number(m, instance, "stop_stiffness", &p->stop_stiffness) ||
      !(p->params = p->law->create(m, instance))) {
    free_instance(p);
    return -1;
  }
  if (p->v_reg <= 0) {
    mju_warning("finrft.rft: config 'v_reg' must be > 0 m/s");
    free_instance(p);
    return -1;
  }
  if (p->stop_stiffness < 0) {
    mju_warning("finrft.rft: config 'stop_stiffness' must be >= 0 N m/rad");
    free_instance(p);
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
        // the last dof of the nearest body up the tree that has dofs: the end of the segment's dof chain
        int b = m->site_bodyid[s];
        while (b > 0 && !m->body_dofnum[b]) b = m->body_parentid[b];
        p->last_dof[nseg] = b > 0 ? m->body_dofadr[b] + m->body_dofnum[b] - 1 : -1;
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
      p->last_dof = (int*)malloc((nseg + 1) * sizeof(int));
      p->hinge_qpos = (int*)malloc((nhinge + 1) * sizeof(int));
      p->hinge_dof = (int*)malloc((nhinge + 1) * sizeof(int));
      if (!p->site || !p->body || !p->last_dof || !p->hinge_qpos || !p->hinge_dof) {
        free_instance(p);
        return -1;
      }
    }
  }
  p->model = m;
  d->plugin_data[instance] = (uintptr_t)p;
  return 0;
}

static void rft_destroy(mjData* d, int instance) {
  free_instance((FinrftInstance*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

const FinrftInstance* finrft_instance(const mjModel* m, mjData* d, int instance) {
  const FinrftInstance* p = (const FinrftInstance*)d->plugin_data[instance];
  if (p && p->model == m) return p;
  rft_destroy(d, instance);
  // The config was checked when the model compiled: this fails only when memory runs out.
  if (rft_init(m, d, instance)) {
    finrft_poison(m, d);
    return NULL;
  }
  return (const FinrftInstance*)d->plugin_data[instance];
}

static void rft_reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data, int instance) {}

// A segment's force enters straight through the com-based motion MuJoCo has already computed: its midpoint's
// velocity is the body's cvel shifted to the midpoint, and each dof j up the body's chain takes the generalized
// force cdof_j . (offset x F, F), which is J^T F without forming the Jacobian (mj_objectVelocity and mj_applyFT
// cost a spatial transform and a full 3 x nv Jacobian per segment).
static void rft_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  if (!(capability_bit & mjPLUGIN_PASSIVE)) return;
  const FinrftInstance* p = finrft_instance(m, d, instance);
  if (!p || p->paused) return;
  mjtNum offset[3], v[3], x[3], y[3], force[3], moment[3];
  for (int i = 0; i < p->nseg; i++) {
    int s = p->site[i], b = p->body[i];
    const mjtNum* com = d->subtree_com + 3 * m->body_rootid[b];
    const mjtNum* cvel = d->cvel + 6 * b;
    const mjtNum* xpos = d->site_xpos + 3 * s;
    for (int k = 0; k < 3; k++) offset[k] = xpos[k] - com[k];
    finrft_cross(v, cvel, offset);
    for (int k = 0; k < 3; k++) v[k] += cvel[3 + k];
    finrft_site_axes(d, s, x, y);
    p->law->force(p->params, p->v_reg, v, x, y, force);
    finrft_cross(moment, offset, force);
    for (int j = p->last_dof[i]; j >= 0; j = m->dof_parentid[j]) {
      const mjtNum* cdof = d->cdof + 6 * j;
      d->qfrc_passive[j] += finrft_dot3(cdof, moment) + finrft_dot3(cdof + 3, force);
    }
  }
  if (p->stop_stiffness > 0) {
    for (int h = 0; h < p->nhinge; h++) {
      mjtNum q = d->qpos[p->hinge_qpos[h]] - m->qpos_spring[p->hinge_qpos[h]];
      d->qfrc_passive[p->hinge_dof[h]] += finrft_stop_torque(q, p->stop_stiffness, NULL);
    }
  }
}

static void add_attribute(const char* key) {
  for (int i = 0; i < nattribute; i++) {
    if (!strcmp(attributes[i], key)) return;
  }
  if (nattribute < MAX_ATTRIBUTES) attributes[nattribute++] = key;
}

void finrft_register_surface(void);  // plugins/finrft_surface.c
void finrft_register_guard(void);    // plugins/finrft_guard.c

mjPLUGIN_LIB_INIT(finrft_rft) {
  finrft_register_surface();
  finrft_register_guard();
  add_attribute("law");
  add_attribute("v_reg");
  add_attribute("stop_stiffness");
  for (int i = 0; i < NLAWS; i++) {
    for (int k = 0; k < kLaws[i]->nkeys; k++) add_attribute(kLaws[i]->keys[k]);
  }
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = FINRFT_PLUGIN;
  plugin.capabilityflags |= mjPLUGIN_PASSIVE;
  plugin.nattribute = nattribute;
  plugin.attributes = attributes;
  plugin.nstate = rft_nstate;
  plugin.init = rft_init;
  plugin.destroy = rft_destroy;
  plugin.reset = rft_reset;
  plugin.compute = rft_compute;
  mjp_registerPlugin(&plugin);
}
