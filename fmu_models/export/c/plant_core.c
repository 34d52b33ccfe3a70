/* pendulum-cosim: FMI-independent core of a plant FMU (see plant_core.h, core_api.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "core_api.h"
#include "core_common.h"
#include "model_funcs.h"

#define IN IN_GROUP
#define FAIL(...) do { snprintf(err, ERRLEN, __VA_ARGS__); return 1; } while (0)

void core_defaults(CoreData *d) {
    memset(d, 0, sizeof(*d));
    for (int k = 0; k < NP; k++) d->p[k] = PARAM_DEFAULT[k];
    for (int k = 0; k < NIP; k++) d->ip[k] = IP_DEFAULT[k];
    for (int k = 0; k < NX; k++) d->x[k] = X_START[k];
    d->step_size = DEFAULT_STEP_SIZE;
}

static void plant_f(CoreWork *wk, const CoreData *d, const double *x, const double *u, double *xdot) {
    wk->arg[0] = x; wk->arg[1] = u; wk->arg[2] = d->p;
    wk->res[0] = xdot;
    mdl_f(wk->arg, wk->res, wk->iw, wk->w, 0);
}

static void plant_h(CoreWork *wk, const CoreData *d, double *y) {
    wk->arg[0] = d->x; wk->arg[1] = d->p;
    wk->res[0] = y;
    mdl_h(wk->arg, wk->res, wk->iw, wk->w, 0);
}

static void plant_jacobians(CoreWork *wk, const CoreData *d, double *A, double *B, double *H) {
    wk->arg[0] = d->x; wk->arg[1] = d->u; wk->arg[2] = d->p;
    wk->res[0] = A; wk->res[1] = B;
    mdl_jac_f(wk->arg, wk->res, wk->iw, wk->w, 0);
    wk->arg[0] = d->x; wk->arg[1] = d->p;
    wk->res[0] = H;
    mdl_jac_h(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int core_exit_init(CoreWork *wk, CoreData *d, char *err) {
    (void)wk;
    if (check_parameters(d->p, d->ip, err)) return 1;
    for (int i = 0; i < NX; i++)
        if (!isfinite(d->x[i])) FAIL("start value of %s is not finite", VAR_NAMES[VR_X + i]);
    d->t0 = d->time;
    d->kg = 0;
    return 0;
}

int core_get_real(CoreWork *wk, CoreData *d, const unsigned vr[], size_t n, double v[], char *err) {
    double xdot[NX], y[NY];
    int have_xdot = 0, have_y = 0;
    for (size_t i = 0; i < n; i++) {
        unsigned r = vr[i];
        if (IN(r, VR_DX, NX)) {
            if (!have_xdot) { plant_f(wk, d, d->x, d->u, xdot); have_xdot = 1; }
            v[i] = xdot[r - VR_DX];
        } else if (IN(r, VR_Y, NY)) {
            if (!have_y) { plant_h(wk, d, y); have_y = 1; }
            v[i] = y[r - VR_Y];
        } else if (r == VR_STEP) v[i] = d->step_size;
        else if (IN(r, VR_X, NX)) v[i] = d->x[r - VR_X];
        else if (IN(r, VR_U, NU)) v[i] = d->u[r - VR_U];
        else if (IN(r, VR_W, NX)) v[i] = d->w[r - VR_W];
        else if (get_common_real(d, r, &v[i], err)) return 1;
    }
    return 0;
}

static int set_real(CoreData *d, unsigned r, double v, int before_run, char *err) {
    if (!(IN(r, VR_P, NP) || r == VR_STEP || IN(r, VR_X, NX) || IN(r, VR_DX, NX) || IN(r, VR_U, NU)
          || IN(r, VR_W, NX) || IN(r, VR_Y, NY)))
        FAIL("no settable Real variable has value reference %u", r);
    if (!isfinite(v)) FAIL("%s: value %g is not finite", VAR_NAMES[r], v);
    if (r == VR_STEP) {
        if (before_run != 1) FAIL("step_size is fixed: set it before leaving initialization mode");
        if (!(v > 0)) FAIL("step_size = %g must be > 0", v);
        d->step_size = v;
    } else if (IN(r, VR_X, NX)) {
        if (!before_run)      /* 2: Continuous-Time Mode, where a state may be set (FMI 2.0.1) */
            FAIL("start value of state %s can only be set before leaving initialization mode "
                 "(use the FMU state or SetContinuousStates)", VAR_NAMES[r]);
        d->x[r - VR_X] = v;
    } else if (IN(r, VR_U, NU)) d->u[r - VR_U] = v;
    else if (IN(r, VR_W, NX)) d->w[r - VR_W] = v;
    else return set_common_real(d, r, v, before_run, err);   /* a parameter, or calculated */
    return 0;
}

CORE_SET_REAL_EACH

/* integrator is an Enumeration (FMI 3.0: Int64 functions), substeps an Int32 (model_config.h IP_WIDTH) */
CORE_INT_PARAMETERS(d->ip)

CORE_NO_BOOLEANS

int core_derivatives(CoreWork *wk, const CoreData *d, double dx[], char *err) {
    plant_f(wk, d, d->x, d->u, dx);
    for (int i = 0; i < NX; i++)
        if (!isfinite(dx[i])) FAIL("der(%s) is not finite", VAR_NAMES[VR_X + i]);
    return 0;
}

void core_get_states(const CoreData *d, double x[]) { memcpy(x, d->x, sizeof(double) * NX); }

int core_set_states(CoreData *d, const double x[], size_t nx, char *err) {
    if (nx != NX) FAIL("%zu states given, this model has %d", nx, NX);
    for (size_t i = 0; i < nx; i++)
        if (!isfinite(x[i])) FAIL("state %s = %g is not finite", VAR_NAMES[VR_X + i], x[i]);
    memcpy(d->x, x, sizeof(double) * NX);
    return 0;
}

int core_directional(CoreWork *wk, const CoreData *d, const unsigned unk[], size_t nU,
                      const unsigned kn[], size_t nK, const double seed[], double sens[], char *err) {
    double A[NX * NX], Bm[NX * NU + 1], H[NY * NX];
    for (size_t k = 0; k < nK; k++)
        if (!(IN(kn[k], VR_X, NX) || IN(kn[k], VR_U, NU) || IN(kn[k], VR_W, NX)))
            FAIL("value reference %u is not a state or an input", kn[k]);
    for (size_t i = 0; i < nU; i++)
        if (!(IN(unk[i], VR_DX, NX) || IN(unk[i], VR_Y, NY) || IN(unk[i], VR_X, NX)))
            FAIL("value reference %u is not a derivative or an output", unk[i]);
    plant_jacobians(wk, d, A, Bm, H);
    for (size_t i = 0; i < nU; i++) {
        unsigned r = unk[i];
        double s = 0;
        for (size_t k = 0; k < nK; k++) {
            unsigned q = kn[k];
            double dz = 0;
            if (IN(r, VR_DX, NX)) {
                if (IN(q, VR_X, NX)) dz = A[(r - VR_DX) + NX * (q - VR_X)];
                else if (IN(q, VR_U, NU)) dz = Bm[(r - VR_DX) + NX * (q - VR_U)];
            } else if (IN(r, VR_Y, NY)) {
                if (IN(q, VR_X, NX)) dz = H[(r - VR_Y) + NY * (q - VR_X)];
            } else {
                dz = (q == r) ? 1.0 : 0.0;   /* a state read as an output */
            }
            s += dz * seed[k];
        }
        sens[i] = s;
    }
    return 0;
}

/* One step of length T on x (in place) with input u. Same arithmetic as PlantModel.step. */
static void one_step(CoreWork *wk, const CoreData *d, double T, const double *u, double *x) {
    double k1[NX], k2[NX], k3[NX], k4[NX], z[NX];
    plant_f(wk, d, x, u, k1);
    if (INTEGRATOR(d) == INTEGRATOR_EULER) {
        for (int i = 0; i < NX; i++) x[i] = x[i] + T * k1[i];
        return;
    }
    for (int i = 0; i < NX; i++) z[i] = x[i] + (T / 2) * k1[i];
    plant_f(wk, d, z, u, k2);
    for (int i = 0; i < NX; i++) z[i] = x[i] + (T / 2) * k2[i];
    plant_f(wk, d, z, u, k3);
    for (int i = 0; i < NX; i++) z[i] = x[i] + T * k3[i];
    plant_f(wk, d, z, u, k4);
    for (int i = 0; i < NX; i++) x[i] = x[i] + (T / 6) * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
}

int core_do_step(CoreWork *wk, CoreData *d, double t, double h, char *err) {
    double x[NX], T = d->step_size, t_end = t + h, ratio, steps;
    long long last, k, first;
    if (check_step(t, h, d->time, err)) return 1;
    ratio = h / T * (double)SUBSTEPS(d);
    if (!(ratio <= (double)MAX_INTERNAL_STEPS))
        FAIL("communication step %g s needs %.3g internal steps of %g s, more than the limit of %ld: "
             "use shorter communication steps or a longer step_size", h, ratio, T / (double)SUBSTEPS(d),
             MAX_INTERNAL_STEPS);
    if (instant_of(t_end, d->t0, T, &last, err)) return 1;
    /* the grid steps to make: bounded by the step asked for (kg is the instant of x) */
    steps = ((double)last - (double)d->kg) * (double)SUBSTEPS(d);
    if (steps > (double)MAX_INTERNAL_STEPS + (double)SUBSTEPS(d))
        FAIL("the FMU state is at grid instant %lld, %.3g internal steps before t + h = %g s: more than the limit of %ld",
             d->kg, steps, t_end, MAX_INTERNAL_STEPS);
    /* the inputs as set at the grid instant drive its step (see plant_core.h) */
    if (at_instant(t, d->t0, T, d->kg)) {
        memcpy(d->u_g, d->u, sizeof(double) * NU);
        memcpy(d->w_g, d->w, sizeof d->w_g);
    }
    memcpy(x, d->x, sizeof(x));
    first = d->kg;
    for (k = first; k < last; k++) {
        for (long long s = 0; s < SUBSTEPS(d); s++) one_step(wk, d, T / (double)SUBSTEPS(d), d->u_g, x);
        for (int i = 0; i < NX; i++) {
            x[i] += d->w_g[i];
            if (!isfinite(x[i]))
                FAIL("the state became non-finite (%s) in the step from t = %g s to %g s; state kept at t = %g s",
                     VAR_NAMES[VR_X + i], d->t0 + (double)k * T, d->t0 + (double)(k + 1) * T, t);
        }
        /* later instants inside this communication step: the inputs as held */
        memcpy(d->u_g, d->u, sizeof(double) * NU);
        memcpy(d->w_g, d->w, sizeof d->w_g);
    }
    memcpy(d->x, x, sizeof(x));
    if (last > d->kg) d->kg = last;
    d->time = t_end;
    return 0;
}

int core_check(const CoreData *d, char *err) {
    if (!isfinite(d->time) || !isfinite(d->t0)) FAIL("the FMU state is invalid: its time is not finite");
    if (check_parameters(d->p, d->ip, err)) return 1;
    if (!(d->step_size > 0) || !isfinite(d->step_size)) FAIL("the FMU state is invalid: step_size %g", d->step_size);
    if (!(d->kg >= 0 && (double)d->kg <= MAX_INSTANTS)) FAIL("the FMU state is invalid: grid instant %lld", d->kg);
    if (check_finite(d->x, NX, "x", err) || check_finite(d->u, NU, "u", err) || check_finite(d->w, NX, "w", err)
        || check_finite(d->u_g, NU, "u_g", err) || check_finite(d->w_g, NX, "w_g", err))
        return 1;
    return 0;
}
