// Law "sandswim": the sand-swimming RFT of Maladen et al. 2009, with k = cot(gamma0),
// F = -tanh(|v|/v_reg) ((c_s k (v^.y^) / sqrt(1 + k^2 (v^.y^)^2) + c_f (v^.y^)) y^ + c_f (v^.x^) x^).
// The twin of finrft/laws/sandswim.py.

#include <math.h>
#include <stdlib.h>

#include "../finrft.h"

typedef struct {
  mjtNum c_s, c_f, k;
} Sandswim;

static const char* kKeys[] = {"c_s", "c_f", "gamma0"};

static void* create(const mjModel* m, int instance) {
  Sandswim* p = (Sandswim*)calloc(1, sizeof(Sandswim));
  mjtNum gamma0 = 0;
  if (p && (finrft_read_number(m, instance, "c_s", &p->c_s) || finrft_read_number(m, instance, "c_f", &p->c_f) ||
            finrft_read_number(m, instance, "gamma0", &gamma0))) {
    free(p);
    return NULL;
  }
  if (p) p->k = cos(gamma0) / sin(gamma0);
  return p;
}

static void force(const void* params, mjtNum v_reg, const mjtNum v[3], const mjtNum x[3], const mjtNum y[3],
                  mjtNum f[3]) {
  const Sandswim* p = (const Sandswim*)params;
  mjtNum ramp, vx, vy;
  finrft_components(v_reg, v, x, y, &ramp, &vx, &vy);
  mjtNum ky = p->k * vy;
  mjtNum cy = p->c_s * ky / sqrt(1 + ky * ky) + p->c_f * vy, cx = p->c_f * vx;
  for (int k = 0; k < 3; k++) f[k] = -ramp * (cy * y[k] + cx * x[k]);
}

const FinrftLaw finrft_law_sandswim = {"sandswim", kKeys, 3, create, free, force};
