// The horizontal free surface z = surface_z: the twin of finrft/surfaces/flat.py.

#include "surfaces.h"

int finrft_flat_depth(double surface_z, const double g[3], int n, const double* points, double* depth) {
  const double point[3] = {0, 0, surface_z}, normal[3] = {0, 0, 1};
  return finrft_plane_depth(point, normal, g, n, points, depth);
}
