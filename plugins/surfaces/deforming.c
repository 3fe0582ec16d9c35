// A heightfield whose heights are state, displaced by the body and relaxed to the angle of repose: the twin of
// finrft/surfaces/deforming.py (its docstring gives the model).

#include <math.h>
#include <stdlib.h>
#include <string.h>

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

void finrft_deforming_grid(FinrftDeformingGrid* g, int nrow, int ncol, const double* heights,
                           const double* original, double pile_factor, const double size[2], const double centre[3],
                           const double frame[9]) {
  g->grid = make_grid(nrow, ncol, heights, size, centre, frame);
  g->original = original;
  g->pile_factor = pile_factor;
  g->scale[0] = (ncol - 1) / (2 * size[0]);
  g->scale[1] = (nrow - 1) / (2 * size[1]);
}

// The grid's (u, v) of (x, y), within it (beyond it, the nearest edge's), its cell's first point and the place in it.
static inline void cell_of(const FinrftDeformingGrid* g, double x, double y, int* i, double* fu, double* fv) {
  int nrow = g->grid.nrow, ncol = g->grid.ncol;
  double u = (x + g->grid.size[0]) * g->scale[0], v = (y + g->grid.size[1]) * g->scale[1];
  u = u > 0 ? (u < ncol - 1 ? u : ncol - 1) : 0;  // (NaN to 0: a point no grid can place)
  v = v > 0 ? (v < nrow - 1 ? v : nrow - 1) : 0;
  int c = (int)u, r = (int)v;  // floor: u, v >= 0
  if (c > ncol - 2) c = ncol - 2;
  if (r > nrow - 2) r = nrow - 2;
  *i = r * ncol + c;
  *fu = u - c;
  *fv = v - r;
}

// Linear along x on the cell's two rows, then along y (the twin's weights, rounded otherwise).
static inline double bilinear(const double* h, int ncol, int i, double fu, double fv) {
  double a = h[i] + fu * (h[i + 1] - h[i]), b = h[i + ncol] + fu * (h[i + ncol + 1] - h[i + ncol]);
  return a + fv * (b - a);
}

// The depth at height z of the point at place (fu, fv) of the cell whose first point is i.
static inline double depth_in(const FinrftDeformingGrid* g, int i, double fu, double fv, double z, int submerged_only) {
  int ncol = g->grid.ncol;
  double deformed = bilinear(g->grid.heights, ncol, i, fu, fv) - z;
  if (!(g->pile_factor > 0) || (submerged_only && !(deformed > 0))) return deformed;
  double below_original = bilinear(g->original, ncol, i, fu, fv) - z;
  int pile = deformed > 0 && below_original <= 0;
  return pile ? g->pile_factor * deformed : (deformed < below_original ? deformed : below_original);
}

static inline double local_depth(const FinrftDeformingGrid* g, const double local[3], int submerged_only) {
  int i;
  double fu, fv;
  cell_of(g, local[0], local[1], &i, &fu, &fv);
  return depth_in(g, i, fu, fv, local[2], submerged_only);
}

void finrft_deforming_body_depths(const FinrftDeformingGrid* g, const double at[3], const double turn[9],
                                  const double extent[3], int n, const double* centres, double* depth) {
  // the body's box turned into the grid's frame, held in a box along the grid's axes
  double half[2];
  for (int j = 0; j < 2; j++) {
    half[j] = fabs(turn[3 * j]) * extent[0] + fabs(turn[3 * j + 1]) * extent[1] + fabs(turn[3 * j + 2]) * extent[2];
  }
  double low[2] = {at[0] - half[0], at[1] - half[1]}, high[2] = {at[0] + half[0], at[1] + half[1]};
  double top = finrft_deforming_top(g, low, high) - at[2];  // as the elements' heights, from `at`
  const double *x = centres, *y = centres + n, *z = centres + 2 * n;
  // every element's height, in one pass the compiler vectorises; those below the top, interpolated
  for (int i = 0; i < n; i++) depth[i] = turn[6] * x[i] + turn[7] * y[i] + turn[8] * z[i];
  // A body a cell within the grid's edges places its elements without clamping them to it.
  const double *size = g->grid.size, *scale = g->scale;
  int ncol = g->grid.ncol, within = (low[0] + size[0]) * scale[0] >= 1 && (low[1] + size[1]) * scale[1] >= 1 &&
                                    (high[0] + size[0]) * scale[0] <= ncol - 2 &&
                                    (high[1] + size[1]) * scale[1] <= g->grid.nrow - 2;
  for (int i = 0; i < n; i++) {
    double height = depth[i];
    if (height >= top) {
      depth[i] = top - height;
      continue;
    }
    double local[3] = {at[0] + turn[0] * x[i] + turn[1] * y[i] + turn[2] * z[i],
                       at[1] + turn[3] * x[i] + turn[4] * y[i] + turn[5] * z[i], at[2] + height};
    if (!within) {
      depth[i] = local_depth(g, local, 1);
      continue;
    }
    double u = (local[0] + size[0]) * scale[0], v = (local[1] + size[1]) * scale[1];
    int c = (int)u, r = (int)v;  // floor: u, v >= 1
    depth[i] = depth_in(g, r * ncol + c, u - c, v - r, local[2], 1);
  }
}

double finrft_deforming_top(const FinrftDeformingGrid* g, const double low[2], const double high[2]) {
  int i0, i1;
  double fu, fv;
  cell_of(g, low[0], low[1], &i0, &fu, &fv);
  cell_of(g, high[0], high[1], &i1, &fu, &fv);
  int ncol = g->grid.ncol, r0 = i0 / ncol, c0 = i0 % ncol, r1 = i1 / ncol + 1, c1 = i1 % ncol + 1;
  const double* h = g->grid.heights;
  double top = h[i0];
  for (int r = r0; r <= r1; r++) {
    for (int c = c0; c <= c1; c++) top = h[r * ncol + c] > top ? h[r * ncol + c] : top;
  }
  return top;
}

int finrft_deforming_depth(int nrow, int ncol, const double* heights, const double* original, double pile_factor,
                           const double size[2], const double centre[3], const double frame[9], const double g[3],
                           int n, const double* points, double* depth) {
  FinrftDeformingGrid grid;
  finrft_deforming_grid(&grid, nrow, ncol, heights, original, pile_factor, size, centre, frame);
  if (finrft_grid_check(&grid.grid, g) || !(isfinite(pile_factor) && pile_factor >= 0) ||
      (pile_factor > 0 && !original)) {
    return FINRFT_SURFACE_BAD_INPUT;
  }
  for (int k = 0; k < n; k++) {
    double local[3];
    finrft_grid_local(&grid.grid, points + 3 * k, local);
    depth[k] = local_depth(&grid, local, 0);
  }
  return 0;
}

// The first grid point not under the body from (r, c) along (sx, sy) in steps of the finer spacing; the last one
// on the grid should the march leave it first.
static int march(const unsigned char* occupied, int nrow, int ncol, int r, int c, double sx, double sy, double dx,
                 double dy) {
  double step = dx < dy ? dx : dy, du = step * sx / dx, dv = step * sy / dy;
  int last = r * ncol + c;
  for (int s = 1; s <= nrow + ncol; s++) {
    // the nearest point's column and row are floor(u) and floor(v), on the grid exactly when 0 <= u < ncol and
    // 0 <= v < nrow, where truncation is the floor
    double u = c + s * du + 0.5, v = r + s * dv + 0.5;
    if (!(u >= 0 && u < ncol && v >= 0 && v < nrow)) return last;
    int cc = (int)u, rr = (int)v;
    if (rr != r || cc != c) {
      last = rr * ncol + cc;
      if (!occupied[last]) return last;
    }
  }
  return last;
}

// The box (r0, r1, c0, c1) grown to hold the point i.
static void grow(int box[4], int ncol, int i) {
  int r = i / ncol, c = i % ncol;
  if (r < box[0]) box[0] = r;
  if (r > box[1]) box[1] = r;
  if (c < box[2]) box[2] = c;
  if (c > box[3]) box[3] = c;
}

// The box grown by one point each way within the grid (none stays none).
static void widen(int box[4], int nrow, int ncol) {
  if (box[0] > box[1]) return;
  box[0] = box[0] > 0 ? box[0] - 1 : 0;
  box[1] = box[1] < nrow - 1 ? box[1] + 1 : nrow - 1;
  box[2] = box[2] > 0 ? box[2] - 1 : 0;
  box[3] = box[3] < ncol - 1 ? box[3] + 1 : ncol - 1;
}

// The box grown to hold the box `other`.
static void join(int box[4], const int other[4]) {
  if (other[0] > other[1]) return;
  if (other[0] < box[0]) box[0] = other[0];
  if (other[1] > box[1]) box[1] = other[1];
  if (other[2] < box[2]) box[2] = other[2];
  if (other[3] > box[3]) box[3] = other[3];
}

// The sweep (finrft_deforming_sweep's) with compaction: of the sand each point loses, the share `compaction` stays
// under it, compacted (added to compacted[i], a height of sand at its bulk density; compacted may be NULL only when
// compaction is 0), and the rest goes to the berm. `changed` (rows r0..r1, columns c0..c1; r0 > r1: none) holds
// every point whose height or occupation it set: the footprints' box, and one point beyond it, where a berm's march
// ends (its first point not under the body, next to one that is, or the last on the grid).
static int sweep(int nrow, int ncol, double* heights, const double size[2], const double frame[9], int n,
                 const double* local, const double* areas, const double* velocities, double front_share,
                 double compaction, double* compacted, unsigned char* occupied, int changed[4]) {
  if (!(front_share >= 0 && front_share <= 1) || !(compaction >= 0 && compaction <= 1) ||
      (compaction > 0 && !compacted)) {
    return FINRFT_SURFACE_BAD_INPUT;
  }
  double *target = NULL, *direction = NULL;
  int cells = nrow * ncol;
  double dx = 2 * size[0] / (ncol - 1), dy = 2 * size[1] / (nrow - 1), top = heights[0];
  for (int i = 1; i < cells; i++) top = heights[i] > top ? heights[i] : top;
  // Each element's footprint: its disc's grid points and the nearest one. The elements above every point lower
  // none and are over none; the rest's footprints (rows r0..r1, columns c0..c1, the nearest point's row and column,
  // kept for the second pass with the element) lie in one box, the only points this sweep reads or changes.
  int box[4] = {nrow, -1, ncol, -1}, nlow = 0;
  int* footprint = malloc(sizeof(int) * 7 * (n > 0 ? n : 1));
  if (!footprint) return FINRFT_SURFACE_BAD_INPUT;
  for (int e = 0; e < n; e++) {
    const double* p = local + 3 * e;
    if (p[2] > top + TOUCH) continue;
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
    int lo_r = r0 < rn ? r0 : rn, hi_r = r1 > rn ? r1 : rn, lo_c = c0 < cn ? c0 : cn, hi_c = c1 > cn ? c1 : cn;
    if (lo_r < box[0]) box[0] = lo_r;
    if (hi_r > box[1]) box[1] = hi_r;
    if (lo_c < box[2]) box[2] = lo_c;
    if (hi_c > box[3]) box[3] = hi_c;
    int* f = footprint + 7 * nlow++;
    f[0] = e, f[1] = r0, f[2] = r1, f[3] = c0, f[4] = c1, f[5] = rn, f[6] = cn;
  }
  if (box[1] >= 0) {  // some element below the highest point
    target = malloc(sizeof(double) * 3 * cells);  // the lowest element's height, then its direction
    if (!target) {
      free(footprint);
      return FINRFT_SURFACE_BAD_INPUT;
    }
    direction = target + cells;
    for (int r = box[0]; r <= box[1]; r++) {
      for (int i = r * ncol + box[2]; i <= r * ncol + box[3]; i++) {
        target[i] = INFINITY;
        direction[2 * i] = direction[2 * i + 1] = 0;
      }
    }
  }
  for (int k = 0; k < nlow; k++) {
    const int* f = footprint + 7 * k;
    int e = f[0], r0 = f[1], r1 = f[2], c0 = f[3], c1 = f[4], rn = f[5], cn = f[6];
    const double* p = local + 3 * e;
    double radius = sqrt((areas[e] > 0 ? areas[e] : 0) / M_PI);
    double v[3];
    const double* vw = velocities + 3 * e;
    for (int j = 0; j < 3; j++) v[j] = vw[0] * frame[j] + vw[1] * frame[3 + j] + vw[2] * frame[6 + j];
    double speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), horizontal = hypot(v[0], v[1]);
    double d[2] = {0, 0};
    if (horizontal > STRAIGHT_DOWN * speed && horizontal > 0) {
      d[0] = v[0] / horizontal;
      d[1] = v[1] / horizontal;
    }
    // the footprint's points row by row, then the nearest point should the disc miss it (as the twin appends it)
    int nearest_seen = 0;
    for (int again = 0; again < 2; again++) {
      for (int r = again ? rn : r0; r <= (again ? rn : r1); r++) {
        for (int c = again ? cn : c0; c <= (again ? cn : c1); c++) {
          if (!again) {
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
  free(footprint);
  memset(occupied, 0, cells);
  for (int j = 0; j < 4; j++) changed[j] = box[j];
  widen(changed, nrow, ncol);
  if (!target) return 0;
  double* removed = target;  // reused in place: the height each point loses
  for (int r = box[0]; r <= box[1]; r++) {
    for (int i = r * ncol + box[2]; i <= r * ncol + box[3]; i++) {
      occupied[i] = target[i] <= heights[i] + TOUCH;
      double lost = target[i] < heights[i] ? heights[i] - target[i] : 0;
      if (target[i] < heights[i]) heights[i] = target[i];
      removed[i] = lost;
    }
  }
  double side = 0.5 * (1 - front_share);
  for (int r = box[0]; r <= box[1]; r++) {
    for (int c = box[2]; c <= box[3]; c++) {
      int i = r * ncol + c;
      if (removed[i] == 0) continue;
      if (compaction > 0) {
        compacted[i] += compaction * removed[i];
        removed[i] *= 1 - compaction;
      }
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
  }
  free(target);
  return 0;
}

int finrft_deforming_sweep(int nrow, int ncol, double* heights, const double size[2], const double centre[3],
                           const double frame[9], const double g[3], int n, const double* points,
                           const double* areas, const double* velocities, double front_share,
                           unsigned char* occupied) {
  FinrftGrid grid = make_grid(nrow, ncol, heights, size, centre, frame);
  if (finrft_grid_check(&grid, g)) return FINRFT_SURFACE_BAD_INPUT;
  double* local = malloc(sizeof(double) * 3 * (n > 0 ? n : 1));
  if (!local) return FINRFT_SURFACE_BAD_INPUT;
  for (int e = 0; e < n; e++) finrft_grid_local(&grid, points + 3 * e, local + 3 * e);
  int changed[4];
  int failed = sweep(nrow, ncol, heights, size, frame, n, local, areas, velocities, front_share, 0, NULL, occupied,
                     changed);
  free(local);
  return failed;
}

// The edges that flow (2 a: from point a along x, 2 a + 1: along y), their first points' columns and their flows
// (from the first point to the second).
typedef struct {
  int *edge, *column;
  double* flow;
} Flows;

// Whether the edge from point a (in column c) to a + offset (1: along x, ncol: along y) is steeper than `rise` by
// more than `over` with neither end blocked: then it is entry n of `flows` (the count is the caller's: kept in the
// struct, every entry's store might change it, and the compiler would reload it).
static inline int add_if_flowing(Flows flows, int n, const double* heights, const unsigned char* blocked, int a,
                                 int offset, double rise, double over, int c) {
  int b = a + offset;
  double step = heights[b] - heights[a], excess = fabs(step) - rise;
  if (!(excess > over) || (blocked && (blocked[a] || blocked[b]))) return 0;
  flows.edge[n] = 2 * a + (offset != 1);
  flows.column[n] = c;
  flows.flow[n] = -copysign(RELAX_RATE * excess, step);
  return 1;
}

// Only an edge steeper than the tolerance flows, and only edges next to a point that changed in the last iteration
// can start to (one that did not change kept its excess, and one with excess moved sand), so the first iteration
// looks at the edges of the points in `box` and each later one at those of the points the last one changed: the
// same heights as the twin's sweep over the whole grid, at the cost of the flowing edges. `box` (rows r0..r1,
// columns c0..c1) holds at the start every edge that may flow, and at the end those that still would (r0 > r1:
// none); `touched`, when not NULL, grows to hold every point whose height changed. The iterations taken, or -1
// (also when out of memory, the heights as they were).
static int relax_box(int nrow, int ncol, double* heights, double dx, double dy, double slope,
                     const unsigned char* blocked, double tolerance, int max_iterations, int box[4], int touched[4]) {
  int cells = nrow * ncol, result = -1, npoint = 0, low = cells, high = -1, left = ncol, right = -1;
  // the points whose edges are looked at and their columns (carried along, as `touched` needs them), the flowing
  // edges, and the iteration (from 1) whose list a point is on
  int* points = malloc(sizeof(int) * 6 * cells);
  double* flow = malloc(sizeof(double) * 2 * cells);
  int* listed = calloc(cells, sizeof(int));
  if (!points || !flow || !listed) {
    free(points), free(flow), free(listed);
    return -1;
  }
  int* columns = points + cells;
  Flows flows = {points + 2 * cells, points + 4 * cells, flow};
  int nflow = 0;
  double rise[2] = {slope * dx, slope * dy}, over[2] = {tolerance * dx, tolerance * dy};
  for (int r = box[0]; r <= box[1]; r++) {
    for (int c = box[2]; c <= box[3]; c++) {
      columns[npoint] = c;
      points[npoint++] = r * ncol + c;
      listed[r * ncol + c] = 1;
    }
  }
  for (int iteration = 0; iteration <= max_iterations; iteration++) {
    int on = iteration + 1, next = iteration + 2;
    nflow = 0;
    for (int k = 0; k < npoint; k++) {
      // the edges to the next point along x and y, and from the previous ones unless those are listed themselves
      int i = points[k], c = columns[k];
      if (c < ncol - 1) nflow += add_if_flowing(flows, nflow, heights, blocked, i, 1, rise[0], over[0], c);
      if (c > 0 && listed[i - 1] != on) {
        nflow += add_if_flowing(flows, nflow, heights, blocked, i - 1, 1, rise[0], over[0], c - 1);
      }
      if (i + ncol < cells) nflow += add_if_flowing(flows, nflow, heights, blocked, i, ncol, rise[1], over[1], c);
      if (i >= ncol && listed[i - ncol] != on) {
        nflow += add_if_flowing(flows, nflow, heights, blocked, i - ncol, ncol, rise[1], over[1], c);
      }
    }
    if (!nflow) {
      result = iteration;
      break;
    }
    if (iteration == max_iterations) break;
    // every flow from the heights the check saw; the points it changes are the next iteration's
    npoint = 0;
    for (int k = 0; k < nflow; k++) {
      int a = flows.edge[k] >> 1, along_y = flows.edge[k] & 1, b = a + (along_y ? ncol : 1), c = flows.column[k];
      heights[a] -= flows.flow[k];
      heights[b] += flows.flow[k];
      if (listed[a] != next) listed[a] = next, columns[npoint] = c, points[npoint++] = a;
      if (listed[b] != next) listed[b] = next, columns[npoint] = c + !along_y, points[npoint++] = b;
      // (edges run from lower to higher indices and columns)
      if (a < low) low = a;
      if (b > high) high = b;
      if (c < left) left = c;
      if (c + !along_y > right) right = c + !along_y;
    }
  }
  if (touched && high >= 0) {
    int changed[4] = {low / ncol, high / ncol, left, right};
    join(touched, changed);
  }
  // where sand would still flow: the points of the edges the last check found steeper than the tolerance
  box[0] = nrow, box[1] = -1, box[2] = ncol, box[3] = -1;
  for (int k = 0; k < nflow; k++) {
    int a = flows.edge[k] >> 1;
    grow(box, ncol, a);
    grow(box, ncol, a + (flows.edge[k] & 1 ? ncol : 1));
  }
  free(points), free(flow), free(listed);
  return result;
}

static int relax_checked(int nrow, int ncol, const double size[2], double repose, double tolerance) {
  return nrow < 2 || ncol < 2 || !(repose > 0 && repose < M_PI / 2) || !(size[0] > 0 && size[1] > 0) ||
         !isfinite(size[0]) || !isfinite(size[1]) || !(tolerance > 0);
}

int finrft_deforming_relax(int nrow, int ncol, double* heights, const double size[2], double repose,
                           const unsigned char* blocked, double tolerance, int max_iterations) {
  if (relax_checked(nrow, ncol, size, repose, tolerance)) return FINRFT_SURFACE_BAD_INPUT;
  int box[4] = {0, nrow - 1, 0, ncol - 1};
  return relax_box(nrow, ncol, heights, 2 * size[0] / (ncol - 1), 2 * size[1] / (nrow - 1), tan(repose), blocked,
                   tolerance, max_iterations, box, NULL);
}

int finrft_deforming_step(FinrftDeforming* s, const double g[3], int n, const double* points, const double* areas,
                          const double* velocities, const double* normals, int imprint, double* removed) {
  int nrow = s->nrow, ncol = s->ncol, cells = nrow * ncol;
  FinrftGrid grid = make_grid(nrow, ncol, s->heights, s->size, s->centre, s->frame);
  // Heights are looked at once, at the imprint: after it every height is one of them, an element's, or sums of
  // finite shares of them, so finite points keep them finite.
  if (relax_checked(nrow, ncol, s->size, s->repose, s->tolerance) || s->step_iterations < 0 ||
      (s->facing && !normals) || (imprint ? finrft_grid_check(&grid, g) : finrft_grid_placed(&grid, g))) {
    return FINRFT_SURFACE_BAD_INPUT;
  }
  for (int k = 0; k < 3 * n; k++) {
    if (!isfinite(points[k]) || !isfinite(velocities[k]) || (s->facing && !isfinite(normals[k]))) {
      return FINRFT_SURFACE_BAD_INPUT;
    }
  }
  // the direction each element pushes its sand along (the sweep takes its horizontal part): with `facing`, a leading
  // element's normal, else its velocity
  double* pushing = NULL;
  if (s->facing) {
    pushing = malloc(sizeof(double) * 3 * (n > 0 ? n : 1));
    if (!pushing) return FINRFT_SURFACE_BAD_INPUT;
    for (int e = 0; e < n; e++) {
      const double *nn = normals + 3 * e, *v = velocities + 3 * e;
      const double* d = nn[0] * v[0] + nn[1] * v[1] + nn[2] * v[2] > 0 ? nn : v;
      for (int j = 0; j < 3; j++) pushing[3 * e + j] = d[j];
    }
  }
  double dx = 2 * s->size[0] / (ncol - 1), dy = 2 * s->size[1] / (nrow - 1);
  // the heights before (cells), and each element in the grid's frame (3 n), once for the marks and the sweep
  double* before = malloc(sizeof(double) * (cells + 3 * n));
  if (!before) {
    free(pushing);
    return FINRFT_SURFACE_BAD_INPUT;
  }
  double* local = before + cells;
  memcpy(before, s->heights, sizeof(double) * cells);
  for (int e = 0; e < n; e++) finrft_grid_local(&grid, points + 3 * e, local + 3 * e);
  // the grid points under the body (DeformingSurface._covered): nearest to an element below the level, and their
  // neighbours; `entered` (was not under before) is read from s->under before it is replaced. `region` grows to
  // hold every point whose height, level or being under the body may change: those under it at the last step
  // (s->held), those under it now, and those the sweep and the relaxation change; elsewhere the level is the height
  // already, and nothing is looked at
  unsigned char* under = s->under;  // 1: under at the last step; 4: under now
  int region[4];
  for (int j = 0; j < 4; j++) region[j] = s->held[j];
  for (int e = 0; e < n; e++) {
    const double* p = local + 3 * e;
    int c = (int)floor((p[0] + s->size[0]) / dx + 0.5), r = (int)floor((p[1] + s->size[1]) / dy + 0.5);
    if (c < 0 || c >= ncol || r < 0 || r >= nrow) continue;
    int i = r * ncol + c;
    if (p[2] < s->level[i] + TOUCH) {  // the point near the element and its neighbours, without a pass over the grid
      under[i] |= 4;
      if (r > 0) under[i - ncol] |= 4;
      if (r < nrow - 1) under[i + ncol] |= 4;
      if (c > 0) under[i - 1] |= 4;
      if (c < ncol - 1) under[i + 1] |= 4;
      int near[4] = {r, r, c, c};
      widen(near, nrow, ncol);
      join(region, near);
    }
  }
  // the imprint is no flow of sand: nothing of it is compacted
  int swept[4];
  int failed = sweep(nrow, ncol, s->heights, s->size, s->frame, n, local, areas, pushing ? pushing : velocities,
                     s->front_share, imprint ? 0 : s->compaction, s->compacted, s->occupied, swept);
  free(pushing);
  if (failed) {
    for (int i = 0; i < cells; i++) under[i] &= 1;
    free(before);
    return failed;
  }
  join(region, swept);
  // what relaxation must look at: the excess left by the last step, and every point the sweep changed or whose
  // being under the body did, with their edges (an edge elsewhere is as the last relaxation left it, without excess)
  int* box = s->dirty;
  join(box, swept);
  join(box, s->held);
  widen(box, nrow, ncol);
  if (box[0] <= box[1]) {
    relax_box(nrow, ncol, s->heights, dx, dy, tan(s->repose), s->occupied, s->tolerance, s->step_iterations, box,
              region);
  }
  if (imprint) region[0] = 0, region[1] = nrow - 1, region[2] = 0, region[3] = ncol - 1;
  double lost = 0;
  int held[4] = {nrow, -1, ncol, -1};
  for (int r = region[0]; r <= region[1]; r++) {
    for (int c = region[2], i = r * ncol + c; c <= region[3]; c++, i++) {
      if (imprint) {
        s->heights[i] = fmin(before[i], s->heights[i]);
        s->original[i] = fmin(s->original[i], s->heights[i]);
      }
      int now = (under[i] & 4) || s->occupied[i], entered = now && !(under[i] & 1);
      under[i] = (unsigned char)now;
      s->level[i] = entered ? before[i] : (now ? s->level[i] : s->heights[i]);
      if (before[i] > s->heights[i]) lost += before[i] - s->heights[i];
      if (now) {
        int point[4] = {r, r, c, c};
        join(held, point);
      }
    }
  }
  for (int j = 0; j < 4; j++) s->held[j] = held[j];
  if (imprint) {  // the imprint lowered points anywhere under the body: every edge may have excess
    box[0] = 0, box[1] = nrow - 1, box[2] = 0, box[3] = ncol - 1;
  }
  *removed = imprint ? 0 : dx * dy * lost;
  free(before);
  return 0;
}
