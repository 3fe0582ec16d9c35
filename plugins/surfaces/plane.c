// A plane free surface at any tilt: the twin of finrft/surfaces/plane.py.

#include <math.h>

#include "surfaces.h"

int finrft_surface_up(const double g[3], double up[3]) {
  double norm = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  if (!isfinite(norm) || norm == 0) return FINRFT_SURFACE_BAD_INPUT;
  for (int i = 0; i < 3; i++) up[i] = -g[i] / norm;
  return 0;
}

void finrft_surface_frame(const double up[3], double frame[9]) {
  double a[3] = {fabs(up[0]) > 0.9 ? 0 : 1, fabs(up[0]) > 0.9 ? 1 : 0, 0};
  double along = a[0] * up[0] + a[1] * up[1] + a[2] * up[2], x[3], length = 0;
  for (int i = 0; i < 3; i++) {
    x[i] = a[i] - along * up[i];
    length += x[i] * x[i];
  }
  length = sqrt(length);
  for (int i = 0; i < 3; i++) {
    frame[i] = x[i] / length;
    frame[6 + i] = up[i];
  }
  frame[3] = up[1] * frame[2] - up[2] * frame[1];
  frame[4] = up[2] * frame[0] - up[0] * frame[2];
  frame[5] = up[0] * frame[1] - up[1] * frame[0];
}

int finrft_plane_depth(const double point[3], const double normal[3], const double g[3], int n, const double* points,
                       double* depth) {
  double up[3], nrm[3];
  double length = sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
  if (finrft_surface_up(g, up) || !isfinite(length) || length == 0) return FINRFT_SURFACE_BAD_INPUT;
  for (int i = 0; i < 3; i++) nrm[i] = normal[i] / length;
  double facing = nrm[0] * up[0] + nrm[1] * up[1] + nrm[2] * up[2];
  if (!(facing > 0)) return FINRFT_SURFACE_BAD_INPUT;
  for (int k = 0; k < n; k++) {
    const double* p = points + 3 * k;
    depth[k] = ((point[0] - p[0]) * nrm[0] + (point[1] - p[1]) * nrm[1] + (point[2] - p[2]) * nrm[2]) / facing;
  }
  return 0;
}
