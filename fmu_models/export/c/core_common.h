/* pendulum-cosim: what the model cores share. Include after core_api.h.
 *
 * Parameter domains (the codes of model_config.h's PARAM_DOMAIN), the checked setting of the
 * Real parameters (group P of model_config.h) and the Integer/Enumeration parameters (group
 * IP: IP_MIN, IP_MAX, IP_WIDTH), the Real variables every core has (its parameters, the time)
 * and the checks of a step and of an FMU state; the core API's time functions, alike in every
 * core (CoreData's `time`); and, used at file scope, the core API functions that cores
 * without some capability implement alike:
 *   CORE_NO_MODEL_EXCHANGE("an estimator FMU")   Co-Simulation only: no states, no derivatives
 *   CORE_NO_BOOLEANS                             no Boolean variables
 * and those a core implements one variable at a time (CORE_GET_REAL_EACH, CORE_SET_REAL_EACH).
 */
#ifndef CORE_COMMON_H
#define CORE_COMMON_H

#include <math.h>
#include <stdio.h>

/* the order of fmu_models.variables.DOMAINS */
enum { DOMAIN_REAL = 0, DOMAIN_POSITIVE = 1, DOMAIN_NONNEGATIVE = 2, DOMAIN_UNIT = 3, DOMAIN_SIGN = 4 };

/* 1 if the value reference r (unsigned) lies in [base, base + n): compared as unsigned
 * long long, so no value reference (up to 2^32 - 1) can overflow the arithmetic. */
#define IN_GROUP(r, base, n) \
    ((unsigned long long)(r) >= (unsigned long long)(base) && \
     (unsigned long long)(r) < (unsigned long long)(base) + (unsigned long long)(n))

double core_time(const CoreData *d) { return d->time; }
void core_set_time(CoreData *d, double t) { d->time = t; }

/* Sample instants t0 + k period of a sampled core (plant grid, filter, signal). A time within
 * SAMPLE_TOL periods of an instant counts as that instant, so that a master that adds up
 * t += h (OMSimulator: 4.999999999999938 after 500 steps of 0.01) still reaches it. */
#define SAMPLE_TOL 1e-6

/* Most sample periods between the start time and any time the core works at: instant
 * indices stay exact in a double and far inside a long long. */
#define MAX_INSTANTS 4503599627370496.0 /* 2^52 */

/* The index *k of the latest instant at or before t (an instant within the tolerance counts);
 * 1 with the message in err if t is not finite or lies more than MAX_INSTANTS periods from t0
 * (no conversion of an out-of-range double to an integer). */
static inline int instant_of(double t, double t0, double period, long long *k, char *err) {
    double q = (t - t0) / period;
    if (!isfinite(t) || !isfinite(q) || fabs(q) > MAX_INSTANTS) {
        snprintf(err, ERRLEN,
                 "time %g s lies %g sample periods of %g s from the start time %g s: at most 2^52 are supported",
                 t, q, period, t0);
        return 1;
    }
    *k = (long long)floor(q + SAMPLE_TOL);
    return 0;
}

/* 1 if t is (within the tolerance) the instant k. */
static inline int at_instant(double t, double t0, double period, long long k) {
    return fabs((t - t0) / period - (double)k) <= SAMPLE_TOL;
}

/* 1 if instant k lies before t + h by more than the tolerance (strictly inside a step that
 * ends at t + h). */
static inline int before_end(double t_end, double t0, double period, long long k) {
    return (double)k < (t_end - t0) / period - SAMPLE_TOL;
}

/* The checks every core's doStep(t, h) starts with: t and h finite, h > 0, t + h finite, t
 * the FMU's time (within 1e-9 relative); else 1 with the message in err. */
static inline int check_step(double t, double h, double time, char *err) {
    if (!isfinite(t)) {
        snprintf(err, ERRLEN, "currentCommunicationPoint %g is not finite", t);
        return 1;
    }
    if (!(h > 0) || !isfinite(h)) {
        snprintf(err, ERRLEN, "communication step size %g must be > 0 and finite", h);
        return 1;
    }
    if (!isfinite(t + h)) {
        snprintf(err, ERRLEN, "currentCommunicationPoint + communicationStepSize = %g + %g is not finite", t, h);
        return 1;
    }
    if (off_time(t, time)) {
        snprintf(err, ERRLEN, "currentCommunicationPoint %.17g differs from the FMU time %.17g", t, time);
        return 1;
    }
    return 0;
}

/* 1 (message in err) unless every v[0..n-1] is finite; `what` names the array. */
static inline int check_finite(const double v[], int n, const char *what, char *err) {
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) {
            snprintf(err, ERRLEN, "the FMU state is invalid: %s[%d] = %g is not finite", what, i, v[i]);
            return 1;
        }
    return 0;
}

/* NULL if v is in the domain, else why not ("must be > 0", ...). */
static inline const char *domain_violation(int domain, double v) {
    if (!isfinite(v)) return "is not finite";
    switch (domain) {
    case DOMAIN_POSITIVE: return v > 0 ? NULL : "must be > 0";
    case DOMAIN_NONNEGATIVE: return v >= 0 ? NULL : "must be >= 0";
    case DOMAIN_UNIT: return (v > 0 && v <= 1) ? NULL : "must be in (0, 1]";
    case DOMAIN_SIGN: return (v == 1.0 || v == -1.0) ? NULL : "must be -1 or +1";
    default: return NULL;
    }
}

/* p[k] = v for the Real parameter with value reference VR_P + k, if the mode allows it and v
 * is in its domain; else 1 with the message in err. */
static inline int set_parameter(double p[], int k, double v, int before_run, char *err) {
    const char *why = domain_violation(PARAM_DOMAIN[k], v);
    if (!before_run) {
        snprintf(err, ERRLEN, "parameter %s is fixed: set it before leaving initialization mode", VAR_NAMES[VR_P + k]);
        return 1;
    }
    if (why) {
        snprintf(err, ERRLEN, "parameter %s = %g %s", VAR_NAMES[VR_P + k], v, why);
        return 1;
    }
    p[k] = v;
    return 0;
}

/* Every Real parameter in its domain, every Integer parameter in its range (leaving
 * initialization mode); else 1 with the first violation in err. */
static inline int check_parameters(const double p[], const long long ip[], char *err) {
    for (int k = 0; k < NP; k++) {
        const char *why = domain_violation(PARAM_DOMAIN[k], p[k]);
        if (why) {
            snprintf(err, ERRLEN, "parameter %s = %g %s", VAR_NAMES[VR_P + k], p[k], why);
            return 1;
        }
    }
    for (int k = 0; k < NIP; k++)
        if (ip[k] < IP_MIN[k] || ip[k] > IP_MAX[k]) {
            snprintf(err, ERRLEN, "parameter %s = %lld must be in [%lld, %lld]", VAR_NAMES[VR_IP + k], ip[k],
                     IP_MIN[k], IP_MAX[k]);
            return 1;
        }
    return 0;
}

/* The value *v of a Real variable that is not in the core's own groups: a parameter (group P)
 * or the time; else 1 with the message in err (no such variable). */
static inline int get_common_real(const CoreData *d, unsigned r, double *v, char *err) {
    if (IN_GROUP(r, VR_P, NP)) *v = d->p[r - VR_P];
    else if (r == VR_TIME) *v = d->time;
    else {
        snprintf(err, ERRLEN, "no Real variable has value reference %u", r);
        return 1;
    }
    return 0;
}

/* Setting a Real variable that is not in the core's own groups: a parameter (group P: only
 * before the run, before_run == 1); else 1 with the message in err (a calculated variable, or
 * no such variable). */
static inline int set_common_real(CoreData *d, unsigned r, double v, int before_run, char *err) {
    if (IN_GROUP(r, VR_P, NP)) return set_parameter(d->p, (int)(r - VR_P), v, before_run == 1, err);
    if (r < N_VARS) snprintf(err, ERRLEN, "%s is calculated and cannot be set", VAR_NAMES[r]);
    else snprintf(err, ERRLEN, "no Real variable has value reference %u", r);
    return 1;
}

/* 0 if the clock state of a core's FMU state is consistent, else 1 with the message in err. */
static inline int check_clock_state(const ClockState *k, char *err) {
    if (!(k->n >= 0 && (double)k->n <= MAX_INSTANTS) || (k->active != 0 && k->active != 1)
        || (k->fresh != 0 && k->fresh != 1)) {
        snprintf(err, ERRLEN, "the FMU state is invalid: clock state %lld, %d, %d", k->n, k->active, k->fresh);
        return 1;
    }
    return 0;
}

/* The index k of the Integer parameter with value reference vr (-1 with the message in err if
 * there is none of this width: INT_32 or INT_64 in FMI 3.0, INT_NONE in FMI 2.0). */
static inline int int_parameter(unsigned vr, int width, char *err) {
    unsigned k;
    if (!IN_GROUP(vr, VR_IP, NIP) || (width != INT_NONE && IP_WIDTH[vr - (unsigned)VR_IP] != width)) {
        snprintf(err, ERRLEN, "no Int%d variable has value reference %u", width ? width : 32, vr);
        return -1;
    }
    k = vr - (unsigned)VR_IP;      /* < NIP: no signed arithmetic on the value reference */
    return (int)k;
}

static inline int get_int_parameters(const long long ip[], const unsigned vr[], size_t n, long long v[], int width,
                                     char *err) {
    for (size_t i = 0; i < n; i++) {
        int k = int_parameter(vr[i], width, err);
        if (k < 0) return 1;
        v[i] = ip[k];
    }
    return 0;
}

static inline int set_int_parameters(long long ip[], const unsigned vr[], size_t n, const long long v[], int width,
                                     int before_run, char *err) {
    for (size_t i = 0; i < n; i++) {
        int k = int_parameter(vr[i], width, err);
        if (k < 0) return 1;
        if (!before_run) {
            snprintf(err, ERRLEN, "parameter %s is fixed: set it before leaving initialization mode",
                     VAR_NAMES[VR_IP + k]);
            return 1;
        }
        if (v[i] < IP_MIN[k] || v[i] > IP_MAX[k]) {
            snprintf(err, ERRLEN, "parameter %s = %lld must be in [%lld, %lld]", VAR_NAMES[VR_IP + k], v[i],
                     IP_MIN[k], IP_MAX[k]);
            return 1;
        }
        ip[k] = v[i];
    }
    return 0;
}

/* core_clock_due and core_clock_next of the clocked form (core_api.h), at file scope: the
 * activations t0 + n PERIOD_EXPR (an expression of d) for n = d->clk.n. */
#define CORE_CLOCK_TIMING(PERIOD_EXPR)                                                                 \
    double core_clock_next(const CoreData *d) { return d->t0 + (double)d->clk.n * (PERIOD_EXPR); }     \
    int core_clock_due(const CoreData *d, double t) {                                                   \
        double P = (PERIOD_EXPR);                                                                       \
        if (at_instant(t, d->t0, P, d->clk.n)) return 1;                                                \
        return (double)d->clk.n < (t - d->t0) / P ? 2 : 0;                                              \
    }

/* core_get_real / core_set_real, one variable at a time through the core's
 *   static int get_real(CoreWork *wk, CoreData *d, unsigned r, double *v, char *err);
 *   static int set_real(CoreData *d, unsigned r, double v, int before_run, char *err);
 * (0, or 1 with the message in err: the call stops at the first variable refused). */
#define CORE_GET_REAL_EACH                                                                             \
    int core_get_real(CoreWork *wk, CoreData *d, const unsigned vr[], size_t n, double v[], char *err) { \
        for (size_t i = 0; i < n; i++)                                                                  \
            if (get_real(wk, d, vr[i], &v[i], err)) return 1;                                           \
        return 0;                                                                                       \
    }
#define CORE_SET_REAL_EACH                                                                             \
    int core_set_real(CoreData *d, const unsigned vr[], size_t n, const double v[], int before_run,     \
                      char *err) {                                                                      \
        for (size_t i = 0; i < n; i++)                                                                  \
            if (set_real(d, vr[i], v[i], before_run, err)) return 1;                                    \
        return 0;                                                                                       \
    }

#define CORE_NO_MODEL_EXCHANGE(WHAT)                                                                   \
    int core_derivatives(CoreWork *wk, const CoreData *d, double dx[], char *err) {                     \
        (void)wk; (void)d; (void)dx;                                                                    \
        snprintf(err, ERRLEN, "%s has no Model Exchange interface", WHAT);                              \
        return 1;                                                                                       \
    }                                                                                                   \
    int core_set_states(CoreData *d, const double x[], size_t nx, char *err) {                          \
        (void)d; (void)x; (void)nx;                                                                     \
        snprintf(err, ERRLEN, "%s has no continuous states", WHAT);                                     \
        return 1;                                                                                       \
    }                                                                                                   \
    void core_get_states(const CoreData *d, double x[]) { (void)d; (void)x; }                           \
    int core_directional(CoreWork *wk, const CoreData *d, const unsigned unk[], size_t nU,              \
                         const unsigned kn[], size_t nK, const double seed[], double sens[], char *err) { \
        (void)wk; (void)d; (void)unk; (void)nU; (void)kn; (void)nK; (void)seed; (void)sens;             \
        snprintf(err, ERRLEN, "directional derivatives are not provided by %s", WHAT);                  \
        return 1;                                                                                       \
    }

/* core_get_int / core_set_int over the Integer parameters at IP (the CoreData field holding
 * them; NULL for a core without any): every core's Integer variables are its parameters. */
#define CORE_INT_PARAMETERS(IP)                                                                        \
    int core_get_int(const CoreData *d, const unsigned vr[], size_t n, long long v[], int width,       \
                     char *err) {                                                                       \
        (void)d;                                                                                        \
        return get_int_parameters(IP, vr, n, v, width, err);                                            \
    }                                                                                                   \
    int core_set_int(CoreData *d, const unsigned vr[], size_t n, const long long v[], int width,       \
                     int before_run, char *err) {                                                       \
        (void)d;                                                                                        \
        return set_int_parameters(IP, vr, n, v, width, before_run, err);                               \
    }

#define CORE_NO_BOOLEANS                                                                               \
    int core_get_bool(const CoreData *d, const unsigned vr[], size_t n, int v[], char *err) {           \
        (void)d; (void)v;                                                                               \
        if (!n) return 0;                                                                               \
        snprintf(err, ERRLEN, "no Boolean variable has value reference %u", vr[0]);                     \
        return 1;                                                                                       \
    }                                                                                                   \
    int core_set_bool(CoreData *d, const unsigned vr[], size_t n, const int v[], int before_run,        \
                      char *err) {                                                                      \
        (void)d; (void)v; (void)before_run;                                                             \
        if (!n) return 0;                                                                               \
        snprintf(err, ERRLEN, "no Boolean variable has value reference %u", vr[0]);                     \
        return 1;                                                                                       \
    }

#endif
