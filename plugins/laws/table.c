// Law "table": F = -tanh(|v|/v_reg) (F_perp(theta) sgn(v^.y^) y^ + F_par(theta) sgn(v^.x^) x^), the magnitudes
// interpolated linearly in the angle of attack theta. The twin of finrft/laws/table.py.
//
// Config `table`: "attack_deg f_perp f_par ..." triples, attack increasing over 0..90 degrees.

#include <math.h>
#include <stdlib.h>

#include "../finrft.h"

typedef struct {
  int n;
  mjtNum* attack;  // radians
  mjtNum* perp;
  mjtNum* par;
} Table;

static const char* kKeys[] = {"table"};

static void destroy(void* params) {
  Table* t = (Table*)params;
  if (!t) return;
  free(t->attack);
  free(t->perp);
  free(t->par);
  free(t);
}

static void* create(const mjModel* m, int instance) {
  const char* text = mj_getPluginConfig(m, instance, "table");
  if (!text || !text[0]) {
    mju_warning("finrft.rft: law 'table' needs config 'table' (attack_deg f_perp f_par triples)");
    return NULL;
  }
  int capacity = 16, count = 0;
  mjtNum* values = (mjtNum*)malloc(capacity * sizeof(mjtNum));
  const char* cursor = text;
  while (values) {
    char* end = NULL;
    double value = strtod(cursor, &end);
    if (end == cursor) break;
    if (!isfinite(value)) {
      free(values);
      mju_warning("finrft.rft: config 'table' holds a non-finite value");
      return NULL;
    }
    if (count == capacity) {
      capacity *= 2;
      mjtNum* grown = (mjtNum*)realloc(values, capacity * sizeof(mjtNum));
      if (!grown) break;
      values = grown;
    }
    values[count++] = value;
    cursor = end;
  }
  while (cursor && (*cursor == ' ' || *cursor == '\t' || *cursor == '\n')) cursor++;
  int bad = !values || (cursor && *cursor) || count < 6 || count % 3;
  int n = count / 3;
  for (int i = 1; !bad && i < n; i++) bad = values[3 * i] <= values[3 * (i - 1)];
  if (!bad) bad = values[0] > 0 || values[3 * (n - 1)] < 90;
  Table* t = bad ? NULL : (Table*)calloc(1, sizeof(Table));
  if (t) {
    t->n = n;
    t->attack = (mjtNum*)malloc(n * sizeof(mjtNum));
    t->perp = (mjtNum*)malloc(n * sizeof(mjtNum));
    t->par = (mjtNum*)malloc(n * sizeof(mjtNum));
    if (!t->attack || !t->perp || !t->par) {
      destroy(t);
      t = NULL;
    }
  }
  for (int i = 0; t && i < n; i++) {
    t->attack[i] = values[3 * i] * (mjPI / 180.0);
    t->perp[i] = values[3 * i + 1];
    t->par[i] = values[3 * i + 2];
  }
  free(values);
  if (bad) {
    mju_warning("finrft.rft: config 'table' must hold numeric triples 'attack_deg f_perp f_par' with the "
                "angle increasing over 0..90 degrees");
  }
  return t;
}

// Linear interpolation with the end values held outside the range, in numpy.interp's arithmetic.
static mjtNum interp(mjtNum x, const mjtNum* xs, const mjtNum* ys, int n) {
  if (x <= xs[0]) return ys[0];
  if (x >= xs[n - 1]) return ys[n - 1];
  int lo = 0, hi = n - 1;
  while (hi - lo > 1) {
    int mid = (lo + hi) / 2;
    if (xs[mid] <= x) lo = mid; else hi = mid;
  }
  mjtNum slope = (ys[hi] - ys[lo]) / (xs[hi] - xs[lo]);
  return slope * (x - xs[lo]) + ys[lo];
}

static void force(const void* params, mjtNum v_reg, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                  mjtNum f[3]) {
  const Table* t = (const Table*)params;
  mjtNum ramp, vx, vy;
  finrft_components(v_reg, v, x, y, &ramp, &vx, &vy);
  mjtNum attack = atan2(fabs(vy), fabs(vx));
  mjtNum cy = interp(attack, t->attack, t->perp, t->n) * ((vy > 0) - (vy < 0));
  mjtNum cx = interp(attack, t->attack, t->par, t->n) * ((vx > 0) - (vx < 0));
  for (int k = 0; k < 3; k++) f[k] = -ramp * (cy * y[k] + cx * x[k]);
}

const FinrftLaw finrft_law_table = {"table", kKeys, 1, create, destroy, force};
