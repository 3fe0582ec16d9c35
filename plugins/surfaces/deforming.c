// A heightfield whose heights are state, displaced by the body and relaxed to the angle of repose: the twin of
// finrft/surfaces/deforming.py (its docstring gives the model).

#include <math.h>
#include <stdlib.h>

#include "surfaces.h"

#define RELAX_RATE 0.25      // finrft.surfaces.deforming.RELAX_RATE
#define STRAIGHT_DOWN 1e-9   // finrft.surfaces.deforming.STRAIGHT_DOWN
#define TOUCH 1e-9           // finrft.surfaces.deforming.TOUCH

static FinrftGrid make_grid(int nrow, int ncol, const double* heights, const double size[2], const double centre[3],
                            const double frame[9]) {
  FinrftGrid grid = {nrow, ncol, heights, {size[0], size[1]}, {centre[0], centre[1], centre[2]}, {0}};
  for (int i = 0; i < 9; i++) grid.frame[i] = frame[i];
  return grid;
}

int finrft_deforming_depth(int nrow, int ncol, const double* heights, const double* original, double pile_factor,
                           const double size[2], const double centre[3], const double frame[9], const double g[3],
                           int n, const double* points, double* depth) {
  if (finrft_hfield_depth(nrow, ncol, heights, size, centre, frame, g, n, points, depth)) {
    return FINRFT_SURFACE_BAD_INPUT;
  }
  if (pile_factor == 0) return 0;
  if (!(isfinite(pile_factor) && pile_factor > 0) || !original) return FINRFT_SURFACE_BAD_INPUT;
  FinrftGrid grid = make_grid(nrow, ncol, original, size, centre, frame);
  for (int k = 0; k < n; k++) {
    double local[3];
    finrft_grid_local(&grid, points + 3 * k, local);
    double below_original = finrft_grid_height(&grid, original, local[0], local[1]) - local[2];
    int pile = depth[k] > 0 && below_original <= 0;
    depth[k] = pile ? pile_factor * depth[k] : fmin(depth[k], below_original);
  }
  return 0;
}

// The first grid point not under the body from (r, c) along (sx, sy) in steps of the finer spacing; the last one
// on the grid should the march leave it first.
static int march(const unsigned char* occupied, int nrow, int ncol, int r, int c, double sx, double sy, double dx,
                 double dy) {
  double step = dx < dy ? dx : dy;
  int last = r * ncol + c;
  for (int s = 1; s <= nrow + ncol; s++) {
    int cc = (int)floor(c + s * step * sx / dx + 0.5), rr = (int)floor(r + s * step * sy / dy + 0.5);
    if (cc < 0 || cc >= ncol || rr < 0 || rr >= nrow) return last;
    if (rr != r || cc != c) {
      last = rr * ncol + cc;
      if (!occupied[last]) return last;
    }
  }
  return last;
}

int finrft_deforming_sweep(int nrow, int ncol, double* heights, const double size[2], const double centre[3],
                           const double frame[9], const double g[3], int n, const double* points,
                           const double* areas, const double* velocities, double front_share,
                           unsigned char* occupied) {
  FinrftGrid grid = make_grid(nrow, ncol, heights, size, centre, frame);
  if (finrft_grid_check(&grid, g) || !(front_share >= 0 && front_share <= 1)) return FINRFT_SURFACE_BAD_INPUT;
  int cells = nrow * ncol;
  double* target = malloc(sizeof(double) * 3 * cells);  // the lowest element's height, then its direction
  if (!target) return FINRFT_SURFACE_BAD_INPUT;
  double* direction = target + cells;
  for (int i = 0; i < cells; i++) {
    target[i] = INFINITY;
    direction[2 * i] = direction[2 * i + 1] = 0;
  }
  double dx = 2 * size[0] / (ncol - 1), dy = 2 * size[1] / (nrow - 1);
  for (int e = 0; e < n; e++) {
    double p[3], v[3];
    finrft_grid_local(&grid, points + 3 * e, p);
    const double* vw = velocities + 3 * e;
    for (int j = 0; j < 3; j++) v[j] = vw[0] * frame[j] + vw[1] * frame[3 + j] + vw[2] * frame[6 + j];
    double radius = sqrt((areas[e] > 0 ? areas[e] : 0) / M_PI);
    double u = (p[0] + size[0]) / dx, w = (p[1] + size[1]) / dy;
    int cn = (int)floor(u + 0.5), rn = (int)floor(w + 0.5);
    cn = cn < 0 ? 0 : (cn > ncol - 1 ? ncol - 1 : cn);
    rn = rn < 0 ? 0 : (rn > nrow - 1 ? nrow - 1 : rn);
    int c0 = (int)ceil(u - radius / dx), c1 = (int)floor(u + radius / dx);
    int r0 = (int)ceil(w - radius / dy), r1 = (int)floor(w + radius / dy);
    if (c0 < 0) c0 = 0;
    if (r0 < 0) r0 = 0;
    if (c1 > ncol - 1) c1 = ncol - 1;
    if (r1 > nrow - 1) r1 = nrow - 1;
    double speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), horizontal = hypot(v[0], v[1]);
    double d[2] = {0, 0};
    if (horizontal > STRAIGHT_DOWN * speed && horizontal > 0) {
      d[0] = v[0] / horizontal;
      d[1] = v[1] / horizontal;
    }
    // the footprint's points row by row, then the nearest point should the disc miss it (as the twin appends it)
    int nearest_seen = 0;
    for (int pass = 0; pass < 2; pass++) {
      for (int r = pass ? rn : r0; r <= (pass ? rn : r1); r++) {
        for (int c = pass ? cn : c0; c <= (pass ? cn : c1); c++) {
          if (!pass) {
            double ex = c * dx - size[0] - p[0], ey = r * dy - size[1] - p[1];
            if (!(ex * ex + ey * ey <= radius * radius || (r == rn && c == cn))) continue;
            if (r == rn && c == cn) nearest_seen = 1;
          } else if (nearest_seen) {
            continue;
          }
          int i = r * ncol + c;
          if (p[2] < target[i]) {
            target[i] = p[2];
            direction[2 * i] = d[0];
            direction[2 * i + 1] = d[1];
          }
        }
      }
    }
  }
  double* removed = target;  // reused in place: the height each point loses
  for (int i = 0; i < cells; i++) {
    occupied[i] = target[i] <= heights[i] + TOUCH;
    double lost = target[i] < heights[i] ? heights[i] - target[i] : 0;
    if (target[i] < heights[i]) heights[i] = target[i];
    removed[i] = lost;
  }
  double side = 0.5 * (1 - front_share);
  for (int i = 0; i < cells; i++) {
    if (removed[i] == 0) continue;
    int r = i / ncol, c = i % ncol;
    double d0 = direction[2 * i], d1 = direction[2 * i + 1];
    if (d0 == 0 && d1 == 0) {
      heights[march(occupied, nrow, ncol, r, c, 1, 0, dx, dy)] += 0.25 * removed[i];
      heights[march(occupied, nrow, ncol, r, c, -1, 0, dx, dy)] += 0.25 * removed[i];
      heights[march(occupied, nrow, ncol, r, c, 0, 1, dx, dy)] += 0.25 * removed[i];
      heights[march(occupied, nrow, ncol, r, c, 0, -1, dx, dy)] += 0.25 * removed[i];
    } else {
      heights[march(occupied, nrow, ncol, r, c, d0, d1, dx, dy)] += front_share * removed[i];
      heights[march(occupied, nrow, ncol, r, c, -d1, d0, dx, dy)] += side * removed[i];
      heights[march(occupied, nrow, ncol, r, c, d1, -d0, dx, dy)] += side * removed[i];
    }
  }
  free(target);
  return 0;
}

// Only edges next to a point that changed in the last iteration can have sand to move (one that did not change
// kept its excess, and one with excess moved sand), so each iteration looks at the box of the points that changed,
// one point wider: the same heights as the twin's sweep over the whole grid, at the cost of the disturbed region.
int finrft_deforming_relax(int nrow, int ncol, double* heights, const double size[2], double repose,
                           const unsigned char* blocked, double tolerance, int max_iterations) {
  if (nrow < 2 || ncol < 2 || !(repose > 0 && repose < M_PI / 2) || !(size[0] > 0 && size[1] > 0) ||
      !isfinite(size[0]) || !isfinite(size[1]) || !(tolerance > 0)) {
    return FINRFT_SURFACE_BAD_INPUT;
  }
  double dx = 2 * size[0] / (ncol - 1), dy = 2 * size[1] / (nrow - 1), slope = tan(repose);
  int nx = nrow * (ncol - 1);
  double* flow = malloc(sizeof(double) * (nx + (nrow - 1) * ncol));
  if (!flow) return FINRFT_SURFACE_BAD_INPUT;
  int result = -1, r0 = 0, r1 = nrow - 1, c0 = 0, c1 = ncol - 1;  // the box of points to look at
  for (int iteration = 0; iteration <= max_iterations; iteration++) {
    double worst = -INFINITY;
    int cr0 = nrow, cr1 = -1, cc0 = ncol, cc1 = -1;  // the box of points that change
    for (int r = r0; r <= r1; r++) {
      for (int c = c0; c < c1; c++) {
        int i = r * ncol + c, free_edge = !blocked || (!blocked[i] && !blocked[i + 1]);
        double step = heights[i + 1] - heights[i], excess = free_edge ? fabs(step) - slope * dx : 0;
        if (excess / dx > worst) worst = excess / dx;
        flow[r * (ncol - 1) + c] = excess > 0 ? -copysign(RELAX_RATE * excess, step) : 0;
        if (excess > 0) {
          if (r < cr0) cr0 = r;
          if (r > cr1) cr1 = r;
          if (c < cc0) cc0 = c;
          if (c + 1 > cc1) cc1 = c + 1;
        }
      }
    }
    for (int r = r0; r < r1; r++) {
      for (int c = c0; c <= c1; c++) {
        int i = r * ncol + c, free_edge = !blocked || (!blocked[i] && !blocked[i + ncol]);
        double step = heights[i + ncol] - heights[i], excess = free_edge ? fabs(step) - slope * dy : 0;
        if (excess / dy > worst) worst = excess / dy;
        flow[nx + i] = excess > 0 ? -copysign(RELAX_RATE * excess, step) : 0;
        if (excess > 0) {
          if (r < cr0) cr0 = r;
          if (r + 1 > cr1) cr1 = r + 1;
          if (c < cc0) cc0 = c;
          if (c > cc1) cc1 = c;
        }
      }
    }
    if (worst <= tolerance) {
      result = iteration;
      break;
    }
    if (iteration == max_iterations) break;
    for (int r = r0; r <= r1; r++) {
      for (int c = c0; c < c1; c++) {
        double f = flow[r * (ncol - 1) + c];
        heights[r * ncol + c] -= f;
        heights[r * ncol + c + 1] += f;
      }
    }
    for (int r = r0; r < r1; r++) {
      for (int c = c0; c <= c1; c++) {
        int i = r * ncol + c;
        heights[i] -= flow[nx + i];
        heights[i + ncol] += flow[nx + i];
      }
    }
    r0 = cr0 > 0 ? cr0 - 1 : 0;
    r1 = cr1 < nrow - 1 ? cr1 + 1 : nrow - 1;
    c0 = cc0 > 0 ? cc0 - 1 : 0;
    c1 = cc1 < ncol - 1 ? cc1 + 1 : ncol - 1;
  }
  free(flow);
  return result;
}
