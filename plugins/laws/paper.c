// Law "paper": F = -tanh(|v|/v_reg) (f_perp (v^.y^) y^ + f_par (v^.x^) x^). The twin of finrft/laws/paper.py.

#include <stdlib.h>

#include "../finrft.h"

typedef struct {
  mjtNum f_perp, f_par;
} Paper;

static const char* kKeys[] = {"f_perp", "f_par"};

static void* create(const mjModel* m, int instance) {
  Paper* p = (Paper*)calloc(1, sizeof(Paper));
  if (p && (finrft_read_number(m, instance, "f_perp", &p->f_perp) ||
            finrft_read_number(m, instance, "f_par", &p->f_par))) {
    free(p);
    return NULL;
  }
  return p;
}

static void force(const void* params, mjtNum v_reg, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                  mjtNum f[3]) {
  const Paper* p = (const Paper*)params;
  mjtNum ramp, vx, vy;
  finrft_components(v_reg, v, x, y, &ramp, &vx, &vy);
  mjtNum cy = p->f_perp * vy, cx = p->f_par * vx;
  for (int k = 0; k < 3; k++) f[k] = -ramp * (cy * y[k] + cx * x[k]);
}

const FinrftLaw finrft_law_paper = {"paper", kKeys, 2, create, free, force};
