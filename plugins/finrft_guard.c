// finrft.guard: a MuJoCo engine plugin (passive force) that stops a step taken without the Python backend's forces.
//
// finrft.attach(..., backend="python") computes the medium's force in a passive-force callback that
// Attached.installed sets for a block; a model stepped outside that block would get no force at all, silently.
// attach therefore gives such a model one instance of this plugin. MuJoCo calls mjcb_passive before the plugins'
// passive compute in the same mj_passive, so the Python callback stamps the instance's one state value (STAMPED)
// and this compute checks it: a passive-force evaluation whose callback did not run ends in mju_error, which
// MuJoCo's Python bindings raise as an exception. It adds no force.
//
// MuJoCo's compiler steps every model it compiles once, on an mjData of its own, where no callback can be
// installed (finrft.callbacks.compiling): the first evaluation of an mjData (after it is made or reset) passes
// unstamped, so a model stepped without its callback stops at its second evaluation (its second step).

#include <mujoco/mujoco.h>

enum { FRESH = 0, STAMPED = 1, CHECKED = 2 };

static int guard_nstate(const mjModel* m, int instance) { return 1; }

static int guard_init(const mjModel* m, mjData* d, int instance) {
  d->plugin_data[instance] = 0;
  return 0;
}

static void guard_reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data, int instance) {
  plugin_state[m->plugin_stateadr[instance]] = FRESH;
}

static void guard_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  if (!(capability_bit & mjPLUGIN_PASSIVE)) return;
  mjtNum* state = d->plugin_state + m->plugin_stateadr[instance];
  if (*state == CHECKED) {
    mju_error("finrft: this model's RFT is computed in Python (attach(..., backend='python')) and its callback is "
              "not installed: step inside `with attached.installed(model):`");
  }
  *state = CHECKED;
}

void finrft_register_guard(void) {
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = "finrft.guard";
  plugin.capabilityflags |= mjPLUGIN_PASSIVE;
  plugin.nstate = guard_nstate;
  plugin.init = guard_init;
  plugin.reset = guard_reset;
  plugin.compute = guard_compute;
  mjp_registerPlugin(&plugin);
}
