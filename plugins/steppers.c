// The time-stepping methods of finrft (the twins of finrft/integrate.py), called through ctypes:
//   finrft_implicit_step     the "implicit", "newton" and "newton-midpoint" methods
//   finrft_adaptive_advance  the "adaptive" and "adaptive-newton" methods
//   finrft_explicit_record   MuJoCo's own step, recording the state at given steps (finrft.batch)
//   finrft_explicit_from     MuJoCo's own step, each from one of given states (what one costs there: bench steps)
// They return 0 or a code of finrft.native.Code (FINRFT_UNSTABLE, ...). A step allocates nothing on the heap: its
// workspace lives on the mjData stack (mj_markStack ... mj_freeStack), sized once per call.
//
// The implicit and newton methods. MuJoCo's implicitfast step treats the joint damping D (and the velocity
// derivative of affine actuator bias) implicitly; on top of that the RFT force is taken at the new velocity: the
// velocity change dv solves
//     G(dv) = (M - dt D) dv - dt (f(v) + F(v + dv)) = 0,
// f every other force MuJoCo computes at v (the finrft plugins paused, unless a constraint is active: see
// step_prepare; the numpy twin subtracts what its callback applied instead, the same numbers), F the RFT force
// summed over every segment of every finrft.rft instance and
// every body of a finrft.surface instance, F(u) = sum_i J_i^T F_i(J_i u) + sum_b J_b^T W_b(J_b u), J_b the Jacobian
// of body b's origin (angular rows, then linear) and W_b its wrench (finrft_surface_wrench) at that twist. A
// rate-independent law is a near-discontinuity in velocity, so a linearisation at v (the first Newton iterate: the
// "implicit" method) overshoots on light segments and bodies; the "newton" method
// iterates, with a backtracking line search on |G|, to the root, the penalty stops taken at the new positions.
// dF_i/dv comes from central differences of the same law (forward ones in Newton's method, whose root does not
// depend on it), so no segment law needs a derivative of its own. dW_b/dtwist is assembled from its elements:
// element e at arm a_e moves at v_e = A_e t, A_e = [-[a_e]x | I], and W_b = sum_e A_e^T F_e(v_e), so dW_b/dtwist =
// sum_e A_e^T (dF_e/dv_e) A_e over the elements below the surface (taken once per step) that lead the motion, each
// 3 x 3 dF_e/dv_e the law's own analytic one where it has one (li2013, rft3d: finrft_surface_element_slope, one
// call), else differenced from the element's law alone (across v_e only where it leads: leading_slope), also for
// the elements that lead only at a probe. Then, as
// MuJoCo's implicitfast: activations, qvel += dv, positions, time. The newton-midpoint method takes the
// Jacobians and elements at the positions half a step ahead at v (F there, f at the start): see integrate.py for
// when that is second order and when it damps.

#include <math.h>
#include <stdint.h>

#include <mujoco/mujoco.h>

#include "finrft.h"

#define NEWTON_TOLERANCE 1e-10
// Where Newton's method finds no root (forces that feed energy in, such as f_par < 0, can leave the implicit
// equation without one near v), the newton method halves the step, down to dt / 2^NEWTON_HALVINGS.
#define NEWTON_HALVINGS 10
// The adaptive newton method stops Newton's method at NEWTON_SHARE of the step's tolerance.
#define NEWTON_SHARE 1e-2
// Newton's method takes an iterate as the root only where its residual, besides its change, is small: at most this
// share of dt times the largest force of the step (`residual_small`). A change below the velocity tolerance alone
// took a box 1e10 m deep at rest with no force: its root lies below RAMP_FLOOR v_reg, where the law gives none.
#define NEWTON_RESIDUAL 1e-3
// Spans of time (s) shorter than this are the rounding of d->time, which the sum of the steps leaves a few of its last
// bits off `end`: the adaptive steps stop this short of `end`, and a step this close to the step size was not cut
// short to land on `end`. Where the `end`s (the samples) are a whole number of largest steps apart, a stretch at the
// largest step ends on each at the step size give or take those bits: decided by their sign, the twins, whose times
// round apart, carried over different step sizes and took different steps (up to 6e-4 rad apart on the light plate
// closing onto a limit stop).
#define TIME_ROUNDING 1e-12
// The speed (m/s) on whose scale an element's force is differenced besides its own: the surface laws are
// rate-independent, so any step small against the element's speed would do but for an element at rest.
#define SURFACE_SPEED 1e-3
// Newton's method on attached surfaces alone keeps its slope while each full step cuts the residual at least this
// much (see newton_solve).
#define SURFACE_DECREASE 0.1
// A newton step on attached surfaces alone, following a step of the same call (or of the same stepper's last call
// that ended where it starts), starts from the velocity change that step made, scaled to the step: the predicted
// change, which misses the root by about the change of the velocity change from step to step, twice backward
// Euler's local error in the velocity. Newton's method then stops once its change is below this share of that
// miss (or below the fixed tolerance), 1e-5 of what the step's own error is: at 1e-3 the solver's own error,
// different in a run and its companion at half the step, doubled the paddle sled's estimated cost of transport
// (0.0119 -> 0.0230, 5.2 times its actual error, beyond the 2 % its scene asks for).
#define PREDICTOR_SHARE 1e-5

// The forces the implicit methods take at the new velocity, as items: every RFT segment of the model (its instance,
// site Jacobian and axes at the current positions), every body with attached surfaces (its finrft.surface instance
// and the Jacobian of its origin, angular rows then linear: its twist) and every penalty stop (its hinge and
// deflection now). Item i < n is segment i (3 rows); item n + j is body j (6 rows).
typedef struct {
  int ninst, n, nbody, nv, nstop;
  const FinrftInstance** inst;  // ninst
  const FinrftInstance** law;   // n: each segment's instance
  const FinrftSurface** surface;  // nbody: each body's instance
  mjtNum* jac;                  // per item, rows x nv: 3 per segment, then 6 per body
  mjtNum* axes;                 // n x 6: x axis, then normal y
  int* first;                   // nbody + 1: body j's submerged elements are first[j] .. first[j + 1] - 1
  mjtNum* element;              // the bodies' elements below the surface at the step's start (FINRFT_SUBMERGED
                                // numbers each: arm, normal, depth, area; world frame)
  mjtNum* element_force;        // 3 per submerged element: its force at the last rft_force
  int* ncol;                    // n + nbody: how many dofs move the item (its body's chain)
  int* col;                     // (n + nbody) x nv: those dofs, ascending; the Jacobian's other columns are zero
  int* moves;                   // n: bit k set when the segment's velocity has a component k (a planar chain's
                                // segments have no z row): dF/dv needs no difference along the others
  mjtNum* vel;                  // per item its velocity at the last rft_force (3 per segment, then a body's twist,
                                // 6), world frame
  mjtNum* out;                  // per item the law's force (segment) or wrench (body: torque, force) there
  int* stop_dof;                // nstop
  mjtNum* stop_k;               // nstop, N m/rad
  mjtNum* stop_q;               // nstop, deflection from the rest angle
} Items;

// Item i's rows (3 for a segment, 6 for a body) and the offsets of its Jacobian and of its velocity.
static int item_rows(const Items* s, int i) {
  return i < s->n ? 3 : 6;
}

static size_t item_offset(const Items* s, int i) {
  return i < s->n ? 3 * (size_t)i : 3 * (size_t)s->n + 6 * (size_t)(i - s->n);
}

// Workspace of the Newton solve, all of size nv or nv x nv.
typedef struct {
  mjtNum *matrix, *jacobian, *slope, *other, *force, *dv, *step, *g, *trial, *candidate, *u;
} Newton;

typedef struct {
  Items items;
  Newton w;
  mjtNum* rhs;
  mjtNum* mass;     // nv x nv, the mass matrix at the step's start
  // The RFT force (nv) and its slope (nv x nv) at the start: a whole step and its first half, from the same
  // start, both begin Newton's method there. start_ready is 0 until computed after each step_prepare.
  mjtNum *start_force, *start_slope;
  int start_ready;
  int64_t* counts;  // NULL, or where to add the steps taken and rejected (halved by the newton method)
  // The positions the items hold: the start's (0), or `midpoint` seconds ahead of it at its velocity (the stops'
  // deflections the start's); then qpos_start (nq) is scratch.
  mjtNum midpoint;
  mjtNum* qpos_start;
  // 1 when rhs holds the RFT force MuJoCo applied at the start, `applied` (nv), the stops' not included (see
  // step_prepare)
  int has_applied;
  mjtNum* applied;
  mjtNum newton_tolerance;  // Newton's method stops when the change is below this times (1 + |qvel|)
  // NULL, or the last step's time after it, its size and its velocity change (nv), which the newton method on
  // attached surfaces alone takes as its next step's start (PREDICTOR_SHARE); guess (nv) holds that start, scaled to
  // the step, and predicted says whether the step at hand has one
  mjtNum* history;
  mjtNum* guess;
  int predicted;
  mjtNum* body_slopes;      // 36 per body: dW/dtwist at the start's velocity, taken with its wrench (rft_force)
} Workspace;

// Item i's dofs (its body's chain, ascending) from `last`, the last dof of the nearest body up the tree that has
// dofs (-1: none): the model's, for every step.
static void item_chain(const mjModel* m, Items* s, int i, int last) {
  int* col = s->col + (size_t)s->nv * i;
  int c = 0;
  for (int dof = last; dof >= 0; dof = m->dof_parentid[dof]) col[c++] = dof;
  for (int a = 0, b = c - 1; a < b; a++, b--) {
    int t = col[a]; col[a] = col[b]; col[b] = t;
  }
  s->ncol[i] = c;
}

// The workspace of a model's steps, and `extra` more numbers (NULL when not wanted), on the mjData stack (after
// mj_markStack); FINRFT_ARENA_FULL, before allocating anything, when the stack cannot hold it beside what
// MuJoCo's own functions have needed of it.
static int workspace_make(const mjModel* m, mjData* d, Workspace* ws, int extra, mjtNum** extra_out) {
  Items* s = &ws->items;
  int nv = m->nv;
  s->ninst = s->n = s->nbody = s->nstop = 0;
  s->nv = nv;
  int nelement = 0;
  int slot = -1, surface_slot = -1;
  mjp_getPlugin(FINRFT_PLUGIN, &slot);
  mjp_getPlugin(FINRFT_SURFACE_PLUGIN, &surface_slot);
  for (int i = 0; i < m->nplugin; i++) {
    const FinrftSurface* surface = m->plugin[i] == surface_slot ? finrft_surface_instance(m, d, i) : NULL;
    if (surface) {
      s->nbody++;
      nelement += surface->n;
    }
    const FinrftInstance* p = m->plugin[i] == slot ? finrft_instance(m, d, i) : NULL;
    if (!p) continue;
    s->ninst++;
    s->n += p->nseg;
    if (p->stop_stiffness > 0) s->nstop += p->nhinge;
  }
  int items = s->n + s->nbody;
  size_t rows = 3 * (size_t)s->n + 6 * (size_t)s->nbody;
  size_t numbers = rows * nv + 6 * (size_t)s->n + 2 * rows + (FINRFT_SUBMERGED + 3) * (size_t)nelement +
                   2 * (size_t)s->nstop + 5 * (size_t)nv * nv + 15 * (size_t)nv + m->nq + (size_t)s->nstop + extra +
                   36 * (size_t)s->nbody;
  size_t ints = (size_t)items * (nv + 1) + s->n + s->nbody + 1 + s->nstop;
  size_t pointers = s->ninst + s->n + s->nbody;
  size_t bytes = numbers * sizeof(mjtNum) + pointers * sizeof(void*) + ints * sizeof(int) + 1024;
  if (bytes + d->maxuse_stack > d->narena - d->pstack - d->parena) return FINRFT_ARENA_FULL;
  s->inst = (const FinrftInstance**)mj_stackAllocByte(d, (s->ninst + 1) * sizeof(void*), sizeof(void*));
  s->law = (const FinrftInstance**)mj_stackAllocByte(d, (s->n + 1) * sizeof(void*), sizeof(void*));
  s->surface = (const FinrftSurface**)mj_stackAllocByte(d, (s->nbody + 1) * sizeof(void*), sizeof(void*));
  s->jac = mj_stackAllocNum(d, rows * nv + 1);
  s->axes = mj_stackAllocNum(d, 6 * (size_t)s->n + 1);
  s->first = mj_stackAllocInt(d, s->nbody + 1);
  s->element = mj_stackAllocNum(d, FINRFT_SUBMERGED * (size_t)nelement + 1);
  s->element_force = mj_stackAllocNum(d, 3 * (size_t)nelement + 1);
  s->ncol = mj_stackAllocInt(d, items + 1);
  s->col = mj_stackAllocInt(d, (size_t)items * nv + 1);
  s->moves = mj_stackAllocInt(d, s->n + 1);
  s->vel = mj_stackAllocNum(d, rows + 1);
  s->out = mj_stackAllocNum(d, rows + 1);
  s->stop_dof = mj_stackAllocInt(d, s->nstop + 1);
  s->stop_k = mj_stackAllocNum(d, s->nstop + 1);
  s->stop_q = mj_stackAllocNum(d, s->nstop + 1);
  for (int i = 0, k = 0, j = 0; i < m->nplugin; i++) {
    if (m->plugin[i] == surface_slot) {
      const FinrftSurface* p = finrft_surface_instance(m, d, i);
      if (p) s->surface[j++] = p;
    }
    const FinrftInstance* p = m->plugin[i] == slot ? finrft_instance(m, d, i) : NULL;
    if (p) s->inst[k++] = p;
  }
  for (int j = 0, i = 0; j < s->ninst; j++) {
    const FinrftInstance* p = s->inst[j];
    for (int k = 0; k < p->nseg; k++, i++) {
      s->law[i] = p;
      item_chain(m, s, i, p->last_dof[k]);
    }
  }
  for (int j = 0; j < s->nbody; j++) {
    const FinrftSurface* p = s->surface[j];
    int b = p->body;
    while (b > 0 && !m->body_dofnum[b]) b = m->body_parentid[b];
    item_chain(m, s, s->n + j, b > 0 ? m->body_dofadr[b] + m->body_dofnum[b] - 1 : -1);
  }
  Newton* w = &ws->w;
  mjtNum** squares[] = {&w->matrix, &w->jacobian, &w->slope, &ws->mass, &ws->start_slope};
  mjtNum** vectors[] = {&w->other, &w->force, &w->dv,  &w->step,  &w->g,           &w->trial,
                        &w->candidate, &w->u, &ws->rhs, &ws->guess, &ws->start_force};
  for (int i = 0; i < 5; i++) *squares[i] = mj_stackAllocNum(d, (size_t)nv * nv + 1);
  for (int i = 0; i < 11; i++) *vectors[i] = mj_stackAllocNum(d, nv + 1);
  ws->start_ready = 0;
  ws->midpoint = 0;
  ws->applied = mj_stackAllocNum(d, nv + 1);
  ws->has_applied = 0;
  ws->qpos_start = mj_stackAllocNum(d, m->nq + 1);
  ws->body_slopes = mj_stackAllocNum(d, 36 * (size_t)s->nbody + 1);
  if (extra_out) *extra_out = mj_stackAllocNum(d, extra);
  ws->counts = NULL;
  ws->newton_tolerance = NEWTON_TOLERANCE;
  ws->history = NULL;
  ws->predicted = 0;
  return 0;
}

// The stops' deflections at the current positions.
static void stops_update(const mjModel* m, const mjData* d, Items* s) {
  int h = 0;
  for (int j = 0; j < s->ninst; j++) {
    const FinrftInstance* p = s->inst[j];
    for (int k = 0; p->stop_stiffness > 0 && k < p->nhinge; k++, h++) {
      s->stop_dof[h] = p->hinge_dof[k];
      s->stop_k[h] = p->stop_stiffness;
      s->stop_q[h] = d->qpos[p->hinge_qpos[k]] - m->qpos_spring[p->hinge_qpos[k]];
    }
  }
}

// Fill in the segments' and bodies' Jacobians, the axes, moved directions and submerged elements at the current
// positions (after mj_forward).
static void items_update(const mjModel* m, mjData* d, Items* s) {
  int i = 0;
  for (int j = 0; j < s->ninst; j++) {
    const FinrftInstance* p = s->inst[j];
    for (int k = 0; k < p->nseg; k++, i++) {
      finrft_site_axes(d, p->site[k], s->axes + 6 * i, s->axes + 6 * i + 3);
      mjtNum* jac = s->jac + item_offset(s, i) * s->nv;
      mj_jacSite(m, d, jac, NULL, p->site[k]);
      const int* col = s->col + (size_t)s->nv * i;
      s->moves[i] = 0;
      for (int r = 0; r < 3; r++) {
        for (int a = 0; a < s->ncol[i]; a++) {
          if (jac[r * s->nv + col[a]] != 0) s->moves[i] |= 1 << r;
        }
      }
    }
  }
  s->first[0] = 0;
  for (int j = 0; j < s->nbody; j++) {
    mjtNum* jac = s->jac + item_offset(s, s->n + j) * s->nv;  // angular rows, then linear: the twist's order
    mj_jacBody(m, d, jac + 3 * s->nv, jac, s->surface[j]->body);
    s->first[j + 1] = s->first[j] + finrft_surface_submerged(s->surface[j], d,
                                                             s->element + FINRFT_SUBMERGED * (size_t)s->first[j]);
  }
}

// dF/dv (3 x 3, row-major) of one segment at velocity v, by central differences, or, given the force f0 at v,
// forward ones: half the law's calls, for Newton's method, whose root does not depend on the derivative. Only
// along the directions in `moves` (bit k: v_k); the other columns are 0, as the segment's Jacobian has no row
// there to take them.
static void segment_jacobian(const FinrftInstance* p, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                             const mjtNum* f0, int moves, mjtNum jac[9]) {
  mjtNum h = 1e-6 * (sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) + p->v_reg);
  for (int k = 0; k < 3; k++) {
    if (moves >> k & 1) continue;
    for (int r = 0; r < 3; r++) jac[3 * r + k] = 0;
  }
  for (int k = 0; f0 && k < 3; k++) {
    if (!(moves >> k & 1)) continue;
    mjtNum up[3] = {v[0], v[1], v[2]}, fu[3];
    up[k] += h;
    p->law->force(p->params, p->v_reg, up, x, y, fu);
    for (int r = 0; r < 3; r++) jac[3 * r + k] = (fu[r] - f0[r]) / h;
  }
  for (int k = 0; !f0 && k < 3; k++) {
    if (!(moves >> k & 1)) continue;
    mjtNum up[3] = {v[0], v[1], v[2]}, down[3] = {v[0], v[1], v[2]}, fu[3], fd[3];
    up[k] += h;
    down[k] -= h;
    p->law->force(p->params, p->v_reg, up, x, y, fu);
    p->law->force(p->params, p->v_reg, down, x, y, fd);
    for (int r = 0; r < 3; r++) jac[3 * r + k] = (fu[r] - fd[r]) / (2 * h);
  }
}

// An element's velocity at the body's twist t: omega x arm + the origin's velocity.
static void element_velocity(const mjtNum t[6], const mjtNum* element, mjtNum v[3]) {
  finrft_cross(v, t, element);
  for (int r = 0; r < 3; r++) v[r] += t[3 + r];
}

// An element's force at velocity v: 0 without a call of its law when it trails (n . v <= 0, the test every surface
// law and DRFT's term make first, in the same arithmetic), as about half the submerged elements do.
static void element_force(const FinrftSurface* p, const mjtNum* element, const mjtNum v[3], mjtNum f[3]) {
  if (finrft_dot3(element + 3, v) > 0) {
    finrft_surface_element_force(p, element + 3, v, element[6], element[7], f);
  } else {
    f[0] = f[1] = f[2] = 0;
  }
}

// Add A_e^T k A_e to dw (6 x 6, row-major), A_e = [-[arm]x | I] (3 x 6) mapping a twist to the element's velocity,
// k (3 x 3) the element's dF/dv: its share of dW/dtwist. By cross products, as A_e^T = ([arm]x ; I): k A_e's row r
// is (arm x k_r, k_r), k_r the row r of k, and [arm]x takes each column of k A_e to arm x it (a sixth of the
// multiplications of the products with A_e's zeros and ones).
static void add_element_slope(const mjtNum arm_in[3], const mjtNum k[9], mjtNum dw[36]) {
  // the arm in locals: dw may alias it, and its reloads after every sum were a third of the function
  const mjtNum arm[3] = {arm_in[0], arm_in[1], arm_in[2]};
  mjtNum ka[18];
  for (int r = 0; r < 3; r++) {
    finrft_cross(ka + 6 * r, arm, k + 3 * r);
    for (int c = 0; c < 3; c++) ka[6 * r + 3 + c] = k[3 * r + c];
  }
  for (int c = 0; c < 6; c++) {
    mjtNum column[3] = {ka[c], ka[6 + c], ka[12 + c]}, turned[3];
    finrft_cross(turned, arm, column);
    for (int r = 0; r < 3; r++) {
      dw[6 * r + c] += turned[r];
      dw[6 * (3 + r) + c] += column[r];
    }
  }
}

// Body j's wrench (torque about its origin, force) at twist t: the sum over its submerged elements, whose forces
// it keeps for body_slope. Given dw (not NULL) and a law with its own Jacobian, its slope dW/dtwist too (as
// body_slope), each leading element's force and Jacobian from one call (finrft_surface_element_slope): the step's
// start wants both at one velocity, where the force's call and then the slope's took the law twice.
static void body_wrench(const Items* s, int j, const mjtNum t[6], mjtNum w[6], mjtNum* dw) {
  const FinrftSurface* p = s->surface[j];
  int analytic = dw && finrft_surface_has_slope(p);
  mju_zero(w, 6);
  if (analytic) mju_zero(dw, 36);
  for (int e = s->first[j]; e < s->first[j + 1]; e++) {
    const mjtNum* element = s->element + FINRFT_SUBMERGED * (size_t)e;
    mjtNum v[3], moment[3], k[9], *f = s->element_force + 3 * (size_t)e;
    element_velocity(t, element, v);
    if (analytic && finrft_dot3(element + 3, v) > 0) {
      // below the ramp's floor (a third of a rolling wheel's leading elements) both are 0: nothing to add
      if (finrft_surface_element_slope(p, element + 3, v, element[6], element[7], f, k)) {
        add_element_slope(element, k, dw);
      }
    } else {
      element_force(p, element, v, f);
    }
    for (int r = 0; r < 3; r++) w[3 + r] += f[r];
    finrft_cross(moment, element, f);
    for (int r = 0; r < 3; r++) w[r] += moment[r];
  }
}

// Two unit vectors across a nonzero v, p1 = v x e / |v x e| (e the axis along v's smallest component, the first
// of equals) and p2 = v^ x p1, as _across in integrate.py.
static void across(const mjtNum v[3], mjtNum p[2][3]) {
  int axis = 0;
  for (int i = 1; i < 3; i++) if (fabs(v[i]) < fabs(v[axis])) axis = i;
  mjtNum e[3] = {0, 0, 0}, unit[3], size = sqrt(finrft_dot3(v, v));
  e[axis] = 1;
  finrft_cross(p[0], v, e);
  mjtNum norm = sqrt(finrft_dot3(p[0], p[0]));
  for (int i = 0; i < 3; i++) {
    p[0][i] /= norm;
    unit[i] = v[i] / size;
  }
  finrft_cross(p[1], unit, p[0]);
}

// dF/dv (3 x 3, row-major) of an element leading at v (n . v above the ramp's floor), given its force f0 = r L
// there, for forward differences: F = r(n . v) L(v), r the ramp, L the law, which is rate-independent (L(c v) =
// L(v), c > 0: dL/dv v = 0), so dF/dv = r'(n . v) L n^T + r (dL/dv p1 p1^T + dL/dv p2 p2^T), p1, p2 across v: two
// probes of the law where the plain differences take three.
static void leading_slope(const FinrftSurface* p, const mjtNum* element, const mjtNum v[3], const mjtNum f0[3],
                          mjtNum h, mjtNum k[9]) {
  const mjtNum* n = element + 3;
  mjtNum ramp = 1, rate = 0;
  if (p->v_reg > 0) {
    mjtNum ratio = finrft_dot3(n, v) / p->v_reg;
    ramp = ratio < 20 ? tanh(ratio) : 1;
    rate = ratio < 20 ? (1 - ramp * ramp) / p->v_reg : 0;
  }
  mjtNum law[3], cross[2][3], dl[2][3];
  for (int r = 0; r < 3; r++) law[r] = f0[r] / ramp;
  across(v, cross);
  for (int c = 0; c < 2; c++) {
    mjtNum u[3], fu[3];
    for (int r = 0; r < 3; r++) u[r] = v[r] + h * cross[c][r];
    finrft_surface_law_force(p, n, u, element[6], element[7], fu);
    for (int r = 0; r < 3; r++) dl[c][r] = (fu[r] - law[r]) / h;
  }
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) {
      k[3 * r + c] = rate * law[r] * n[c] + ramp * (dl[0][r] * cross[0][c] + dl[1][r] * cross[1][c]);
    }
  }
}

// dF/dv (3 x 3, row-major) of an element at v by differences along each axis in steps h: forward ones from its
// force f0 there when `forward`, else central ones. 0 when it trails at v and at every probe (n . v <= 0: every
// surface law and the ramp are exactly 0 there): its slope is then 0 and no call of its law is made.
static int probed_slope(const FinrftSurface* p, const mjtNum* element, const mjtNum v[3], const mjtNum f0[3],
                        mjtNum h, int forward, mjtNum k[9]) {
  const mjtNum* n = element + 3;
  mjtNum probe[2][3][3];
  int sides = forward ? 1 : 2, leads = finrft_dot3(n, v) > 0;
  for (int side = 0; side < sides; side++) {
    for (int c = 0; c < 3; c++) {
      mjtNum* u = probe[side][c];
      for (int r = 0; r < 3; r++) u[r] = v[r];
      u[c] += side ? -h : h;
      leads |= finrft_dot3(n, u) > 0;
    }
  }
  if (!leads) return 0;
  for (int c = 0; c < 3; c++) {
    mjtNum fu[3], fd[3];
    element_force(p, element, probe[0][c], fu);
    if (forward) {
      for (int r = 0; r < 3; r++) k[3 * r + c] = (fu[r] - f0[r]) / h;
    } else {
      element_force(p, element, probe[1][c], fd);
      for (int r = 0; r < 3; r++) k[3 * r + c] = (fu[r] - fd[r]) / (2 * h);
    }
  }
  return 1;
}

// dW/dtwist (6 x 6, row-major) of body j at twist t, sum_e A_e^T (dF_e/dv_e) A_e: each element's 3 x 3 the law's
// own (finrft_surface_element_slope) where it has one, exact whatever `forward` says, and nothing for an element
// trailing at v_e; else in steps h = 1e-6 (|v_e| + SURFACE_SPEED), by forward differences from its force at t
// (kept by body_wrench at t) when `forward`, else central ones (probed_slope); forward, an element leading at v_e
// (its force not 0) with no DRFT term by leading_slope's two probes. An element trailing at v_e and at every probe
// adds nothing.
static void body_slope(const Items* s, int j, const mjtNum t[6], int forward, mjtNum dw[36]) {
  const FinrftSurface* p = s->surface[j];
  int analytic = finrft_surface_has_slope(p);
  mju_zero(dw, 36);
  for (int e = s->first[j]; e < s->first[j + 1]; e++) {
    const mjtNum* element = s->element + FINRFT_SUBMERGED * (size_t)e;
    const mjtNum* f0 = s->element_force + 3 * (size_t)e;
    mjtNum v[3], k[9];
    element_velocity(t, element, v);
    mjtNum h = 1e-6 * (sqrt(finrft_dot3(v, v)) + SURFACE_SPEED);
    if (analytic) {
      // the law's own Jacobian: nothing for an element that trails (n . v <= 0, where every surface law is 0)
      mjtNum f[3];
      if (!(finrft_dot3(element + 3, v) > 0) || !finrft_surface_element_slope(p, element + 3, v, element[6], element[7],
                                                                                f, k)) {
        continue;
      }
    } else if (forward && p->drft_lambda == 0 && (f0[0] != 0 || f0[1] != 0 || f0[2] != 0)) {
      leading_slope(p, element, v, f0, h, k);
    } else if (!probed_slope(p, element, v, f0, h, forward, k)) {
      continue;
    }
    add_element_slope(element, k, dw);
  }
}

// The RFT force at generalised velocity u (nv), each item's velocity and force (and each submerged element's
// force) kept for rft_slope: segments' J^T F(J u), bodies' J^T W(J u). Given body_slopes (36 per body, or NULL),
// the slope dW/dtwist of each body whose law has its own Jacobian goes there, for rft_slope at the same u.
static void rft_force(const Items* s, const mjtNum* u, mjtNum* force, mjtNum* body_slopes) {
  int nv = s->nv;
  mju_zero(force, nv);
  for (int i = 0; i < s->n + s->nbody; i++) {
    int rows = item_rows(s, i);
    const mjtNum* jac = s->jac + item_offset(s, i) * nv;
    const int* col = s->col + (size_t)nv * i;
    mjtNum *v = s->vel + item_offset(s, i), *f = s->out + item_offset(s, i);
    for (int r = 0; r < rows; r++) {
      v[r] = 0;
      for (int c = 0; c < s->ncol[i]; c++) v[r] += jac[r * nv + col[c]] * u[col[c]];
    }
    if (i < s->n) {
      s->law[i]->law->force(s->law[i]->params, s->law[i]->v_reg, v, s->axes + 6 * i, s->axes + 6 * i + 3, f);
    } else {
      body_wrench(s, i - s->n, v, f, body_slopes ? body_slopes + 36 * (size_t)(i - s->n) : NULL);
    }
    for (int c = 0; c < s->ncol[i]; c++) {
      int k = col[c];
      mjtNum sum = 0;
      for (int r = 0; r < rows; r++) sum += jac[r * nv + k] * f[r];
      force[k] += sum;
    }
  }
}

// Add item i's J^T c J to slope (nv x nv), c its slope in its own velocity (rows x rows).
static void add_item_slope(const Items* s, int i, const mjtNum* c, mjtNum* slope) {
  int nv = s->nv, rows = item_rows(s, i);
  const mjtNum* jac = s->jac + item_offset(s, i) * nv;
  const int* col = s->col + (size_t)nv * i;
  mjtNum cj[6];
  for (int b = 0; b < s->ncol[i]; b++) {
    int k = col[b];
    for (int r = 0; r < rows; r++) {
      cj[r] = 0;
      for (int q = 0; q < rows; q++) cj[r] += c[rows * r + q] * jac[q * nv + k];
    }
    for (int a = 0; a < s->ncol[i]; a++) {
      int row = col[a];
      mjtNum sum = 0;
      for (int r = 0; r < rows; r++) sum += jac[r * nv + row] * cj[r];
      slope[row * nv + k] += sum;
    }
  }
}

// The derivative of the RFT force (nv x nv) at the velocity of the last rft_force, J^T (dF/dv) J summed over the
// items, the laws' by forward differences when `forward`, else central ones; a body's from body_slopes where that
// rft_force put it there (not NULL, the law with its own Jacobian).
static void rft_slope(const Items* s, mjtNum* slope, int forward, const mjtNum* body_slopes) {
  int nv = s->nv;
  mju_zero(slope, nv * nv);
  for (int i = 0; i < s->n + s->nbody; i++) {
    size_t at = item_offset(s, i);
    mjtNum c[36];
    if (i < s->n) {
      segment_jacobian(s->law[i], s->vel + at, s->axes + 6 * i, s->axes + 6 * i + 3,
                       forward ? s->out + at : NULL, s->moves[i], c);
    } else if (body_slopes && finrft_surface_has_slope(s->surface[i - s->n])) {
      mju_copy(c, body_slopes + 36 * (size_t)(i - s->n), 36);
    } else {
      body_slope(s, i - s->n, s->vel + at, forward, c);
    }
    add_item_slope(s, i, c, slope);
  }
}

// Add A_e^T s n^T A_e = (A_e^T s) (A_e^T n)^T to dw (6 x 6, row-major): add_element_slope for an element's slope of
// rank one, s n^T, in a sixth of its arithmetic (A_e^T x = (arm x x, x)).
static void add_rank_one_slope(const mjtNum arm[3], const mjtNum s[3], const mjtNum n[3], mjtNum dw[36]) {
  mjtNum a[6], b[6];
  finrft_cross(a, arm, s);
  finrft_cross(b, arm, n);
  for (int r = 0; r < 3; r++) {
    a[3 + r] = s[r];
    b[3 + r] = n[r];
  }
  for (int r = 0; r < 6; r++) {
    for (int c = 0; c < 6; c++) dw[6 * r + c] += a[r] * b[c];
  }
}

// The linearly implicit step's slope at the velocity of the last rft_force: the secants of the elements that trail
// by less than the ramp's width (finrft_surface_trailing_slope; as the numpy twin's trailing_slopes), added to slope.
static void add_trailing_slopes(const Items* s, mjtNum* slope) {
  for (int j = 0; j < s->nbody; j++) {
    const FinrftSurface* p = s->surface[j];
    if (!finrft_surface_has_slope(p)) continue;
    mjtNum c[36], secant[3];
    int any = 0;
    mju_zero(c, 36);
    for (int e = s->first[j]; e < s->first[j + 1]; e++) {
      const mjtNum* element = s->element + FINRFT_SUBMERGED * (size_t)e;
      mjtNum v[3];
      element_velocity(s->vel + item_offset(s, s->n + j), element, v);
      if (finrft_surface_trailing_slope(p, element + 3, v, element[6], element[7], secant)) {
        add_rank_one_slope(element, secant, element + 3, c);
        any = 1;
      }
    }
    if (any) add_item_slope(s, s->n + j, c, slope);
  }
}

// Add the penalty stops' torque at the deflection they reach after `ahead` seconds at u to force (when not NULL),
// and its derivative in u to slope (when not NULL).
static void stops_add(const Items* s, const mjtNum* u, mjtNum ahead, mjtNum* force, mjtNum* slope) {
  for (int h = 0; h < s->nstop; h++) {
    int dof = s->stop_dof[h];
    mjtNum stiffening, torque = finrft_stop_torque(s->stop_q[h] + ahead * u[dof], s->stop_k[h], &stiffening);
    if (force) force[dof] += torque;
    if (slope) slope[dof * s->nv + dof] += stiffening * ahead;
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

// G(dv) into out: matrix dv - dt (other + F(qvel + dv)), the stops dt ahead; returns |G|.
static mjtNum newton_residual(const Items* s, Newton* w, const mjtNum* qvel, const mjtNum* dv, mjtNum dt,
                              mjtNum* out) {
  int nv = s->nv;
  for (int i = 0; i < nv; i++) w->u[i] = qvel[i] + dv[i];
  rft_force(s, w->u, w->force, NULL);
  stops_add(s, w->u, dt, w->force, NULL);
  mju_mulMatVec(out, w->matrix, dv, nv, nv);
  for (int i = 0; i < nv; i++) out[i] -= dt * (w->other[i] + w->force[i]);
  return mju_norm(out, nv);
}

// Whether the residual g (of the iterate whose RFT and stop forces are w->force) is at most NEWTON_RESIDUAL of dt
// times the step's largest force, w->other's or w->force's.
static int residual_small(const Newton* w, const mjtNum* g, int nv, mjtNum dt) {
  mjtNum size = 0, scale = 0;
  for (int i = 0; i < nv; i++) {
    size = mju_max(size, fabs(g[i]));
    scale = mju_max(scale, mju_max(fabs(w->other[i]), fabs(w->force[i])));
  }
  return size <= NEWTON_RESIDUAL * dt * scale;
}

// Whether a change of Newton's method as large as `change` (its largest component) that brings the velocity change
// to `next` ends it: below the tolerance times (1 + |qvel + next|), or, from a predicted start, below
// PREDICTOR_SHARE of how far next lies from the prediction.
static int change_small(const Workspace* ws, const mjtNum* qvel, const mjtNum* next, mjtNum change) {
  mjtNum scale = 0, miss = 0;
  for (int i = 0; i < ws->items.nv; i++) {
    scale = mju_max(scale, fabs(qvel[i] + next[i]));
    if (ws->predicted) miss = mju_max(miss, fabs(next[i] - ws->guess[i]));
  }
  return change <= mju_max(ws->newton_tolerance * (1 + scale), PREDICTOR_SHARE * miss);
}

// The velocity change of one step from the start step_prepare saw into ws->w.dv (ws->rhs = M qacc at v). With
// iterations == 1 the linearly implicit step in the RFT force (the first Newton iterate, no line search, stops as
// MuJoCo computed them); otherwise the root of G, with the stops' torque taken at the new positions too, by
// Newton's method, or FINRFT_NOT_CONVERGED.
static int newton_solve(Workspace* ws, const mjtNum* qvel, mjtNum dt, int iterations) {
  const Items* s = &ws->items;
  Newton* w = &ws->w;
  int nv = s->nv;
  mjtNum ahead = iterations > 1 ? dt : 0;
  const mjtNum* rhs = ws->rhs;
  if (ws->predicted) {
    // from the predicted change: the force and its slope there (one pass of the law) start Newton's method
    for (int i = 0; i < nv; i++) w->u[i] = qvel[i] + ws->guess[i];
    rft_force(s, w->u, w->force, ws->body_slopes);
    rft_slope(s, w->slope, 1, ws->body_slopes);
  } else {
    if (!ws->start_ready) {
      rft_force(s, qvel, ws->start_force, ws->body_slopes);
      rft_slope(s, ws->start_slope, iterations > 1, ws->body_slopes);
      if (iterations == 1) add_trailing_slopes(s, ws->start_slope);
      ws->start_ready = 1;
    }
    mju_copy(w->force, ws->start_force, nv);
    mju_copy(w->slope, ws->start_slope, nv * nv);
  }
  // other: every force but F and the stops', taken out where step_prepare's forward pass applied them
  mju_copy(w->other, rhs, nv);
  if (ws->has_applied) {
    mju_copy(w->trial, ws->applied, nv);  // w->trial is free until the search
    stops_add(s, qvel, 0, w->trial, NULL);
    for (int i = 0; i < nv; i++) w->other[i] -= w->trial[i];
  }
  stops_add(s, ws->predicted ? w->u : qvel, ahead, w->force, w->slope);
  for (int i = 0; i < nv; i++) w->dv[i] = ws->predicted ? ws->guess[i] : 0;
  mju_mulMatVec(w->g, w->matrix, w->dv, nv, nv);
  for (int i = 0; i < nv; i++) w->g[i] -= dt * (w->other[i] + w->force[i]);
  mjtNum norm = mju_norm(w->g, nv);
  // With attached surfaces alone, a leaner Newton's method, to the same root: the slope is kept while full steps
  // cut the residual by SURFACE_DECREASE each (made fresh when they stop doing so, or when a search stalls on a
  // kept one), and a step below the tolerance is taken without a residual to confirm it: the sand-swimmer's steps
  // take a third of the slopes and 40 % fewer calls of the law. Segments keep full Newton's method: a slope kept
  // on a segment law that feeds energy in (f_par < 0) once led it to another root.
  int lean = s->n == 0, fresh = 1;
  for (int it = 0; it < iterations; it++) {
    for (int i = 0; i < nv * nv; i++) w->jacobian[i] = w->matrix[i] - dt * w->slope[i];
    for (int i = 0; i < nv; i++) w->step[i] = -w->g[i];
    if (solve_dense(w->jacobian, w->step, nv)) return FINRFT_NOT_CONVERGED;
    if (iterations == 1) {
      mju_copy(w->dv, w->step, nv);
      return 0;
    }
    if (lean) {
      mjtNum size = 0;
      for (int i = 0; i < nv; i++) {
        size = mju_max(size, fabs(w->step[i]));
        w->candidate[i] = w->dv[i] + w->step[i];
      }
      if (change_small(ws, qvel, w->candidate, size) && residual_small(w, w->g, nv, dt)) {
        mju_copy(w->dv, w->candidate, nv);
        return 0;
      }
    }
    mjtNum alpha = 1, trial_norm;
    for (;;) {
      for (int i = 0; i < nv; i++) w->candidate[i] = w->dv[i] + alpha * w->step[i];
      trial_norm = newton_residual(s, w, qvel, w->candidate, dt, w->trial);
      if (trial_norm <= (1 - 1e-4 * alpha) * norm || alpha < 1e-6) break;
      alpha /= 2;
    }
    mjtNum change = 0;
    for (int i = 0; i < nv; i++) {
      w->dv[i] += alpha * w->step[i];
      w->g[i] = w->trial[i];
      change = mju_max(change, fabs(alpha * w->step[i]));
    }
    mjtNum before = norm;
    norm = trial_norm;
    if (change_small(ws, qvel, w->dv, change) && (fresh || alpha >= 1e-6) && residual_small(w, w->g, nv, dt)) return 0;
    // On attached surfaces, a search that fails on a fresh slope has met a kink of a law (an element switching
    // on) with no descent left: iterating on creeps across it by 1e-6 of a step per iteration, at 20 residuals
    // each, so the step is halved at once instead (the sand-swimmer's steps: half the calls of the law).
    if (lean && fresh && trial_norm > (1 - 1e-4 * alpha) * before) return FINRFT_NOT_CONVERGED;
    fresh = !(lean && alpha == 1 && trial_norm <= SURFACE_DECREASE * before);
    if (!fresh) continue;
    // the search's last residual was taken at the accepted iterate: rft_force's segments are there
    rft_slope(s, w->slope, 1, NULL);
    stops_add(s, w->u, dt, NULL, w->slope);
  }
  return FINRFT_NOT_CONVERGED;
}

// Pause (1) or resume (0) the passive force of every finrft.rft and finrft.surface instance of d.
static void plugins_pause(const mjModel* m, mjData* d, int paused) {
  int slot = -1, surface_slot = -1;
  mjp_getPlugin(FINRFT_PLUGIN, &slot);
  mjp_getPlugin(FINRFT_SURFACE_PLUGIN, &surface_slot);
  for (int i = 0; i < m->nplugin; i++) {
    FinrftInstance* p = m->plugin[i] == slot ? (FinrftInstance*)finrft_instance(m, d, i) : NULL;
    FinrftSurface* q = m->plugin[i] == surface_slot ? (FinrftSurface*)finrft_surface_instance(m, d, i) : NULL;
    if (p) p->paused = paused;
    if (q) q->paused = paused;
  }
}

// Pause (1) or resume (0) the medium's force on d: a forward pass between them computes the kinematics,
// velocities, actuators and every other force of a state whose medium force is read elsewhere, as a recording of
// an implicit step reads it where the step took it (finrft.experiments.attached_model.record_forward, which
// calls mj_forward itself: MuJoCo's Python callbacks may raise, which must not unwind through this library).
FINRFT_EXPORT void finrft_pause_medium(const mjModel* m, mjData* d, int paused) {
  plugins_pause(m, d, paused);
}

// What a step needs of its start (the state in d): MuJoCo's forces but the RFT force and the stops' (the plugins
// paused: the step takes those itself, and computing them in the forward pass as well cost a tenth of a wheel's
// step), rhs = M qacc, the mass matrix, the items. A constraint's force (a limit, a contact, friction loss) answers
// every other force, those too: with any constraint active the forward pass is taken again with them, and they
// are taken out of rhs (has_applied). With midpoint > 0 the segments and bodies are taken at the positions
// `midpoint` seconds ahead at the start's velocity (the stops stay at the start, which their deflection ahead
// already counts from); d's derived quantities are the start's again afterwards.
static void step_prepare(const mjModel* m, mjData* d, Workspace* ws, mjtNum midpoint) {
  Items* s = &ws->items;
  plugins_pause(m, d, 1);
  mj_forward(m, d);
  plugins_pause(m, d, 0);
  ws->has_applied = d->nefc > 0;
  if (ws->has_applied) mj_forward(m, d);
  mj_mulM(m, d, ws->rhs, d->qacc);
  mj_fullM(m, d, ws->mass);
  stops_update(m, d, s);
  ws->start_ready = 0;
  ws->midpoint = midpoint;
  // the items at the start: the force the forward pass applied there, and every step's but the midpoint's (whose
  // start's elements, a second pass over every element, cost a seventh of the hexapod's step)
  if (ws->has_applied || !(midpoint > 0)) items_update(m, d, s);
  if (ws->has_applied) rft_force(s, d->qvel, ws->applied, NULL);
  if (midpoint > 0) {
    mju_copy(ws->qpos_start, d->qpos, m->nq);
    mj_integratePos(m, d->qpos, d->qvel, midpoint);
    mj_kinematics(m, d);
    mj_comPos(m, d);
    items_update(m, d, s);
    mju_copy(d->qpos, ws->qpos_start, m->nq);
    mj_kinematics(m, d);
    mj_comPos(m, d);
  }
}

// One implicit step of size dt from the start step_prepare saw:
// 0, FINRFT_UNSTABLE when the state stopped being finite, or FINRFT_NOT_CONVERGED (the state untouched). It leaves
// MuJoCo's derived quantities in d as they were at the start (without the RFT force and the stops': mj_forward
// brings them up to date), so another step from the same start needs no step_prepare once the state is restored.
static int step_take(const mjModel* m, mjData* d, mjtNum dt, int iterations, Workspace* ws) {
  int nv = m->nv;
  Newton* w = &ws->w;
  mju_copy(w->matrix, ws->mass, nv * nv);
  for (int i = 0; i < nv; i++) w->matrix[i * nv + i] += dt * m->dof_damping[i];
  for (int a = 0; a < m->nu; a++) {
    if (m->actuator_trntype[a] != mjTRN_JOINT || m->actuator_biastype[a] != mjBIAS_AFFINE) continue;
    int dof = m->jnt_dofadr[m->actuator_trnid[2 * a]];
    mjtNum gear = m->actuator_gear[6 * a];
    w->matrix[dof * nv + dof] -= dt * gear * gear * m->actuator_biasprm[mjNBIAS * a + 2];
  }
  if (newton_solve(ws, d->qvel, dt, iterations)) return FINRFT_NOT_CONVERGED;
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
    if (!isfinite(d->qvel[i])) failed = FINRFT_UNSTABLE;
  }
  if (ws->counts) ws->counts[0]++;
  mju_copy(d->qacc_warmstart, d->qacc, nv);
  mj_integratePos(m, d->qpos, d->qvel, dt);
  d->time += dt;
  return failed;
}

// One implicit step of size dt, the RFT force taken at the positions a fraction `midpoint` of it ahead (0: the
// start); 0, FINRFT_UNSTABLE when the state stopped being finite, or FINRFT_NOT_CONVERGED.
static int implicit_step(const mjModel* m, mjData* d, mjtNum dt, int iterations, mjtNum midpoint, Workspace* ws,
                         int halvings) {
  step_prepare(m, d, ws, midpoint * dt);
  mjtNum* history = ws->history;
  ws->predicted = history && iterations > 1 && ws->items.n == 0 && history[0] == d->time;
  for (int i = 0; ws->predicted && i < m->nv; i++) ws->guess[i] = history[2 + i] * (dt / history[1]);
  int failed = step_take(m, d, dt, iterations, ws);
  if (history && !failed) {
    history[0] = d->time;
    history[1] = dt;
    mju_copy(history + 2, ws->w.dv, m->nv);
  }
  if (failed != FINRFT_NOT_CONVERGED) return failed;
  // the halves start afresh: a prediction may be what led Newton's method astray
  if (history) history[0] = NAN;
  if (iterations == 1 || halvings == NEWTON_HALVINGS) return FINRFT_NOT_CONVERGED;
  if (ws->counts) ws->counts[1]++;
  failed = implicit_step(m, d, dt / 2, iterations, midpoint, ws, halvings + 1);
  return failed ? failed : implicit_step(m, d, dt / 2, iterations, midpoint, ws, halvings + 1);
}

// The implicit (iterations == 1), newton and newton-midpoint (midpoint 0.5, else 0) methods: nstep steps of the
// model's time step. counts (or NULL): the steps taken (a halved step counts as two) and rejected (halved) are
// added to counts[0] and counts[1]. history (or NULL; nv + 2 numbers, NaN first before the first call): the last
// step's time after it, size and velocity change, which a newton step on attached surfaces alone that starts at
// that time takes as its start (PREDICTOR_SHARE), and which each step leaves there for the next.
FINRFT_EXPORT int finrft_implicit_step(const mjModel* m, mjData* d, int nstep, int iterations, mjtNum midpoint,
                                       int64_t* counts, mjtNum* history) {
  Workspace ws;
  mj_markStack(d);
  int failed = workspace_make(m, d, &ws, 0, NULL);
  ws.counts = counts;
  ws.history = history;
  for (int step = 0; step < nstep && !failed; step++) {
    failed = implicit_step(m, d, m->opt.timestep, iterations, midpoint, &ws, 0);
  }
  mj_freeStack(d);
  return failed;
}

// The adaptive methods: steps over `duration` seconds, implicit (iterations == 1: "adaptive") or newton
// ("adaptive-newton"), each accepted when one step of h and two of h/2 agree to `tol` (max over qpos, qvel of
// |difference| / (1e-3 + |value|); newton steps: over qpos only, as a light segment's velocity jumps onto the
// stiff force's balance within any step, which shows in the positions as h times the jump, see integrate.py).
// Both are first order, so the accepted positions and velocities are extrapolated, 2 (two halves) - (one step),
// which cancels the first-order error. The step grows or shrinks by 0.9 sqrt(tol / error) (within 0.2x..2x), never
// above hmax; *h carries it over calls (the caller sets it small again after a reversal). A newton step whose solve
// finds no root is rejected like one over the tolerance, its size divided by 4 (no halving inside the step).
// counts (or NULL): the steps accepted and rejected are added to counts[0] and counts[1].
// Returns 0, FINRFT_UNSTABLE, FINRFT_STEP_TOO_SMALL when the step falls below 1e-9 s, or another failure's code.
FINRFT_EXPORT int finrft_adaptive_advance(const mjModel* m, mjData* d, mjtNum duration, mjtNum hmax, mjtNum tol,
                                          int iterations, mjtNum* h, int64_t* counts) {
  const int spec = mjSTATE_INTEGRATION;
  int size = mj_stateSize(m, spec);
  Workspace ws;
  mjtNum* states = NULL;
  mj_markStack(d);
  int failed = workspace_make(m, d, &ws, 3 * size, &states);
  mjtNum *start = states, *full = states + size, *halves = states + 2 * size;
  // Newton's error, a velocity, moves a position by h times it: far below what the step's test allows
  ws.newton_tolerance = mju_max(NEWTON_TOLERANCE, NEWTON_SHARE * tol);
  mjtNum end = d->time + duration;
  // the slice of the integration state holding qpos and qvel (after time)
  int first = 1, count = m->nq + m->nv;
  int measured = iterations > 1 ? m->nq : count;
  while (!failed && d->time < end - TIME_ROUNDING) {
    mjtNum step = mju_min(mju_min(*h, hmax), end - d->time);
    // The whole step and the first half start from the same state: one step_prepare serves both.
    mj_getState(m, d, start, spec);
    step_prepare(m, d, &ws, 0);
    failed = step_take(m, d, step, iterations, &ws);
    mj_getState(m, d, full, spec);
    mj_setState(m, d, start, spec);
    if (!failed) failed = step_take(m, d, step / 2, iterations, &ws);
    if (!failed) {
      step_prepare(m, d, &ws, 0);
      failed = step_take(m, d, step / 2, iterations, &ws);
    }
    mj_getState(m, d, halves, spec);
    if (failed == FINRFT_NOT_CONVERGED && iterations > 1) {
      mj_setState(m, d, start, spec);
      *h = step / 4;
      failed = 0;
      if (counts) counts[1]++;
      if (*h < 1e-9) failed = FINRFT_STEP_TOO_SMALL;
      continue;
    }
    mjtNum error = 0;
    for (int i = first; i < first + measured; i++) {
      error = mju_max(error, fabs(full[i] - halves[i]) / (1e-3 + fabs(halves[i])));
    }
    if (failed || !isfinite(error)) {
      failed = failed ? failed : FINRFT_UNSTABLE;
    } else if (error <= tol) {
      for (int i = first; i < first + count; i++) halves[i] += halves[i] - full[i];
      mj_setState(m, d, halves, spec);
      mjtNum proposal = mju_min(hmax, step * mju_min(2.0, 0.9 * sqrt(tol / mju_max(error, 1e-300))));
      // a step cut short to land on `end` (a sample, a reversal) is no reason to shorten the steps after it
      *h = step < *h - TIME_ROUNDING ? mju_max(*h, proposal) : proposal;
      if (counts) counts[0]++;
    } else {
      mj_setState(m, d, start, spec);
      *h = step * mju_max(0.2, 0.9 * sqrt(tol / error));
      if (counts) counts[1]++;
      if (*h < 1e-9) failed = FINRFT_STEP_TOO_SMALL;
    }
  }
  mj_freeStack(d);
  return failed;
}

// `nstep` of MuJoCo's steps, with the mjSTATE_FULLPHYSICS state after step at[j] (1 <= at[0] < at[1] < ... <=
// nstep) written to out + j * nstate. As MuJoCo's rollout, but recording the states a batch keeps, not every step's:
// the copy of each step's state cost rollout 5 % of a plate's steps. FINRFT_UNSTABLE, at once, when a recorded or
// the final state is not finite.
static int all_finite(const mjtNum* x, int n) {
  for (int i = 0; i < n; i++) {
    if (!isfinite(x[i])) return 0;
  }
  return 1;
}

FINRFT_EXPORT int finrft_explicit_record(const mjModel* m, mjData* d, int nstep, int nrecord, const int* at,
                                         mjtNum* out) {
  int spec = mjSTATE_FULLPHYSICS, nstate = mj_stateSize(m, spec);
  for (int i = 1, j = 0; i <= nstep; i++) {
    mj_step(m, d);
    int record = j < nrecord && at[j] == i;
    if (!record && i < nstep) continue;
    if (!all_finite(d->qpos, m->nq) || !all_finite(d->qvel, m->nv)) return FINRFT_UNSTABLE;
    if (record) mj_getState(m, d, out + (size_t)nstate * j++, spec);
  }
  return 0;
}

// `nstep` of MuJoCo's steps, step i from the i % nstate-th of the `nstate` mjSTATE_INTEGRATION states `states`
// (the controls and applied forces with the physics: a servo's ctrl from another instant is a violent step): what
// one step costs at those states. A run of explicit steps leaves them where the step is beyond its limit: the
// wheel rig's at its own 62.5 ms is out of the sand in three steps, and its later steps cost nothing of the medium.
FINRFT_EXPORT void finrft_explicit_from(const mjModel* m, mjData* d, const mjtNum* states, int nstate, int nstep) {
  size_t size = mj_stateSize(m, mjSTATE_INTEGRATION);
  for (int i = 0; i < nstep; i++) {
    mj_setState(m, d, states + size * (size_t)(i % nstate), mjSTATE_INTEGRATION);
    mj_step(m, d);
  }
}
