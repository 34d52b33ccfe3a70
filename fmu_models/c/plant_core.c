/* pendulum-cosim: FMI-independent core of a plant FMU (see plant_core.h). */
#include <math.h>
#include <string.h>
#include "plant_core.h"
#include "model_funcs.h"

void plant_defaults(PlantData *d) {
    memset(d, 0, sizeof(*d));
    for (int k = 0; k < NP; k++) d->p[k] = PARAM_DEFAULT[k];
    for (int k = 0; k < NX; k++) d->x[k] = X_START[k];
    d->step_size = DEFAULT_STEP_SIZE;
    d->integrator = INTEGRATOR_EULER;
    d->substeps = 1;
}

const char *plant_check_param(int k, double v) {
    if (!isfinite(v)) return "must be finite";
    switch (PARAM_DOMAIN[k]) {
    case DOMAIN_POSITIVE: return v > 0 ? NULL : "must be > 0";
    case DOMAIN_NONNEGATIVE: return v >= 0 ? NULL : "must be >= 0";
    case DOMAIN_SIGN: return (v == 1.0 || v == -1.0) ? NULL : "must be -1 or +1";
    default: return NULL;
    }
}

void plant_f(PlantWork *wk, const PlantData *d, const double *x, double *xdot) {
    wk->arg[0] = x; wk->arg[1] = d->u; wk->arg[2] = d->p;
    wk->res[0] = xdot;
    mdl_f(wk->arg, wk->res, wk->iw, wk->w, 0);
}

void plant_h(PlantWork *wk, const PlantData *d, double *y) {
    wk->arg[0] = d->x; wk->arg[1] = d->p;
    wk->res[0] = y;
    mdl_h(wk->arg, wk->res, wk->iw, wk->w, 0);
}

void plant_jacobians(PlantWork *wk, const PlantData *d, double *A, double *B, double *H) {
    wk->arg[0] = d->x; wk->arg[1] = d->u; wk->arg[2] = d->p;
    wk->res[0] = A; wk->res[1] = B;
    mdl_jac_f(wk->arg, wk->res, wk->iw, wk->w, 0);
    wk->arg[0] = d->x; wk->arg[1] = d->p;
    wk->res[0] = H;
    mdl_jac_h(wk->arg, wk->res, wk->iw, wk->w, 0);
}

/* One step of length T from x into xn (may alias x). Same arithmetic as PlantModel.step. */
static void one_step(PlantWork *wk, const PlantData *d, double T, double *x) {
    double k1[NX], k2[NX], k3[NX], k4[NX], z[NX];
    plant_f(wk, d, x, k1);
    if (d->integrator == INTEGRATOR_EULER) {
        for (int i = 0; i < NX; i++) x[i] = x[i] + T * k1[i];
        return;
    }
    for (int i = 0; i < NX; i++) z[i] = x[i] + (T / 2) * k1[i];
    plant_f(wk, d, z, k2);
    for (int i = 0; i < NX; i++) z[i] = x[i] + (T / 2) * k2[i];
    plant_f(wk, d, z, k3);
    for (int i = 0; i < NX; i++) z[i] = x[i] + T * k3[i];
    plant_f(wk, d, z, k4);
    for (int i = 0; i < NX; i++) x[i] = x[i] + (T / 6) * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
}

int plant_advance(PlantWork *wk, PlantData *d, double h) {
    double x[NX];
    double T = d->step_size / d->substeps;
    double ratio = h / T;
    double n = floor(ratio + 0.5), rest = 0.0;
    /* a communication step that is not a whole number of internal steps ends with a
     * partial step of the remaining length */
    if (fabs(ratio - n) > 1e-9 * fmax(1.0, ratio)) {
        n = floor(ratio);
        rest = h - n * T;
    }
    memcpy(x, d->x, sizeof(x));
    for (long k = 0; k < (long)n; k++) one_step(wk, d, T, x);
    if (rest > 0) one_step(wk, d, rest, x);
    for (int i = 0; i < NX; i++) {
        x[i] += d->w[i];
        if (!isfinite(x[i])) return 1;
    }
    memcpy(d->x, x, sizeof(x));
    d->time += h;
    return 0;
}
