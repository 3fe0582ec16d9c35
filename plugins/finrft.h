// Declarations shared by the plugin (finrft_rft.c), the force laws (laws/*.c) and the steppers (steppers.c).
//
// setup.py defines, from the Python sources of truth:
//   FINRFT_LAWS                 X(paper)X(table)...: every file in plugins/laws/, by name (laws/NAME.c defines
//                               `const FinrftLaw finrft_law_NAME`)
//   FINRFT_UNSTABLE, ...        the steppers' return codes, finrft.native.Code

#ifndef FINRFT_H_
#define FINRFT_H_

#include <math.h>
#include <stdint.h>

#include <mujoco/mujoco.h>

#include "surfaces/surfaces.h"

#if !defined(FINRFT_LAWS) || !defined(FINRFT_UNSTABLE) || !defined(FINRFT_STEP_TOO_SMALL) || \
    !defined(FINRFT_NOT_CONVERGED) || !defined(FINRFT_ARENA_FULL)
#error "build the plugin with setup.py (pip install .): it defines the law list and the return codes"
#endif

#define FINRFT_PLUGIN "finrft.rft"

#if defined(_WIN32)
#define FINRFT_EXPORT __declspec(dllexport)
#else
#define FINRFT_EXPORT __attribute__((visibility("default")))
#endif

// A segment force law: F (world frame, N) on one segment from its midpoint velocity v and its axis x and in-plane
// normal y (unit vectors, world frame). Every law fades out below the speed v_reg (m/s, > 0), which the plugin
// reads for all laws; the implicit steps difference a law on that scale. The twin of finrft/laws/NAME.py.
typedef struct {
  const char* name;           // the value of config `law`
  const char* const* keys;    // the config keys of its own parameters
  int nkeys;
  // Its parameters from an instance's config, or NULL after a mju_warning that names the key.
  void* (*create)(const mjModel* m, int instance);
  void (*destroy)(void* params);
  void (*force)(const void* params, mjtNum v_reg, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                mjtNum force[3]);
} FinrftLaw;

// Small vector products, inline: the segment loop runs every step, and MuJoCo's mju_ versions are calls into its
// library (about a third of the plugin's time in a 3-segment plate).
static inline mjtNum finrft_dot3(const mjtNum a[3], const mjtNum b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static inline void finrft_cross(mjtNum out[3], const mjtNum a[3], const mjtNum b[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

// R v, R a 3 x 3 row-major matrix, summed as mju_mulMatVec3 sums it (the same numbers without the call).
static inline void finrft_mul_mat_vec3(mjtNum out[3], const mjtNum R[9], const mjtNum v[3]) {
  out[0] = R[0] * v[0] + R[1] * v[1] + R[2] * v[2];
  out[1] = R[3] * v[0] + R[4] * v[1] + R[5] * v[2];
  out[2] = R[6] * v[0] + R[7] * v[1] + R[8] * v[2];
}

// The inputs of every law: tanh(|v| / v_reg), and the direction cosines v^.x^ and v^.y^ (0 at rest). Inline,
// as it is on the steps' hot path.
static inline void finrft_components(mjtNum v_reg, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                                     mjtNum* ramp, mjtNum* vx, mjtNum* vy) {
  mjtNum speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  mjtNum safe = speed > 0 ? speed : 1, ratio = speed / v_reg;
  // tanh is 1 in double from 19.1 on: the same number without the call, for a segment well above v_reg
  *ramp = ratio < 20 ? tanh(ratio) : 1;
  *vx = (v[0] * x[0] + v[1] * x[1] + v[2] * x[2]) / safe;
  *vy = (v[0] * y[0] + v[1] * y[1] + v[2] * y[2]) / safe;
}

// A required config value as one finite number; 0, or -1 after a warning naming the key.
int finrft_read_number(const mjModel* m, int instance, const char* key, mjtNum* out);

// The penalty stop on a hinge deflection q (rad) from its rest angle: the torque -k (q + |q|) q, and into *slope
// (when not NULL) its derivative in q.
static inline mjtNum finrft_stop_torque(mjtNum q, mjtNum k, mjtNum* slope) {
  if (slope) *slope = q > 0 ? -4 * k * q : 0;
  return -k * (q + fabs(q)) * q;
}

// An instance of the plugin: one force group's law, the segments it acts on and the hinges carrying its stop.
typedef struct {
  const mjModel* model;  // the model it was made for (finrft_instance)
  const FinrftLaw* law;
  void* params;
  mjtNum v_reg, stop_stiffness;
  int nseg;
  int* site;
  int* body;
  int* last_dof;  // per segment: the last dof of its body's chain (-1: none), where J^T F starts
  int nhinge;
  int* hinge_qpos;
  int* hinge_dof;
  int paused;  // set by the steppers around the forward pass at a step's start: they take the force themselves
} FinrftInstance;


// The instance of finrft.rft with index `instance` for the model `m` that `d` is stepped with. MuJoCo's rollout
// steps one mjData with every model of a batch that has the same sizes, while an instance holds what it read from
// the model it was made for (law, coefficients, segments): an instance made for another model is made again for
// this one. NULL (with every generalized force NaN, so that the run stops as unstable) should that fail.
const FinrftInstance* finrft_instance(const mjModel* m, mjData* d, int instance);

// Fill the passive forces with NaN: a plugin that cannot compute its forces must not let a run go on without them.
static inline void finrft_poison(const mjModel* m, mjData* d) {
  for (int i = 0; i < m->nv; i++) d->qfrc_passive[i] = NAN;
}

// A segment's axis x and normal y (world frame): its site's x and y axes.
static inline void finrft_site_axes(const mjData* d, int s, mjtNum x[3], mjtNum y[3]) {
  const mjtNum* R = d->site_xmat + 9 * s;
  x[0] = R[0]; x[1] = R[3]; x[2] = R[6];
  y[0] = R[1]; y[1] = R[4]; y[2] = R[7];
}

// finrft.surface (plugins/finrft_surface.c): one instance per body, the body's surface elements and their law.
#define FINRFT_SURFACE_PLUGIN "finrft.surface"

// The free surface an instance measures its elements' depths from (config `surface`; finrft.surfaces.Field's
// twin), one kind of plugins/surfaces/ behind finrft_field_depth. A kind with state (the deforming one: a grid of
// heights that the elements displace) keeps it per mjData: see finrft_field_depth in finrft_surface.c.
enum { FINRFT_FIELD_FLAT, FINRFT_FIELD_PLANE, FINRFT_FIELD_HFIELD, FINRFT_FIELD_DEFORMING };
typedef struct {
  int kind;                    // FINRFT_FIELD_*, by the name of its file in plugins/surfaces/ (kFields)
  double surface_z;            // flat
  double point[3], normal[3];  // plane: a point of it (m) and its normal out of the sand
  int nrow, ncol;              // hfield: the grid as finrft_hfield_depth takes it, its heights owned here
  double* heights;
  double size[2], centre[3], frame[9];
  double* original;            // deforming: the heights it started from (`heights` are the level the run sets)
  double pile_factor;          // deforming: the wheel group's pile rule's factor, 0: none
} FinrftField;

// Each of n points' (world, m) depth along gravity g below the surface: 0, or FINRFT_SURFACE_BAD_INPUT where
// the surface cannot be measured under g (n = 0 checks only).
int finrft_field_depth(const FinrftField* f, const double g[3], int n, const double* points, double* depth);

typedef struct {
  const mjModel* model;  // the model it was made for (finrft_surface_instance)
  int law;               // index into the table of surface laws in finrft_surface.c
  double coef[60];       // the law's coefficients: li2013 the first 9, rft3d 60
  double zeta, xi, mu_surf, surface_z;
  FinrftField field;     // the free surface (surface_z's flat one unless config `surface` names another)
  double gravity[3];     // the model's, read again at every finrft_surface_instance (between steps it may change)
  int level;             // flat under gravity along -z (or none): depth from z alone, the laws' own frame (today's)
  int measured;          // gravity, level and frame are the model's as last read
  int upright;           // gravity along -z (or none): the laws' frame is the identity, their own
  double frame[9];       // otherwise the laws' frame, rows x, y, up (finrft_surface_frame)
  double* scratch;       // 4 n: the elements' world centres, then their depths, at one evaluation (on a deforming
                         // surface 3 n more: the elements' centres by coordinate, deforming_elements)
  double v_reg;          // m/s, the ramp tanh(max(n.v, 0) / v_reg) of every element's force; 0: none
  double drft_lambda, bulk_density;  // drft_lambda = 0: no DRFT term
  int body;
  int n;
  double* element;  // n x 7: centre, normal (body frame), area
  int ngeom;        // the geoms the elements were cut from (config `geoms`; 0: not given, nothing checked)
  double* geom;     // ngeom x 12: place among the body's geoms, type, size, pos, quat as they were cut
  int paused;       // as FinrftInstance's
  int has_applied;  // 1 when the last passive force computation on this mjData applied `applied` (not paused)
  double applied[6];
  double reach;      // deforming surface: the elements' largest distance from the body's origin
  double extent[3];  // deforming surface: the elements' largest |coordinate| along each body axis
} FinrftSurface;

// The instance of finrft.surface with index `instance` for the model `m` that `d` is stepped with (made again for
// another model, as finrft_instance); NULL, with the passive forces NaN, should that fail.
const FinrftSurface* finrft_surface_instance(const mjModel* m, mjData* d, int instance);

// The medium's force and torque on the instance's body, wrench = (torque about the body's origin, force), world
// frame, had the body the twist (angular velocity, velocity of its origin), world frame, at the positions of d
// (after mj_kinematics): the sum over its elements, as the plugin applies it.
void finrft_surface_wrench(const FinrftSurface* p, const mjData* d, const mjtNum twist[6], mjtNum wrench[6]);

// One element's force (world frame) under the instance's law, DRFT term and ramp: outward unit normal, velocity,
// depth below the surface (m), area (m^2).
//
// With the ramp on, an element whose n . v is at most FINRFT_RAMP_FLOOR v_reg has no force (the ramp would leave
// less than that share of it) and costs no call of its law: a face moving along itself, which rounding puts on
// either side of n . v = 0, as the sides of a rolling wheel, a third of its submerged elements (RAMP_FLOOR in
// finrft/laws/__init__.py).
#define FINRFT_RAMP_FLOOR 1e-12
void finrft_surface_element_force(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                                  mjtNum area, mjtNum f[3]);

// Whether the instance's law has an analytic velocity Jacobian (finrft_surface_element_slope): li2013 and rft3d.
int finrft_surface_has_slope(const FinrftSurface* p);

// finrft_surface_element_force into f and its derivative in v into k (3 x 3, row-major: k[3 i + j] = df_i/dv_j),
// analytic; only for an instance whose law has one (finrft_surface_has_slope). 0 where both are 0 without a call of
// the law (below the ramp's floor), else 1.
int finrft_surface_element_slope(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                                  mjtNum area, mjtNum f[3], mjtNum k[9]);
// The linearly implicit step's slope of an element trailing by less than the ramp's width (-v_reg < n . v <=
// FINRFT_RAMP_FLOOR v_reg): the secant to where it leads by v_reg (as Attached.trailing_slopes), of rank one, s n^T,
// its s into secant. 1 where it wrote s, 0 for any other element or without a ramp.
int finrft_surface_trailing_slope(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                                  mjtNum area, mjtNum secant[3]);

// The instance's law alone on one element (no DRFT term, no ramp), as finrft_surface_element_force's arguments:
// every surface law is rate-independent, a function of the direction of v alone.
void finrft_surface_law_force(const FinrftSurface* p, const mjtNum normal[3], const mjtNum v[3], mjtNum depth,
                              mjtNum area, mjtNum f[3]);

// The instance's elements below the free surface at the positions of d (after mj_kinematics), world frame, into
// out (FINRFT_SUBMERGED numbers each: arm from the body's origin, outward normal, depth, area; room for all p->n);
// returns their count. Positions are fixed within a step, so the implicit steps take them once per step and loop
// over these alone: an element above the surface has no force at any velocity.
#define FINRFT_SUBMERGED 8
int finrft_surface_submerged(const FinrftSurface* p, const mjData* d, mjtNum* out);

// The steppers (steppers.c), which the peak-keeping steppers (peaks.c) call.
int finrft_implicit_step(const mjModel* m, mjData* d, int nstep, int iterations, mjtNum midpoint, int64_t* counts,
                         mjtNum* history);
int finrft_adaptive_advance(const mjModel* m, mjData* d, mjtNum duration, mjtNum hmax, mjtNum tol, int iterations,
                            mjtNum* h, int64_t* counts);

#endif  // FINRFT_H_
