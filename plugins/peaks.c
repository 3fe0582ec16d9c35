// A prescribed drive's peak load kept over every step by the steppers themselves (the twin of
// finrft.integrate.LoadPeak): a Python call after each step cost the paper plate's drag half its time.
//   finrft_explicit_peak   MuJoCo's own step
//   finrft_implicit_peak   the implicit, newton and newton-midpoint methods (finrft_implicit_step)
//   finrft_adaptive_peak   the adaptive methods (finrft_adaptive_advance), at given instants
// The load at a state is armature * max |qacc| over the drive's dofs, qacc that of MuJoCo's forward pass there.
// `peak` holds the stroke's record (LoadPeak's slots): the largest load, its change to the neighbouring loads, the
// last load taken (NaN: none yet in the stroke), 1 when that one set the peak, and 1 when the current state's load
// is still to be taken.
// The fixed-step ones also keep a trace for the chatter probe (finrft.stepping.ChatterProbe): the velocities of the
// `nwatch` dofs `watch` after each step i of the call in trace[i * nwatch ...] (none where nwatch is 0), so that a
// run steps from one recorded sample to the next in one call, probes and all.

#include <math.h>
#include <stdint.h>

#include <mujoco/mujoco.h>

#include "finrft.h"

enum { PEAK, CHANGE, LAST, AFTER_PEAK, PENDING };

// Take the load of the state whose forward pass left `qacc`. A peak at the stroke's first state is at its instant
// exactly: nothing earlier in the stroke to miss, and the load falling after it (a light plate relaxing to the new
// velocity in microseconds) is no error.
static void trace_take(const mjData* d, int step, int nwatch, const int* watch, mjtNum* trace) {
  for (int j = 0; j < nwatch; j++) trace[step * nwatch + j] = d->qvel[watch[j]];
}

static void peak_take(int ndof, const int* dofs, mjtNum armature, const mjtNum* qacc, mjtNum* peak) {
  mjtNum load = 0;
  for (int i = 0; i < ndof; i++) load = mju_max(load, fabs(qacc[dofs[i]]));
  load *= armature;
  if (peak[AFTER_PEAK] != 0) peak[CHANGE] = mju_max(peak[CHANGE], fabs(peak[PEAK] - load));
  int higher = load > peak[PEAK];
  if (higher) {
    peak[PEAK] = load;
    peak[CHANGE] = isnan(peak[LAST]) ? 0 : fabs(load - peak[LAST]);
  }
  peak[AFTER_PEAK] = higher && !isnan(peak[LAST]);
  peak[LAST] = load;
  peak[PENDING] = 0;
}

// nstep of MuJoCo's steps. Each step's forward pass is the state's it starts from (the euler and implicit
// integrators keep its qacc), so that state's load costs nothing more; the last state's is left pending, taken by
// the next call's first step (or by LoadPeak.flush). Runge-Kutta's qacc is its last stage's: a forward pass after
// each step instead.
FINRFT_EXPORT int finrft_explicit_peak(const mjModel* m, mjData* d, int nstep, int ndof, const int* dofs,
                                       mjtNum armature, mjtNum* peak, int nwatch, const int* watch, mjtNum* trace) {
  for (int i = 0; i < nstep; i++) {
    mj_step(m, d);
    trace_take(d, i, nwatch, watch, trace);
    if (m->opt.integrator == mjINT_RK4) {
      mj_forward(m, d);
      peak_take(ndof, dofs, armature, d->qacc, peak);
      continue;
    }
    if (peak[PENDING] != 0) peak_take(ndof, dofs, armature, d->qacc, peak);
    peak[PENDING] = 1;
  }
  return 0;
}

// finrft_implicit_step's steps, one at a time, the load taken after each (its forward pass leaves the medium's
// force out: a full one is needed).
FINRFT_EXPORT int finrft_implicit_peak(const mjModel* m, mjData* d, int nstep, int iterations, mjtNum midpoint,
                                       int64_t* counts, mjtNum* history, int ndof, const int* dofs,
                                       mjtNum armature, mjtNum* peak, int nwatch, const int* watch, mjtNum* trace) {
  for (int i = 0; i < nstep; i++) {
    int failed = finrft_implicit_step(m, d, 1, iterations, midpoint, counts, history);
    if (failed) return failed;
    trace_take(d, i, nwatch, watch, trace);
    mj_forward(m, d);
    peak_take(ndof, dofs, armature, d->qacc, peak);
  }
  return 0;
}

// finrft_adaptive_advance to each instant at[0] < at[1] < ... < at[n - 1] in turn, the load taken at each.
FINRFT_EXPORT int finrft_adaptive_peak(const mjModel* m, mjData* d, int n, const mjtNum* at, mjtNum hmax,
                                       mjtNum tol, int iterations, mjtNum* h, int64_t* counts, int ndof,
                                       const int* dofs, mjtNum armature, mjtNum* peak) {
  for (int j = 0; j < n; j++) {
    int failed = finrft_adaptive_advance(m, d, at[j] - d->time, hmax, tol, iterations, h, counts);
    if (failed) return failed;
    mj_forward(m, d);
    peak_take(ndof, dofs, armature, d->qacc, peak);
  }
  return 0;
}
