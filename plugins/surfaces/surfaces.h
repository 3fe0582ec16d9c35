// The free surfaces of the medium, the twins of finrft/surfaces/NAME.py: each point's depth (m) along gravity
// below the surface, positive below it. The plugin (finrft_surface.c) holds its surface as a FinrftField and
// measures its elements with finrft_field_depth, which calls these.
//
// Points, gravity and vectors are world-frame double[3]; `points` and `depth` hold n points. A grid is MuJoCo's
// <hfield> layout: heights[r * ncol + c] (m) at x = -size[0] + 2 size[0] c / (ncol - 1), y = -size[1] +
// 2 size[1] r / (nrow - 1) of its frame, `frame` row-major with the grid's axes as columns, `centre` its origin.
// Functions return 0, or FINRFT_SURFACE_BAD_INPUT where the Python twin raises SceneError.

#ifndef FINRFT_SURFACES_H_
#define FINRFT_SURFACES_H_

#if defined(_WIN32)
#define FINRFT_SURFACE_EXPORT __declspec(dllexport)
#else
#define FINRFT_SURFACE_EXPORT __attribute__((visibility("default")))
#endif

#ifndef M_PI
#define M_PI 3.14159265358979323846  // not in strict C99's math.h
#endif

#define FINRFT_SURFACE_BAD_INPUT (-1)
#define FINRFT_FRAME_TOLERANCE 1e-9  // finrft.surfaces.hfield.FRAME_TOLERANCE

// The unit vector against gravity; FINRFT_SURFACE_BAD_INPUT for a zero or non-finite gravity.
int finrft_surface_up(const double g[3], double up[3]);

FINRFT_SURFACE_EXPORT int finrft_flat_depth(double surface_z, const double g[3], int n, const double* points,
                                            double* depth);
FINRFT_SURFACE_EXPORT int finrft_plane_depth(const double point[3], const double normal[3], const double g[3],
                                             int n, const double* points, double* depth);

// A heightfield's grid; finrft_grid_check: FINRFT_SURFACE_BAD_INPUT unless it is at least 2 x 2, its size
// positive, its heights finite and its frame a rotation whose z axis is against gravity
// (finrft.surfaces.hfield.grid); finrft_grid_placed: the same but for the heights.
typedef struct {
  int nrow, ncol;
  const double* heights;
  double size[2], centre[3], frame[9];
} FinrftGrid;

int finrft_grid_check(const FinrftGrid* grid, const double g[3]);
int finrft_grid_placed(const FinrftGrid* grid, const double g[3]);
// A point's coordinates in the grid's frame (inline: the deforming surface places every element at each update).
static inline void finrft_grid_local(const FinrftGrid* grid, const double p[3], double local[3]) {
  double d[3] = {p[0] - grid->centre[0], p[1] - grid->centre[1], p[2] - grid->centre[2]};
  for (int j = 0; j < 3; j++) {
    local[j] = d[0] * grid->frame[j] + d[1] * grid->frame[3 + j] + d[2] * grid->frame[6 + j];
  }
}
double finrft_grid_height(const FinrftGrid* grid, const double* heights, double x, double y);

FINRFT_SURFACE_EXPORT int finrft_hfield_depth(int nrow, int ncol, const double* heights, const double size[2],
                                              const double centre[3], const double frame[9], const double g[3],
                                              int n, const double* points, double* depth);

// The deforming surface (finrft.surfaces.deforming): depth from the deformed heights, with pile_factor > 0 the
// wheel group's pile rule against `original` (pile_factor 0: none, `original` may be NULL).
FINRFT_SURFACE_EXPORT int finrft_deforming_depth(int nrow, int ncol, const double* heights, const double* original,
                                                 double pile_factor, const double size[2], const double centre[3],
                                                 const double frame[9], const double g[3], int n,
                                                 const double* points, double* depth);
// A deforming surface's grid as the plugin measures its elements on it: the level (`grid`), the heights it started
// from and the pile rule's factor (finrft_deforming_depth's), and the grid points per metre along x and y.
typedef struct {
  FinrftGrid grid;
  const double* original;
  double pile_factor;
  double scale[2];
} FinrftDeformingGrid;
void finrft_deforming_grid(FinrftDeformingGrid* g, int nrow, int ncol, const double* heights,
                           const double* original, double pile_factor, const double size[2], const double centre[3],
                           const double frame[9]);
// The depths (finrft_deforming_depth's, but not through the pile rule where <= 0: no force either way) of n points
// of a body, `centres` (3 n: every x, every y, every z) in the body's frame, whose origin is `at` in the grid's frame
// and whose axes turn into the grid's by `turn` (3 x 3, row-major), each coordinate within `extent` of its origin;
// a point above every grid point under that box gets a depth <= 0 without interpolating the grid.
void finrft_deforming_body_depths(const FinrftDeformingGrid* g, const double at[3], const double turn[9],
                                  const double extent[3], int n, const double* centres, double* depth);
// The highest height of the grid points around the box [low, high] of the grid's frame (x, y; beyond the grid, of
// its nearest edge): no point of the surface over the box is higher.
double finrft_deforming_top(const FinrftDeformingGrid* g, const double low[2], const double high[2]);
// Sweep: heights updated in place, occupied[nrow * ncol] set to 1 under the body.
FINRFT_SURFACE_EXPORT int finrft_deforming_sweep(int nrow, int ncol, double* heights, const double size[2],
                                                 const double centre[3], const double frame[9], const double g[3],
                                                 int n, const double* points, const double* areas,
                                                 const double* velocities, double front_share,
                                                 unsigned char* occupied);
// The frame the laws measure their angles in, rows x, y, z (row-major): z = up (unit), x the world's x (y where up
// is near x) made square to it; the identity for up = +z. As finrft.surfaces.law_frame.
void finrft_surface_frame(const double up[3], double frame[9]);

// Relax in place; blocked may be NULL. The iterations taken, or -1 when max_iterations did not reach tolerance.
FINRFT_SURFACE_EXPORT int finrft_deforming_relax(int nrow, int ncol, double* heights, const double size[2],
                                                 double repose, const unsigned char* blocked, double tolerance,
                                                 int max_iterations);

// A run's deforming surface (finrft.surfaces.deforming.DeformingSurface, whose arrays these point into; its ctypes
// twin _Deforming): the grid, the sand's heights, the level the elements measure from, the original heights (the
// pile rule's), the points under the body at the last step and those the last sweep found so (bytes, 0 or 1), and
// `dirty`, the box (r0, r1, c0, c1; r0 > r1: none) of the edges relaxation left with excess; `compaction`, the share
// of the sand a sweep removes that is compacted under the body instead of going to the berm, added to `compacted`
// (a height of sand at its bulk density, per grid point; may be NULL when compaction is 0); `facing` 1: an element
// leading into the sand (outward normal . velocity > 0) pushes its sand along its normal's horizontal part (the side
// it faces) rather than along its horizontal motion (0).
typedef struct {
  int nrow, ncol;
  double size[2], centre[3], frame[9];
  double repose, front_share, tolerance;
  int step_iterations;
  double *heights, *level, *original;
  unsigned char *under, *occupied;
  int dirty[4];
  double compaction;
  double* compacted;
  int facing;
  int held[4];  // the box (rows r0..r1, columns c0..c1) of the points under the body at the last step; r0 > r1: none
} FinrftDeforming;

// One step (DeformingSurface.step): the elements at `points` (world, m) of `areas` moving at `velocities` sweep the
// sand, which relaxes at most step_iterations times, and the level follows; with `imprint` the body's imprint
// instead. `normals` (world, unit; NULL only when s->facing is 0) the elements' outward normals. The volume displaced
// into *removed (m^3); 0, or FINRFT_SURFACE_BAD_INPUT (nothing changed).
FINRFT_SURFACE_EXPORT int finrft_deforming_step(FinrftDeforming* s, const double g[3], int n, const double* points,
                                                const double* areas, const double* velocities,
                                                const double* normals, int imprint, double* removed);

#endif  // FINRFT_SURFACES_H_
