// A heightfield free surface (MuJoCo's <hfield> layout), bilinear between its points: the twin of
// finrft/surfaces/hfield.py.

#include <math.h>

#include "surfaces.h"

int finrft_grid_check(const FinrftGrid* grid, const double g[3]) {
  if (finrft_grid_placed(grid, g)) return FINRFT_SURFACE_BAD_INPUT;
  for (int i = 0; i < grid->nrow * grid->ncol; i++) {
    if (!isfinite(grid->heights[i])) return FINRFT_SURFACE_BAD_INPUT;
  }
  return 0;
}

int finrft_grid_placed(const FinrftGrid* grid, const double g[3]) {
  double up[3];
  if (finrft_surface_up(g, up) || grid->nrow < 2 || grid->ncol < 2) return FINRFT_SURFACE_BAD_INPUT;
  if (!(isfinite(grid->size[0]) && isfinite(grid->size[1]) && grid->size[0] > 0 && grid->size[1] > 0)) {
    return FINRFT_SURFACE_BAD_INPUT;
  }
  const double* R = grid->frame;
  for (int a = 0; a < 3; a++) {
    for (int b = 0; b < 3; b++) {
      double dot = R[a] * R[b] + R[3 + a] * R[3 + b] + R[6 + a] * R[6 + b];
      if (fabs(dot - (a == b)) > FINRFT_FRAME_TOLERANCE) return FINRFT_SURFACE_BAD_INPUT;
    }
  }
  double off = sqrt((R[2] - up[0]) * (R[2] - up[0]) + (R[5] - up[1]) * (R[5] - up[1]) +
                    (R[8] - up[2]) * (R[8] - up[2]));
  return off > FINRFT_FRAME_TOLERANCE ? FINRFT_SURFACE_BAD_INPUT : 0;
}

static double clamp(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

double finrft_grid_height(const FinrftGrid* grid, const double* h, double x, double y) {
  int nrow = grid->nrow, ncol = grid->ncol;
  double dx = 2 * grid->size[0] / (ncol - 1), dy = 2 * grid->size[1] / (nrow - 1);
  double u = clamp((x + grid->size[0]) / dx, 0, ncol - 1.0), v = clamp((y + grid->size[1]) / dy, 0, nrow - 1.0);
  int c = (int)floor(u), r = (int)floor(v);
  if (c > ncol - 2) c = ncol - 2;
  if (r > nrow - 2) r = nrow - 2;
  double fu = u - c, fv = v - r;
  const double* row = h + r * ncol + c;
  return (1 - fu) * (1 - fv) * row[0] + fu * (1 - fv) * row[1] + (1 - fu) * fv * row[ncol] + fu * fv * row[ncol + 1];
}

int finrft_hfield_depth(int nrow, int ncol, const double* heights, const double size[2], const double centre[3],
                        const double frame[9], const double g[3], int n, const double* points, double* depth) {
  FinrftGrid grid = {nrow, ncol, heights, {size[0], size[1]}, {centre[0], centre[1], centre[2]}, {0}};
  for (int i = 0; i < 9; i++) grid.frame[i] = frame[i];
  if (finrft_grid_check(&grid, g)) return FINRFT_SURFACE_BAD_INPUT;
  for (int k = 0; k < n; k++) {
    double local[3];
    finrft_grid_local(&grid, points + 3 * k, local);
    depth[k] = finrft_grid_height(&grid, heights, local[0], local[1]) - local[2];
  }
  return 0;
}
