/* pendulum-cosim: FMI-independent core of an estimator FMU (see filter_core.h, core_api.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "core_api.h"
#include "core_common.h"
#include "model_funcs.h"

#define IN IN_GROUP
#define FAIL(...) do { snprintf(err, ERRLEN, __VA_ARGS__); return 1; } while (0)

/* where a step argument comes from / a step result goes to (model_config.h tables) */
enum { SRC_STATE = 0, SRC_U = 1, SRC_Y = 2, SRC_MASK = 3, SRC_FIXED = 4 };
enum { DST_STATE = 0, DST_DIAG = 1, DST_STATUS = 2, DST_DROP = 3 };
enum { OUT_STATE = 0, OUT_DIAG = 1, OUT_FIXED = 2 };

void core_defaults(CoreData *d) {
    memset(d, 0, sizeof(*d));
    for (int k = 0; k < NP; k++) d->p[k] = PARAM_DEFAULT[k];
    for (int j = 0; j < NY; j++) d->valid[j] = 1;
}

int core_exit_init(CoreWork *wk, CoreData *d, char *err) {
    double stamp[1];
    if (check_parameters(d->p, NULL, err)) return 1;
    for (int i = 0; i < N_LESS; i++)
        if (!(d->p[LESS_LO[i]] < d->p[LESS_HI[i]]))
            FAIL("parameter %s = %g must be below %s = %g", VAR_NAMES[VR_P + LESS_LO[i]], d->p[LESS_LO[i]],
                 VAR_NAMES[VR_P + LESS_HI[i]], d->p[LESS_HI[i]]);
    /* flt_init(p) -> the state arrays and the fixed inputs, at their offsets */
    wk->arg[0] = d->p;
    for (int j = 0; j < INIT_NOUT; j++)
        wk->res[j] = (INIT_DST[j] == 0 ? d->state : d->fixed) + INIT_OFF[j];
    wk->res[INIT_NOUT] = stamp;
    flt_init(wk->arg, wk->res, wk->iw, wk->w, 0);
    if (stamp[0] != 0) FAIL("the initial covariances are not valid (non-finite after the parameters' mapping)");
    memset(d->diag, 0, sizeof d->diag);
    d->t0 = d->time;
    d->kc = 0;
    d->cand_ok = 0;
    memset(&d->clk, 0, sizeof d->clk);
    return 0;
}

/* The step for the current inputs from the committed state, into cand_*. */
static int candidate(CoreWork *wk, CoreData *d, char *err) {
    double mask[NY > 0 ? NY : 1];
    if (d->cand_ok) return 0;
    for (int j = 0; j < NY; j++) mask[j] = d->valid[j] ? 1.0 : 0.0;
    for (int i = 0; i < STEP_NIN; i++) {
        const double *base = STEP_SRC[i] == SRC_STATE ? d->state : STEP_SRC[i] == SRC_U ? d->u_prev
                           : STEP_SRC[i] == SRC_Y ? d->y : STEP_SRC[i] == SRC_MASK ? mask : d->fixed;
        wk->arg[i] = base + STEP_OFF[i];
    }
    for (int j = 0; j < STEP_NOUT; j++) {
        switch (STEP_DST[j]) {
        case DST_STATE: wk->res[j] = d->cand_state + STEP_ROFF[j]; break;
        case DST_DIAG: wk->res[j] = d->cand_diag + STEP_ROFF[j]; break;
        case DST_STATUS: wk->res[j] = &wk->status; break;
        default: wk->res[j] = NULL;        /* CasADi skips a NULL result */
        }
    }
    wk->status = 0;
    flt_step(wk->arg, wk->res, wk->iw, wk->w, 0);
    if (wk->status == 1)
        FAIL("an input or a valid measurement is NaN or inf at t = %g s; estimate kept", d->time);
    if (wk->status != 0)
        FAIL("the estimate became non-finite at t = %g s (diverged, or covariances too large); estimate kept",
             d->time);
    d->cand_ok = 1;
    return 0;
}

static int get_real(CoreWork *wk, CoreData *d, unsigned r, double *v, char *err) {
    if (IN(r, VR_OUT, NOUT)) {
        const double *state = d->state, *diag = d->diag;
        if (at_instant(d->time, d->t0, PERIOD, d->kc + 1)) {   /* the update of this instant */
            if (candidate(wk, d, err)) return 1;
            state = d->cand_state;
            diag = d->cand_diag;
        }
        int k = (int)(r - VR_OUT);
        const double *base = OUT_SRC[k] == OUT_STATE ? state : OUT_SRC[k] == OUT_DIAG ? diag : d->fixed;
        *v = base[OUT_OFF[k]];
    } else if (IN(r, VR_U, NU)) *v = d->u[r - VR_U];
    else if (IN(r, VR_Y, NY)) *v = d->y[r - VR_Y];
    else return get_common_real(d, r, v, err);
    return 0;
}

static int set_real(CoreData *d, unsigned r, double v, int before_run, char *err) {
    if (IN(r, VR_U, NU)) {
        if (!isfinite(v)) FAIL("%s: value %g is not finite", VAR_NAMES[r], v);
        d->u[r - VR_U] = v;
    } else if (IN(r, VR_Y, NY)) {
        d->y[r - VR_Y] = v;                      /* NaN: a missing measurement (if the filter says so) */
        d->cand_ok = 0;
    } else return set_common_real(d, r, v, before_run, err);
    return 0;
}

CORE_GET_REAL_EACH
CORE_SET_REAL_EACH

CORE_INT_PARAMETERS(NULL)          /* no Integer variables */

int core_get_bool(const CoreData *d, const unsigned vr[], size_t n, int v[], char *err) {
    for (size_t i = 0; i < n; i++) {
        if (!IN(vr[i], VR_VALID, NY)) FAIL("no Boolean variable has value reference %u", vr[i]);
        v[i] = d->valid[vr[i] - VR_VALID];
    }
    return 0;
}

int core_set_bool(CoreData *d, const unsigned vr[], size_t n, const int v[], int before_run, char *err) {
    (void)before_run;
    for (size_t i = 0; i < n; i++) {
        if (!IN(vr[i], VR_VALID, NY)) FAIL("no Boolean variable has value reference %u", vr[i]);
        d->valid[vr[i] - VR_VALID] = v[i] ? 1 : 0;
        d->cand_ok = 0;
    }
    return 0;
}

/* Commits the candidate (the update of instant kc + 1). */
static int commit(CoreWork *wk, CoreData *d, char *err) {
    if (candidate(wk, d, err)) return 1;
    memcpy(d->state, d->cand_state, sizeof d->state);
    memcpy(d->diag, d->cand_diag, sizeof d->diag);
    d->kc += 1;
    d->cand_ok = 0;
    return 0;
}

int core_do_step(CoreWork *wk, CoreData *d, double t, double h, char *err) {
    double t_end = t + h, updates;
    long long k_end, n;
    if (check_step(t, h, d->time, err)) return 1;
    updates = h / PERIOD;
    if (!(updates <= (double)MAX_UPDATES))
        FAIL("communication step %g s holds %.3g filter updates of %g s, more than the limit of %ld",
             h, updates, PERIOD, MAX_UPDATES);
    /* every instant index below is in range (no conversion or loop past the step asked for) */
    if (instant_of(t_end, d->t0, PERIOD, &k_end, err)) return 1;
    if ((double)k_end - (double)d->kc > (double)MAX_UPDATES + 2)
        FAIL("the FMU state has committed instant %lld, %.3g updates before t + h = %g s: more than the limit of %ld",
             d->kc, (double)k_end - (double)d->kc, t_end, MAX_UPDATES);
    if (at_instant(t, d->t0, PERIOD, d->kc + 1) && commit(wk, d, err)) return 1;
    /* the input of the latest instant predicts the next update */
    if (at_instant(t, d->t0, PERIOD, d->kc)) memcpy(d->u_prev, d->u, sizeof d->u);
    for (n = 0; before_end(t_end, d->t0, PERIOD, d->kc + 1); n++) {
        if (n > MAX_UPDATES + 2) { d->time = t; FAIL("more than %ld filter updates in one step", MAX_UPDATES); }
        d->time = d->t0 + (double)(d->kc + 1) * PERIOD;      /* for the messages */
        if (commit(wk, d, err)) { d->time = t; return 1; }
        memcpy(d->u_prev, d->u, sizeof d->u);
    }
    d->cand_ok = 0;
    d->time = t_end;
    return 0;
}

int core_check(const CoreData *d, char *err) {
    if (!isfinite(d->time) || !isfinite(d->t0)) FAIL("the FMU state is invalid: its time is not finite");
    if (check_parameters(d->p, NULL, err)) return 1;
    if (!(d->kc >= 0 && (double)d->kc <= MAX_INSTANTS)) FAIL("the FMU state is invalid: committed instant %lld", d->kc);
    if (d->cand_ok != 0 && d->cand_ok != 1) FAIL("the FMU state is invalid: candidate flag %d", d->cand_ok);
    for (int j = 0; j < NY; j++)
        if (d->valid[j] != 0 && d->valid[j] != 1) FAIL("the FMU state is invalid: valid flag %d", d->valid[j]);
    if (check_finite(d->u, NU, "u", err) || check_finite(d->u_prev, NU, "u_prev", err)
        || check_finite(d->state, NSTATE, "state", err))
        return 1;
    if (check_clock_state(&d->clk, err)) return 1;
#ifdef CLOCK_VR
    if (d->clk.n > 0 && d->kc != d->clk.n - 1)
        FAIL("the FMU state is invalid: %lld clock activations, committed instant %lld", d->clk.n, d->kc);
#endif
    return 0;
}

#ifdef CLOCK_VR
/* ------------------------------------------------------------------ the clocked form */
CORE_CLOCK_TIMING(PERIOD)

int core_is_clocked(unsigned r) {
    return IN(r, VR_U, NU) || IN(r, VR_Y, NY) || IN(r, VR_VALID, NY) || IN(r, VR_OUT, NOUT);
}

int core_clock_begin(CoreWork *wk, CoreData *d, char *err) {
    (void)wk; (void)err;
    d->cand_ok = 0;                      /* activation k >= 1: the outputs show its update */
    return 0;
}

int core_clock_end(CoreWork *wk, CoreData *d, char *err) {
    if (d->clk.n > 0 && commit(wk, d, err)) return 1;     /* activation 0: the initial estimate */
    memcpy(d->u_prev, d->u, sizeof d->u);                 /* the input predicts the next update */
    d->clk.n += 1;
    return 0;
}
#endif

CORE_NO_MODEL_EXCHANGE("an estimator FMU")
