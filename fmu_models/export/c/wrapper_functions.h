/* pendulum-cosim: the FMI functions of the FMI 2.0 and FMI 3.0 wrappers written once.
 *
 * Include after wrapper_common.h, having defined HANDLE (fmi2Component or fmi3Instance) and
 * REAL (fmi2Real or fmi3Float64). Two parts:
 *   - the calls both versions make after their own state and argument checks: what a call does
 *     to the core and the instance (each takes the instance and the function's name, for the
 *     messages);
 *   - the functions both versions define alike (the same arguments, states and messages), named
 *     FMI(...) here; and those alike but for names or a mask, defined by the wrapper with the
 *     macros COMPLETED_INTEGRATOR_STEP, GET_DERIVATIVES, GET_NOMINALS and FMU_STATE_FUNCTIONS.
 * Each wrapper defines the rest of its version's API over these. */
#ifndef WRAPPER_FUNCTIONS_H
#define WRAPPER_FUNCTIONS_H

#include <math.h>

/* ------------------------------------------------------------------ shared calls */
/* fmi2SetupExperiment / fmi3EnterInitializationMode: the experiment's tolerance and times. */
static STATUS start_experiment(Instance *c, const char *fn, int tolDef, double tol, double start, int stopDef,
                               double stop) {
    if (tolDef && !(tol > 0 && isfinite(tol))) return fail(c, fn, "tolerance %g must be finite and > 0", tol);
    if (!isfinite(start)) return fail(c, fn, "start time %g is not finite", start);
    if (stopDef && !(stop >= start))
        return fail(c, fn, "stop time %g is not a time at or after the start time %g", stop, start);
    core_set_time(&c->d, start);
    return STATUS_OK;
}

/* Leaving Initialization Mode for the state `next`. */
static STATUS exit_initialization(Instance *c, const char *fn, Mode next) {
    BEGIN_CHANGE(c);
    if (core_exit_init(&c->wk, &c->d, c->err)) return undo(c, fn);
    c->mode = next;
    return STATUS_OK;
}

static STATUS get_reals(Instance *c, const char *fn, const unsigned vr[], size_t n, REAL v[]) {
    return core(c, fn, core_get_real(&c->wk, &c->d, vr, n, v, c->err));
}

static STATUS set_reals(Instance *c, const char *fn, const unsigned vr[], size_t n, const REAL v[]) {
    BEGIN_CHANGE(c);
    if (core_set_real(&c->d, vr, n, v, SET_WHEN(c), c->err)) return undo(c, fn);
    return STATUS_OK;
}

/* get_T and set_T: the values of the FMI integer type T, one at a time through the core's
 * integers of width WIDTH (INT_NONE in FMI 2.0, INT_32 or INT_64 in FMI 3.0). */
#define INT_CALLS(T, WIDTH)                                                                              \
    static STATUS get_##T(Instance *c, const char *fn, const unsigned vr[], size_t n, T v[]) {           \
        long long tmp;                                                                                   \
        for (size_t i = 0; i < n; i++) {                                                                 \
            if (core_get_int(&c->d, &vr[i], 1, &tmp, WIDTH, c->err)) return core(c, fn, 1);             \
            v[i] = (T)tmp;                                                                               \
        }                                                                                                \
        return STATUS_OK;                                                                                \
    }                                                                                                    \
    static STATUS set_##T(Instance *c, const char *fn, const unsigned vr[], size_t n, const T v[]) {     \
        BEGIN_CHANGE(c);                                                                                 \
        for (size_t i = 0; i < n; i++) {                                                                 \
            long long tmp = (long long)v[i];                                                             \
            if (core_set_int(&c->d, &vr[i], 1, &tmp, WIDTH, BEFORE_RUN(c), c->err)) return undo(c, fn); \
        }                                                                                                \
        return STATUS_OK;                                                                                \
    }

static STATUS get_booleans(Instance *c, const char *fn, const unsigned vr[], size_t n, FMI(Boolean) v[]) {
    for (size_t i = 0; i < n; i++) {
        int tmp;
        if (core_get_bool(&c->d, &vr[i], 1, &tmp, c->err)) return core(c, fn, 1);
        v[i] = tmp ? FMI(True) : FMI(False);
    }
    return STATUS_OK;
}

static STATUS set_booleans(Instance *c, const char *fn, const unsigned vr[], size_t n, const FMI(Boolean) v[]) {
    BEGIN_CHANGE(c);
    for (size_t i = 0; i < n; i++) {
        int tmp = v[i] ? 1 : 0;
        if (core_set_bool(&c->d, &vr[i], 1, &tmp, BEFORE_RUN(c), c->err)) return undo(c, fn);
    }
    return STATUS_OK;
}

/* Co-Simulation: the core's step from t over h, whole or not at all. */
static STATUS do_step(Instance *c, const char *fn, double t, double h) {
    BEGIN_CHANGE(c);
    if (core_do_step(&c->wk, &c->d, t, h, c->err)) return undo(c, fn);
    return STATUS_OK;
}

/* Model Exchange: the number of continuous states passed is the model's. */
#define NSTATES(fn, x, nx) do { ARRAY(fn, x, nx); \
    if ((nx) != (size_t)CORE_NX) return fail(c, fn, "nx = %zu, this model has %d states", (size_t)(nx), CORE_NX); \
    } while (0)

/* ------------------------------------------------------------------ functions defined alike */
STATUS FMI(SetDebugLogging)(HANDLE inst, FMI(Boolean) on, size_t n, const FMI(String) cats[]) {
    ALLOW(FMI_NAME(SetDebugLogging), ANY, ANY);
    return set_debug_logging(c, FMI_NAME(SetDebugLogging), on != FMI(False), n, cats);
}

void FMI(FreeInstance)(HANDLE inst) {
    Instance *c = (Instance *)inst;
    if (!c) return;
    states_free_all(c);
    mem_free(c, c);
}

STATUS FMI(Reset)(HANDLE inst) {
    ALLOW(FMI_NAME(Reset), ANY, ANY);
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return STATUS_OK;
}

STATUS FMI(EnterContinuousTimeMode)(HANDLE inst) {
    ALLOW(FMI_NAME(EnterContinuousTimeMode), 0, B(M_EVENT));
    c->mode = M_CONT;
    return STATUS_OK;
}

/* Continuous-Time Mode only: in Event Mode the standard allows it for a pure discrete-time
 * model alone. */
STATUS FMI(SetTime)(HANDLE inst, REAL t) {
    ALLOW(FMI_NAME(SetTime), 0, B(M_CONT));
    if (!isfinite(t)) return fail(c, FMI_NAME(SetTime), "time %g is not finite", t);
    core_set_time(&c->d, t);
    return STATUS_OK;
}

STATUS FMI(SetContinuousStates)(HANDLE inst, const REAL x[], size_t nx) {
    const char *fn = FMI_NAME(SetContinuousStates);
    ALLOW(fn, 0, B(M_CONT));
    NSTATES(fn, x, nx);
    return core(c, fn, core_set_states(&c->d, x, nx, c->err));
}

STATUS FMI(GetContinuousStates)(HANDLE inst, REAL x[], size_t nx) {
    const char *fn = FMI_NAME(GetContinuousStates);
    ALLOW(fn, 0, GET_ME);
    NSTATES(fn, x, nx);
    core_get_states(&c->d, x);
    return STATUS_OK;
}

/* The functions both versions define alike but for a name or a mask: defined where the
 * wrapper names them. */
/* fmiXCompletedIntegratorStep, with the version's names of its output arguments (the messages
 * name them): no event, no termination. */
#define COMPLETED_INTEGRATOR_STEP(ENTER, TERM)                                                                  \
    STATUS FMI(CompletedIntegratorStep)(HANDLE inst, FMI(Boolean) noSetPrior, FMI(Boolean) *ENTER,             \
                                        FMI(Boolean) *TERM) {                                                   \
        ALLOW(FMI_NAME(CompletedIntegratorStep), 0, B(M_CONT));                                                 \
        (void)noSetPrior;                                                                                       \
        NOT_NULL(FMI_NAME(CompletedIntegratorStep), ENTER);                                                     \
        NOT_NULL(FMI_NAME(CompletedIntegratorStep), TERM);                                                      \
        *ENTER = FMI(False);                                                                                    \
        *TERM = FMI(False);                                                                                     \
        return STATUS_OK;                                                                                       \
    }

/* The derivatives of the continuous states, under the version's NAME. */
#define GET_DERIVATIVES(NAME)                                                                                   \
    STATUS NAME(HANDLE inst, REAL dx[], size_t nx) {                                                            \
        ALLOW(#NAME, 0, GET_ME);                                                                                \
        NSTATES(#NAME, dx, nx);                                                                                 \
        return core(c, #NAME, core_derivatives(&c->wk, &c->d, dx, c->err));                                    \
    }

/* fmiXGetNominalsOfContinuousStates, allowed in the Model Exchange states ME_MASK: all 1. */
#define GET_NOMINALS(ME_MASK)                                                                                   \
    STATUS FMI(GetNominalsOfContinuousStates)(HANDLE inst, REAL nom[], size_t nx) {                             \
        ALLOW(FMI_NAME(GetNominalsOfContinuousStates), 0, ME_MASK);                                             \
        NSTATES(FMI_NAME(GetNominalsOfContinuousStates), nom, nx);                                              \
        for (size_t i = 0; i < nx; i++) nom[i] = 1.0;                                                           \
        return STATUS_OK;                                                                                       \
    }

/* The FMU-state functions under the version's names (STATE: the FMU-state type). */
#define FMU_STATE_FUNCTIONS(STATE, GET, SET, FREE, SIZE, SERIALIZE, DESERIALIZE)               \
    STATUS GET(HANDLE inst, STATE *s) {                    /* not after an Error (check_state) */ \
        ALLOW(#GET, LIVE, LIVE);                                                               \
        return get_fmu_state(c, #GET, s);                                                      \
    }                                                                                          \
    STATUS SET(HANDLE inst, STATE s) {                                                         \
        ALLOW(#SET, ANY, ANY);                                                                 \
        return set_fmu_state(c, #SET, s);                                                      \
    }                                                                                          \
    STATUS FREE(HANDLE inst, STATE *s) {                                                       \
        ALLOW(#FREE, ANY, ANY);                                                                \
        return free_fmu_state(c, #FREE, s);                                                    \
    }                                                                                          \
    STATUS SIZE(HANDLE inst, STATE s, size_t *size) {                                          \
        ALLOW(#SIZE, ANY, ANY);                                                                \
        return fmu_state_size(c, #SIZE, s, size);                                              \
    }                                                                                          \
    STATUS SERIALIZE(HANDLE inst, STATE s, FMI(Byte) out[], size_t size) {                     \
        ALLOW(#SERIALIZE, ANY, ANY);                                                           \
        return serialize_fmu_state(c, #SERIALIZE, s, out, size);                               \
    }                                                                                          \
    STATUS DESERIALIZE(HANDLE inst, const FMI(Byte) in[], size_t size, STATE *s) {             \
        ALLOW(#DESERIALIZE, ANY, ANY);                                                         \
        return deserialize_fmu_state(c, #DESERIALIZE, in, size, s);                            \
    }

#endif
