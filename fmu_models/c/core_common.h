/* pendulum-cosim: what the model cores share. Include after core_api.h.
 *
 * Parameter domains (the generated tables of model_config.h use these codes) and the checked
 * setting of a Real parameter; and, used at file scope, the core API functions that cores
 * without some capability implement alike:
 *   CORE_NO_MODEL_EXCHANGE("an estimator FMU")   Co-Simulation only: no states, no derivatives
 *   CORE_NO_BOOLEANS                             no Boolean variables
 */
#ifndef CORE_COMMON_H
#define CORE_COMMON_H

#include <math.h>
#include <stdio.h>

/* the order of fmu_models.variables.DOMAINS */
enum { DOMAIN_REAL = 0, DOMAIN_POSITIVE = 1, DOMAIN_NONNEGATIVE = 2, DOMAIN_UNIT = 3, DOMAIN_SIGN = 4 };

/* NULL if v is in the domain, else why not ("must be > 0", ...). */
static const char *domain_violation(int domain, double v) {
    if (!isfinite(v)) return "is not finite";
    switch (domain) {
    case DOMAIN_POSITIVE: return v > 0 ? NULL : "must be > 0";
    case DOMAIN_NONNEGATIVE: return v >= 0 ? NULL : "must be >= 0";
    case DOMAIN_UNIT: return (v > 0 && v <= 1) ? NULL : "must be in (0, 1]";
    case DOMAIN_SIGN: return (v == 1.0 || v == -1.0) ? NULL : "must be -1 or +1";
    default: return NULL;
    }
}

/* *slot = v for the parameter `name` of `domain`, if the mode allows it and v is valid;
 * else 1 with the message in err. */
static int set_parameter(double *slot, const char *name, int domain, double v, int before_run, char *err) {
    const char *why = domain_violation(domain, v);
    if (!before_run) {
        snprintf(err, ERRLEN, "parameter %s is fixed: set it before leaving initialization mode", name);
        return 1;
    }
    if (why) {
        snprintf(err, ERRLEN, "parameter %s = %g %s", name, v, why);
        return 1;
    }
    *slot = v;
    return 0;
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
