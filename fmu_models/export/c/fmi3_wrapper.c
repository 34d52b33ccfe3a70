/* pendulum-cosim: FMI 3.0 Model Exchange + Co-Simulation wrapper around a model core
 * (core_api.h: a plant, an estimator or a signal). Every FMI 3.0 function is exported
 * (importers such as fmpy load them all by name); those this FMU does not support answer
 * fmi3Error with a message. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"
#include "core_api.h"
#include "wrapper_modes.h"

typedef enum { ME, CS } Kind;

typedef struct {
    CoreData d;
    CoreWork wk;
    Kind kind;
    Mode mode;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    int logging;
    char err[ERRLEN];
} Instance;

static void logmsg(Instance *c, fmi3Status st, const char *cat, const char *fn, const char *text) {
    char buf[ERRLEN + 200];
    if (!c || !c->log || (st < fmi3Warning && !c->logging)) return;
    snprintf(buf, sizeof buf, "%s: %s", fn, text);
    c->log(c->env, st, cat, buf);
}

#define STATUS fmi3Status
#define STATUS_OK fmi3OK
#define STATUS_ERROR fmi3Error
#define IS_CS(c) ((c)->kind == CS)
#include "wrapper_common.h"

#define ALLOW(fn, mask) ALLOW_IN(inst, fn, mask)
#define UNSUPPORTED(fn, why) return fail(c, fn, "%s", why)

/* ------------------------------------------------------------------ lifecycle */
const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance inst, fmi3Boolean on, size_t n, const fmi3String cats[]) {
    ALLOW("fmi3SetDebugLogging", ANY_LIVE | B(M_ERROR));
    (void)n; (void)cats;
    c->logging = on ? 1 : 0;
    return fmi3OK;
}

static Instance *instantiate(Kind kind, fmi3String token, fmi3Boolean logging,
                             fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    Instance *c = (Instance *)calloc(1, sizeof(Instance));
    if (!c) return NULL;
    c->env = env;
    c->log = log;
    c->logging = logging ? 1 : 0;
    if (!token || strcmp(token, MODEL_GUID) != 0) {
        fail(c, "fmi3Instantiate", "instantiationToken %s does not match this FMU's %s", token ? token : "(null)", MODEL_GUID);
        free(c);
        return NULL;
    }
    c->kind = kind;
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return c;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String res,
                                          fmi3Boolean visible, fmi3Boolean logging,
                                          fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    (void)name; (void)res; (void)visible;
    if (!CORE_HAS_ME) {
        if (log) log(env, fmi3Error, "logStatusError", "fmi3InstantiateModelExchange: this FMU has no Model Exchange interface");
        return NULL;
    }
    return instantiate(ME, token, logging, env, log);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res,
                                         fmi3Boolean visible, fmi3Boolean logging,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference req[], size_t nreq,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback upd) {
    (void)name; (void)res; (void)visible; (void)eventModeUsed; (void)earlyReturnAllowed;
    (void)req; (void)nreq; (void)upd;
    return instantiate(CS, token, logging, env, log);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String res,
                                               fmi3Boolean visible, fmi3Boolean logging,
                                               fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                               fmi3ClockUpdateCallback cu, fmi3LockPreemptionCallback lp,
                                               fmi3UnlockPreemptionCallback up) {
    (void)name; (void)token; (void)res; (void)visible; (void)logging; (void)cu; (void)lp; (void)up;
    if (log) log(env, fmi3Error, "logStatusError", "fmi3InstantiateScheduledExecution: not supported by this FMU");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance inst) { free(inst); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance inst, fmi3Boolean tolDef, fmi3Float64 tol,
                                       fmi3Float64 start, fmi3Boolean stopDef, fmi3Float64 stop) {
    ALLOW("fmi3EnterInitializationMode", B(M_INSTANTIATED));
    (void)tolDef; (void)tol;
    if (!isfinite(start)) return fail(c, "fmi3EnterInitializationMode", "start time must be finite");
    if (stopDef && !(stop >= start)) return fail(c, "fmi3EnterInitializationMode", "stop time %g < start time %g", stop, start);
    core_set_time(&c->d, start);
    c->mode = M_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance inst) {
    ALLOW("fmi3ExitInitializationMode", B(M_INIT));
    if (core_exit_init(&c->wk, &c->d, c->err)) { c->mode = M_ERROR; return core(c, "fmi3ExitInitializationMode", 1); }
    c->mode = c->kind == CS ? M_STEP : M_EVENT;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance inst) {
    ALLOW("fmi3EnterEventMode", B(M_EVENT) | B(M_CONT));
    c->mode = M_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance inst) {
    ALLOW("fmi3Terminate", RUNNING | B(M_ERROR));
    c->mode = M_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance inst) {
    ALLOW("fmi3Reset", ANY_LIVE | B(M_ERROR));
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return fmi3OK;
}

/* ------------------------------------------------------------------ values */
fmi3Status fmi3GetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    ALLOW("fmi3GetFloat64", ANY_LIVE);
    if (nv != n) return fail(c, "fmi3GetFloat64", "nValues = %zu differs from nValueReferences = %zu (all variables are scalars)", nv, n);
    return core(c, "fmi3GetFloat64", core_get_real(&c->wk, &c->d, vr, n, v, c->err));
}

fmi3Status fmi3SetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv) {
    ALLOW("fmi3SetFloat64", ANY_LIVE & ~B(M_TERMINATED));
    if (nv != n) return fail(c, "fmi3SetFloat64", "nValues = %zu differs from nValueReferences = %zu (all variables are scalars)", nv, n);
    return core(c, "fmi3SetFloat64", core_set_real(&c->d, vr, n, v, BEFORE_RUN(c), c->err));
}

/* Integer-valued variables: the core says which width each has (Enumerations use Int64). */
#define INT_GET(fn, T, width) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) { \
    long long tmp; ALLOW(#fn, ANY_LIVE); \
    if (nv != n) return fail(c, #fn, "nValues = %zu differs from nValueReferences = %zu", nv, n); \
    for (size_t i = 0; i < n; i++) { \
        if (core_get_int(&c->d, &vr[i], 1, &tmp, width, c->err)) return core(c, #fn, 1); \
        v[i] = (T)tmp; } \
    return fmi3OK; }
#define INT_SET(fn, T, width) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv) { \
    long long tmp; ALLOW(#fn, ANY_LIVE & ~B(M_TERMINATED)); \
    if (nv != n) return fail(c, #fn, "nValues = %zu differs from nValueReferences = %zu", nv, n); \
    for (size_t i = 0; i < n; i++) { \
        tmp = (long long)v[i]; \
        if (core_set_int(&c->d, &vr[i], 1, &tmp, width, BEFORE_RUN(c), c->err)) return core(c, #fn, 1); } \
    return fmi3OK; }
INT_GET(fmi3GetInt64, fmi3Int64, INT_64)
INT_SET(fmi3SetInt64, fmi3Int64, INT_64)
INT_GET(fmi3GetInt32, fmi3Int32, INT_32)
INT_SET(fmi3SetInt32, fmi3Int32, INT_32)

fmi3Status fmi3GetBoolean(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Boolean v[], size_t nv) {
    ALLOW("fmi3GetBoolean", ANY_LIVE);
    if (nv != n) return fail(c, "fmi3GetBoolean", "nValues = %zu differs from nValueReferences = %zu", nv, n);
    for (size_t i = 0; i < n; i++) {
        int tmp;
        if (core_get_bool(&c->d, &vr[i], 1, &tmp, c->err)) return core(c, "fmi3GetBoolean", 1);
        v[i] = tmp ? fmi3True : fmi3False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Boolean v[], size_t nv) {
    ALLOW("fmi3SetBoolean", ANY_LIVE & ~B(M_TERMINATED));
    if (nv != n) return fail(c, "fmi3SetBoolean", "nValues = %zu differs from nValueReferences = %zu", nv, n);
    for (size_t i = 0; i < n; i++) {
        int tmp = v[i] ? 1 : 0;
        if (core_set_bool(&c->d, &vr[i], 1, &tmp, BEFORE_RUN(c), c->err)) return core(c, "fmi3SetBoolean", 1);
    }
    return fmi3OK;
}

/* Types this FMU has no variables of. */
#define NONE_GET(fn, T) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) { \
    ALLOW(#fn, ANY_LIVE); (void)v; (void)nv; \
    return n ? fail(c, #fn, "no variable of this type has value reference %u", vr[0]) : fmi3OK; }
#define NONE_SET(fn, T) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv) { \
    ALLOW(#fn, ANY_LIVE); (void)v; (void)nv; \
    return n ? fail(c, #fn, "no variable of this type has value reference %u", vr[0]) : fmi3OK; }
NONE_GET(fmi3GetFloat32, fmi3Float32) NONE_SET(fmi3SetFloat32, fmi3Float32)
NONE_GET(fmi3GetInt8, fmi3Int8)       NONE_SET(fmi3SetInt8, fmi3Int8)
NONE_GET(fmi3GetUInt8, fmi3UInt8)     NONE_SET(fmi3SetUInt8, fmi3UInt8)
NONE_GET(fmi3GetInt16, fmi3Int16)     NONE_SET(fmi3SetInt16, fmi3Int16)
NONE_GET(fmi3GetUInt16, fmi3UInt16)   NONE_SET(fmi3SetUInt16, fmi3UInt16)
NONE_GET(fmi3GetUInt32, fmi3UInt32)   NONE_SET(fmi3SetUInt32, fmi3UInt32)
NONE_GET(fmi3GetUInt64, fmi3UInt64)   NONE_SET(fmi3SetUInt64, fmi3UInt64)
NONE_GET(fmi3GetString, fmi3String)   NONE_SET(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, size_t sizes[], fmi3Binary v[], size_t nv) {
    ALLOW("fmi3GetBinary", ANY_LIVE); (void)sizes; (void)v; (void)nv;
    return n ? fail(c, "fmi3GetBinary", "no Binary variable has value reference %u", vr[0]) : fmi3OK;
}
fmi3Status fmi3SetBinary(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const size_t sizes[], const fmi3Binary v[], size_t nv) {
    ALLOW("fmi3SetBinary", ANY_LIVE); (void)sizes; (void)v; (void)nv;
    return n ? fail(c, "fmi3SetBinary", "no Binary variable has value reference %u", vr[0]) : fmi3OK;
}
fmi3Status fmi3GetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    ALLOW("fmi3GetClock", ANY_LIVE); (void)v;
    return n ? fail(c, "fmi3GetClock", "no Clock variable has value reference %u", vr[0]) : fmi3OK;
}
fmi3Status fmi3SetClock(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    ALLOW("fmi3SetClock", ANY_LIVE); (void)v;
    return n ? fail(c, "fmi3SetClock", "no Clock variable has value reference %u", vr[0]) : fmi3OK;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance inst, fmi3ValueReference vr, size_t *n) {
    ALLOW("fmi3GetNumberOfVariableDependencies", ANY_LIVE); (void)vr; (void)n;
    UNSUPPORTED("fmi3GetNumberOfVariableDependencies", "not supported: read the dependencies from the ModelStructure");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance inst, fmi3ValueReference dep, size_t ei[], fmi3ValueReference ind[],
                                       size_t eii[], fmi3DependencyKind kinds[], size_t n) {
    ALLOW("fmi3GetVariableDependencies", ANY_LIVE); (void)dep; (void)ei; (void)ind; (void)eii; (void)kinds; (void)n;
    UNSUPPORTED("fmi3GetVariableDependencies", "not supported: read the dependencies from the ModelStructure");
}

/* ------------------------------------------------------------------ FMU state */
fmi3Status fmi3GetFMUState(fmi3Instance inst, fmi3FMUState *s) {
    ALLOW("fmi3GetFMUState", ANY_LIVE);
    if (!s) return fail(c, "fmi3GetFMUState", "FMUState pointer is NULL");
    if (!*s && !(*s = calloc(1, sizeof(SavedState)))) return fail(c, "fmi3GetFMUState", "out of memory");
    save_state((SavedState *)*s, c);
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance inst, fmi3FMUState s) {
    ALLOW("fmi3SetFMUState", ANY_LIVE);
    return restore_state(c, "fmi3SetFMUState", (const SavedState *)s);
}

fmi3Status fmi3FreeFMUState(fmi3Instance inst, fmi3FMUState *s) {
    ALLOW("fmi3FreeFMUState", ANY_LIVE | B(M_ERROR));
    if (s && *s) { free(*s); *s = NULL; }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance inst, fmi3FMUState s, size_t *size) {
    ALLOW("fmi3SerializedFMUStateSize", ANY_LIVE); (void)s;
    *size = sizeof(SavedState);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance inst, fmi3FMUState s, fmi3Byte out[], size_t size) {
    ALLOW("fmi3SerializeFMUState", ANY_LIVE);
    if (!s) return fail(c, "fmi3SerializeFMUState", "FMUState is NULL");
    if (size < sizeof(SavedState)) return fail(c, "fmi3SerializeFMUState", "buffer of %zu bytes, need %zu", size, sizeof(SavedState));
    memcpy(out, s, sizeof(SavedState));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance inst, const fmi3Byte in[], size_t size, fmi3FMUState *s) {
    SavedState tmp;
    ALLOW("fmi3DeserializeFMUState", ANY_LIVE);
    if (deserialize_state((const unsigned char *)in, size, &tmp, c->err)) return core(c, "fmi3DeserializeFMUState", 1);
    if (!*s && !(*s = calloc(1, sizeof(SavedState)))) return fail(c, "fmi3DeserializeFMUState", "out of memory");
    memcpy(*s, &tmp, sizeof tmp);
    return fmi3OK;
}

/* ------------------------------------------------------------------ derivatives */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance inst, const fmi3ValueReference unk[], size_t nU,
                                        const fmi3ValueReference kn[], size_t nK, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sens[], size_t nSens) {
    ALLOW("fmi3GetDirectionalDerivative", B(M_INIT) | RUNNING);
    if (!CORE_HAS_DERIVATIVES) return fail(c, "fmi3GetDirectionalDerivative", "not provided by this FMU");
    if (nSeed != nK || nSens != nU) return fail(c, "fmi3GetDirectionalDerivative", "nSeed must equal nKnowns and nSensitivity nUnknowns (scalar variables)");
    return core(c, "fmi3GetDirectionalDerivative", core_directional(&c->wk, &c->d, unk, nU, kn, nK, seed, sens, c->err));
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance inst, const fmi3ValueReference unk[], size_t nU,
                                    const fmi3ValueReference kn[], size_t nK, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sens[], size_t nSens) {
    ALLOW("fmi3GetAdjointDerivative", B(M_INIT) | RUNNING);
    if (!CORE_HAS_DERIVATIVES) return fail(c, "fmi3GetAdjointDerivative", "not provided by this FMU");
    /* v^T J: accumulate row by row with the directional derivative of each known */
    if (nSeed != nU || nSens != nK) return fail(c, "fmi3GetAdjointDerivative", "nSeed must equal nUnknowns and nSensitivity nKnowns (scalar variables)");
    for (size_t k = 0; k < nK; k++) {
        double one = 1.0, col[256];
        if (nU > 256) return fail(c, "fmi3GetAdjointDerivative", "too many unknowns (at most 256)");
        if (core_directional(&c->wk, &c->d, unk, nU, &kn[k], 1, &one, col, c->err)) return core(c, "fmi3GetAdjointDerivative", 1);
        sens[k] = 0;
        for (size_t i = 0; i < nU; i++) sens[k] += seed[i] * col[i];
    }
    return fmi3OK;
}

/* ------------------------------------------------------------------ configuration, clocks: not used */
fmi3Status fmi3EnterConfigurationMode(fmi3Instance inst) {
    ALLOW("fmi3EnterConfigurationMode", ANY_LIVE);
    UNSUPPORTED("fmi3EnterConfigurationMode", "this FMU has no structural parameters");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance inst) {
    ALLOW("fmi3ExitConfigurationMode", ANY_LIVE);
    UNSUPPORTED("fmi3ExitConfigurationMode", "this FMU has no structural parameters");
}
#define NO_CLOCKS(fn, ...) fmi3Status fn(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, __VA_ARGS__) { \
    ALLOW(#fn, ANY_LIVE); (void)vr; (void)n; UNSUPPORTED(#fn, "this FMU has no clocks"); }
NO_CLOCKS(fmi3GetIntervalDecimal, fmi3Float64 iv[], fmi3IntervalQualifier q[])
NO_CLOCKS(fmi3GetIntervalFraction, fmi3UInt64 cn[], fmi3UInt64 rs[], fmi3IntervalQualifier q[])
NO_CLOCKS(fmi3GetShiftDecimal, fmi3Float64 sh[])
NO_CLOCKS(fmi3GetShiftFraction, fmi3UInt64 cn[], fmi3UInt64 rs[])
NO_CLOCKS(fmi3SetIntervalDecimal, const fmi3Float64 iv[])
NO_CLOCKS(fmi3SetIntervalFraction, const fmi3UInt64 cn[], const fmi3UInt64 rs[])
NO_CLOCKS(fmi3SetShiftDecimal, const fmi3Float64 sh[])
NO_CLOCKS(fmi3SetShiftFraction, const fmi3UInt64 cn[], const fmi3UInt64 rs[])

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance inst) {
    ALLOW("fmi3EvaluateDiscreteStates", ANY_LIVE);
    return fmi3OK;   /* no discrete states */
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance inst, fmi3Boolean *need, fmi3Boolean *term, fmi3Boolean *nom,
                                    fmi3Boolean *vals, fmi3Boolean *nextDef, fmi3Float64 *next) {
    ALLOW("fmi3UpdateDiscreteStates", B(M_EVENT) | B(M_STEP));
    *need = fmi3False; *term = fmi3False; *nom = fmi3False; *vals = fmi3False; *nextDef = fmi3False; *next = 0;
    return fmi3OK;
}

/* ------------------------------------------------------------------ Model Exchange */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance inst) {
    ALLOW("fmi3EnterContinuousTimeMode", B(M_EVENT));
    c->mode = M_CONT;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance inst, fmi3Boolean noSetPrior, fmi3Boolean *enter, fmi3Boolean *term) {
    ALLOW("fmi3CompletedIntegratorStep", B(M_CONT)); (void)noSetPrior;
    *enter = fmi3False; *term = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance inst, fmi3Float64 t) {
    ALLOW("fmi3SetTime", B(M_EVENT) | B(M_CONT));
    if (!isfinite(t)) return fail(c, "fmi3SetTime", "time %g is not finite", t);
    core_set_time(&c->d, t);
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance inst, const fmi3Float64 x[], size_t nx) {
    ALLOW("fmi3SetContinuousStates", B(M_CONT));
    return core(c, "fmi3SetContinuousStates", core_set_states(&c->d, x, nx, c->err));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance inst, fmi3Float64 dx[], size_t nx) {
    ALLOW("fmi3GetContinuousStateDerivatives", B(M_INIT) | B(M_EVENT) | B(M_CONT) | B(M_TERMINATED));
    if (nx != CORE_NX) return fail(c, "fmi3GetContinuousStateDerivatives", "nx = %zu, this model has %d states", nx, CORE_NX);
    return core(c, "fmi3GetContinuousStateDerivatives", core_derivatives(&c->wk, &c->d, dx, c->err));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance inst, fmi3Float64 ind[], size_t ni) {
    ALLOW("fmi3GetEventIndicators", ANY_LIVE); (void)ind;
    return ni ? fail(c, "fmi3GetEventIndicators", "this model has no event indicators") : fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance inst, fmi3Float64 x[], size_t nx) {
    ALLOW("fmi3GetContinuousStates", ANY_LIVE);
    if (nx != CORE_NX) return fail(c, "fmi3GetContinuousStates", "nx = %zu, this model has %d states", nx, CORE_NX);
    core_get_states(&c->d, x);
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance inst, fmi3Float64 nom[], size_t nx) {
    ALLOW("fmi3GetNominalsOfContinuousStates", ANY_LIVE);
    if (nx != CORE_NX) return fail(c, "fmi3GetNominalsOfContinuousStates", "nx = %zu, this model has %d states", nx, CORE_NX);
    for (size_t i = 0; i < nx; i++) nom[i] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance inst, size_t *n) {
    ALLOW("fmi3GetNumberOfEventIndicators", ANY_LIVE);
    *n = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance inst, size_t *n) {
    ALLOW("fmi3GetNumberOfContinuousStates", ANY_LIVE);
    *n = CORE_NX;
    return fmi3OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance inst) {
    ALLOW("fmi3EnterStepMode", B(M_EVENT) | B(M_STEP));
    if (c->kind != CS) return fail(c, "fmi3EnterStepMode", "instance is not a Co-Simulation instance");
    c->mode = M_STEP;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance inst, const fmi3ValueReference vr[], size_t n,
                                    const fmi3Int32 orders[], fmi3Float64 v[], size_t nv) {
    ALLOW("fmi3GetOutputDerivatives", ANY_LIVE); (void)vr; (void)orders; (void)v; (void)nv;
    return n ? fail(c, "fmi3GetOutputDerivatives", "output derivatives are not provided (maxOutputDerivativeOrder=0)") : fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance inst, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetPrior,
                      fmi3Boolean *eventNeeded, fmi3Boolean *term, fmi3Boolean *early, fmi3Float64 *last) {
    ALLOW("fmi3DoStep", B(M_STEP)); (void)noSetPrior;
    if (c->kind != CS) return fail(c, "fmi3DoStep", "instance was not instantiated for Co-Simulation");
    *eventNeeded = fmi3False; *term = fmi3False; *early = fmi3False;
    if (core_do_step(&c->wk, &c->d, t, h, c->err)) { *last = core_time(&c->d); return core(c, "fmi3DoStep", 1); }
    *last = core_time(&c->d);
    return fmi3OK;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance inst, fmi3ValueReference clk, fmi3Float64 t) {
    ALLOW("fmi3ActivateModelPartition", ANY_LIVE); (void)clk; (void)t;
    UNSUPPORTED("fmi3ActivateModelPartition", "Scheduled Execution is not supported by this FMU");
}
