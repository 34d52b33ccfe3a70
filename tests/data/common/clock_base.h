/* Shared by the hand-written clocked FMI 3.0 test FMUs of pendulum-cosim's tests
 * (tests/data/clock_lab, tests/data/clock_loop, tests/data/clock_bench); independent of
 * pendulum-cosim's code.
 *
 * Every instance keeps the FMI state it is in and checks each call against the FMI 3.0
 * rules for it. A call the standard forbids is a "violation": it is reported through the
 * logger as "ILLEGAL: <what>" (status error), counted in the instance's violation count,
 * appended to the call log, and answered with fmi3Error (the instance is then in the
 * error state, where only fmi3FreeInstance, fmi3Reset and the logging function are
 * allowed, as after any error).
 *
 * The call log: if the environment variable CLOCK_FMU_LOG names a file, every call is
 * appended to it as one line "<instance> <function> <details>", and every violation as
 * "<instance> ILLEGAL <what>". */
#ifndef CLOCK_BASE_H
#define CLOCK_BASE_H

#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"

enum {
    S_INSTANTIATED, S_INIT, S_EVENT, S_CONT, S_STEP, S_ACTIVATION, S_TERMINATED, S_ERROR, S_FATAL, S_FREED
};
static const char *STATE_NAME[] = {"Instantiated", "InitializationMode", "EventMode", "ContinuousTimeMode",
                                   "StepMode", "ClockActivationMode", "Terminated", "error", "fatal", "freed"};
enum { KIND_ME, KIND_CS, KIND_SE };

typedef struct {
    int state, kind, violations;
    char name[64];
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logger;
    fmi3ClockUpdateCallback clock_update;
    bool event_mode_used, early_return_allowed;
    double time;
} Base;

#define TOL 1e-9

static void call_log(Base *b, const char *fmt, ...) {
    const char *path = getenv("CLOCK_FMU_LOG");
    FILE *f;
    va_list ap;
    if (!path || !(f = fopen(path, "a"))) return;
    fprintf(f, "%s ", b->name);
    va_start(ap, fmt);
    vfprintf(f, fmt, ap);
    va_end(ap);
    fputc('\n', f);
    fclose(f);
}

/* a call answered with fmi3Error: the line `logged` in the call log, the message through the
 * logger, the instance in the error state */
static fmi3Status refused(Base *b, const char *logged, const char *message) {
    call_log(b, "%s", logged);
    if (b->logger) b->logger(b->env, fmi3Error, "logStatusError", message);
    if (b->state != S_FATAL && b->state != S_FREED) b->state = S_ERROR;
    return fmi3Error;
}

/* a violation of the call rules: logged, counted; the caller returns fmi3Error */
static fmi3Status violation(Base *b, const char *fmt, ...) {
    char text[512], logged[600], msg[600];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    b->violations++;
    snprintf(logged, sizeof logged, "ILLEGAL %s", text);
    snprintf(msg, sizeof msg, "ILLEGAL: %s", text);
    return refused(b, logged, msg);
}

/* may any call but FreeInstance/Reset/SetDebugLogging be made now? */
static bool usable(Base *b, const char *fn) {
    if (b->state == S_ERROR || b->state == S_FATAL || b->state == S_FREED) {
        int was = b->state;
        violation(b, "%s after %s", fn, STATE_NAME[was]);
        if (was != S_ERROR) b->state = was;
        return false;
    }
    return true;
}

/* the call is allowed only in the states of mask (bit per state) */
#define M(s) (1 << (s))
static bool in_states(Base *b, const char *fn, int mask) {
    if (!usable(b, fn)) return false;
    if (!(mask & M(b->state))) {
        violation(b, "%s in %s", fn, STATE_NAME[b->state]);
        return false;
    }
    return true;
}

static bool near(double a, double b) { return fabs(a - b) <= TOL * fmax(1.0, fabs(b)); }

/* nValues must equal nValueReferences (every variable is a scalar) */
static bool scalars(Base *b, const char *fn, size_t n, size_t nv) {
    if (nv == n) return true;
    violation(b, "%s with nValues %zu for %zu scalars", fn, nv, n);
    return false;
}

/* --- instantiation ---
 * A zeroed instance of `size` bytes whose first member is its Base, in Instantiated (NULL:
 * out of memory). */
static void *new_instance(size_t size, fmi3String name, int kind, fmi3InstanceEnvironment env,
                          fmi3LogMessageCallback logger) {
    Base *b = (Base *)calloc(1, size);
    if (!b) return NULL;
    strncpy(b->name, name ? name : "?", sizeof(b->name) - 1);
    b->kind = kind;
    b->env = env;
    b->logger = logger;
    b->state = S_INSTANTIATED;
    return b;
}

/* Each FMU defines create: a new instance of interface `kind` (KIND_ME, KIND_CS, KIND_SE), or
 * NULL for a wrong token or an interface it does not have. Its instantiation functions are
 * these: Co-Simulation requires Event Mode (as an FMU with clocks needs it), Scheduled
 * Execution a clockUpdate callback. */
static void *create(fmi3String name, fmi3String token, int kind, fmi3InstanceEnvironment env,
                    fmi3LogMessageCallback logger);

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
                                          fmi3Boolean log, fmi3InstanceEnvironment env, fmi3LogMessageCallback cb) {
    (void)res; (void)vis; (void)log;
    return create(name, token, KIND_ME, env, cb);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
                                         fmi3Boolean log, fmi3Boolean evt, fmi3Boolean early,
                                         const fmi3ValueReference req[], size_t nreq, fmi3InstanceEnvironment env,
                                         fmi3LogMessageCallback cb, fmi3IntermediateUpdateCallback upd) {
    Base *b;
    (void)res; (void)vis; (void)log; (void)req; (void)nreq; (void)upd;
    b = (Base *)create(name, token, KIND_CS, env, cb);
    if (!b) return NULL;
    b->event_mode_used = evt;
    b->early_return_allowed = early;
    call_log(b, "eventModeUsed=%d earlyReturnAllowed=%d", (int)evt, (int)early);
    if (!evt) violation(b, "fmi3InstantiateCoSimulation with eventModeUsed = false: an FMU with clocks requires it");
    return b;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
                                               fmi3Boolean log, fmi3InstanceEnvironment env, fmi3LogMessageCallback cb,
                                               fmi3ClockUpdateCallback cu, fmi3LockPreemptionCallback lock,
                                               fmi3UnlockPreemptionCallback unlock) {
    Base *b;
    (void)res; (void)vis; (void)log; (void)lock; (void)unlock;
    b = (Base *)create(name, token, KIND_SE, env, cb);
    if (!b) return NULL;
    b->clock_update = cu;
    if (!cu) violation(b, "fmi3InstantiateScheduledExecution without a clockUpdate callback");
    return b;
}

/* --- functions none of these FMUs supports: an error with a message, never a crash --- */
static fmi3Status unsupported(fmi3Instance inst, const char *fn) {
    char msg[200];
    if (!inst) return fmi3Error;
    snprintf(msg, sizeof msg, "%s is not supported by this FMU", fn);
    return refused((Base *)inst, fn, msg);
}

#define UNSUPPORTED_GET(NAME, T)                                                                     \
    fmi3Status fmi3Get##NAME(fmi3Instance i, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) { \
        (void)vr; (void)n; (void)v; (void)nv; return unsupported(i, "fmi3Get" #NAME); }
#define UNSUPPORTED_SET(NAME, T)                                                                           \
    fmi3Status fmi3Set##NAME(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv) { \
        (void)vr; (void)n; (void)v; (void)nv; return unsupported(i, "fmi3Set" #NAME); }

/* --- Model Exchange: the functions of an FMU that defines WITH_MODEL_EXCHANGE before including
 * this, and, for its instance b, the functions declared here (arrays of n_states or
 * n_indicators values). States are set in Continuous-Time and Event Mode, the integrator step
 * completes in Continuous-Time Mode; the getters answer in any state but the error states. */
#ifdef WITH_MODEL_EXCHANGE
static size_t n_states(Base *b);
static size_t n_indicators(Base *b);
static void get_states(Base *b, double x[]);
static void set_states(Base *b, const double x[]);
static void derivatives(Base *b, double dx[]);
static void indicators(Base *b, double z[]);

/* The instance of a call passing n values where the model has count(b) (`what`: states,
 * indicators), allowed in the states of mask (0: any state but the error states); NULL after
 * refusing it. */
static Base *me_call(fmi3Instance inst, const char *fn, int mask, size_t n, size_t (*count)(Base *),
                     const char *what) {
    Base *b = (Base *)inst;
    if (!b || !(mask ? in_states(b, fn, mask) : usable(b, fn))) return NULL;
    if (n != count(b)) {
        violation(b, "%s with %zu %s (%zu)", fn, n, what, count(b));
        return NULL;
    }
    return b;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance inst, const fmi3Float64 x[], size_t n) {
    Base *b = me_call(inst, "fmi3SetContinuousStates", M(S_CONT) | M(S_EVENT), n, n_states, "states");
    if (!b) return fmi3Error;
    set_states(b, x);
    return fmi3OK;
}
#define ME_GETTER(fn, count, what, get) fmi3Status fn(fmi3Instance inst, fmi3Float64 v[], size_t n) { \
    Base *b = me_call(inst, #fn, 0, n, count, what); if (!b) return fmi3Error; get(b, v); return fmi3OK; }
ME_GETTER(fmi3GetContinuousStates, n_states, "states", get_states)
ME_GETTER(fmi3GetContinuousStateDerivatives, n_states, "states", derivatives)
ME_GETTER(fmi3GetEventIndicators, n_indicators, "indicators", indicators)

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance inst, fmi3Float64 x[], size_t n) {
    Base *b = (Base *)inst;
    if (!b || !usable(b, "fmi3GetNominalsOfContinuousStates")) return fmi3Error;
    for (size_t i = 0; i < n; i++) x[i] = 1.0;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance inst, size_t *n) { *n = n_indicators((Base *)inst); return fmi3OK; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance inst, size_t *n) { *n = n_states((Base *)inst); return fmi3OK; }

fmi3Status fmi3SetTime(fmi3Instance inst, fmi3Float64 t) {
    Base *b = (Base *)inst;
    if (!b || !in_states(b, "fmi3SetTime", M(S_CONT) | M(S_EVENT))) return fmi3Error;
    b->time = t;
    return fmi3OK;
}
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance inst, fmi3Boolean nsp, fmi3Boolean *enter, fmi3Boolean *term) {
    Base *b = (Base *)inst;
    (void)nsp;
    if (!b || !in_states(b, "fmi3CompletedIntegratorStep", M(S_CONT))) return fmi3Error;
    *enter = false;
    *term = false;
    return fmi3OK;
}
#endif

/* The interval functions of an FMU whose clocks answer only fmi3GetIntervalDecimal */
#define DECIMAL_INTERVAL_STUBS                                                                               \
    fmi3Status fmi3GetIntervalFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[], fmi3IntervalQualifier q[]) { \
        (void)vr; (void)n; (void)c; (void)r; (void)q; return unsupported(i, "fmi3GetIntervalFraction"); }   \
    fmi3Status fmi3SetIntervalDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Float64 iv[]) { \
        (void)vr; (void)n; (void)iv; return unsupported(i, "fmi3SetIntervalDecimal"); }                    \
    fmi3Status fmi3SetIntervalFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c[], const fmi3UInt64 r[]) { \
        (void)vr; (void)n; (void)c; (void)r; return unsupported(i, "fmi3SetIntervalFraction"); }           \
    fmi3Status fmi3GetShiftDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]) { \
        (void)vr; (void)n; (void)s; return unsupported(i, "fmi3GetShiftDecimal"); }                        \
    fmi3Status fmi3GetShiftFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[]) { \
        (void)vr; (void)n; (void)c; (void)r; return unsupported(i, "fmi3GetShiftFraction"); }

#define COMMON_STUBS                                                                                         \
    const char *fmi3GetVersion(void) { return fmi3Version; }                                                \
    fmi3Status fmi3GetString(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3String v[], size_t nv) { \
        (void)vr; (void)n; (void)v; (void)nv; return unsupported(i, "fmi3GetString"); }                    \
    fmi3Status fmi3SetString(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3String v[], size_t nv) { \
        (void)vr; (void)n; (void)v; (void)nv; return unsupported(i, "fmi3SetString"); }                    \
    fmi3Status fmi3GetBinary(fmi3Instance i, const fmi3ValueReference vr[], size_t n, size_t s[], fmi3Binary v[], size_t nv) { \
        (void)vr; (void)n; (void)s; (void)v; (void)nv; return unsupported(i, "fmi3GetBinary"); }           \
    fmi3Status fmi3SetBinary(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const size_t s[], const fmi3Binary v[], size_t nv) { \
        (void)vr; (void)n; (void)s; (void)v; (void)nv; return unsupported(i, "fmi3SetBinary"); }           \
    UNSUPPORTED_GET(Float32, fmi3Float32) UNSUPPORTED_SET(Float32, fmi3Float32)                             \
    UNSUPPORTED_GET(Int8, fmi3Int8) UNSUPPORTED_SET(Int8, fmi3Int8)                                         \
    UNSUPPORTED_GET(UInt8, fmi3UInt8) UNSUPPORTED_SET(UInt8, fmi3UInt8)                                     \
    UNSUPPORTED_GET(Int16, fmi3Int16) UNSUPPORTED_SET(Int16, fmi3Int16)                                     \
    UNSUPPORTED_GET(UInt16, fmi3UInt16) UNSUPPORTED_SET(UInt16, fmi3UInt16)                                 \
    UNSUPPORTED_GET(UInt32, fmi3UInt32) UNSUPPORTED_SET(UInt32, fmi3UInt32)                                 \
    UNSUPPORTED_GET(Int64, fmi3Int64) UNSUPPORTED_SET(Int64, fmi3Int64)                                     \
    UNSUPPORTED_GET(UInt64, fmi3UInt64) UNSUPPORTED_SET(UInt64, fmi3UInt64)                                 \
    UNSUPPORTED_GET(Boolean, fmi3Boolean) UNSUPPORTED_SET(Boolean, fmi3Boolean)                             \
    fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance i, fmi3ValueReference vr, size_t *n) {     \
        (void)vr; (void)n; return unsupported(i, "fmi3GetNumberOfVariableDependencies"); }                 \
    fmi3Status fmi3GetVariableDependencies(fmi3Instance i, fmi3ValueReference d, size_t e[], fmi3ValueReference k[], size_t ke[], fmi3DependencyKind dk[], size_t n) { \
        (void)d; (void)e; (void)k; (void)ke; (void)dk; (void)n; return unsupported(i, "fmi3GetVariableDependencies"); } \
    fmi3Status fmi3GetFMUState(fmi3Instance i, fmi3FMUState *s) { (void)s; return unsupported(i, "fmi3GetFMUState"); } \
    fmi3Status fmi3SetFMUState(fmi3Instance i, fmi3FMUState s) { (void)s; return unsupported(i, "fmi3SetFMUState"); } \
    fmi3Status fmi3FreeFMUState(fmi3Instance i, fmi3FMUState *s) { (void)s; return unsupported(i, "fmi3FreeFMUState"); } \
    fmi3Status fmi3SerializedFMUStateSize(fmi3Instance i, fmi3FMUState s, size_t *n) { (void)s; (void)n; return unsupported(i, "fmi3SerializedFMUStateSize"); } \
    fmi3Status fmi3SerializeFMUState(fmi3Instance i, fmi3FMUState s, fmi3Byte b[], size_t n) { (void)s; (void)b; (void)n; return unsupported(i, "fmi3SerializeFMUState"); } \
    fmi3Status fmi3DeserializeFMUState(fmi3Instance i, const fmi3Byte b[], size_t n, fmi3FMUState *s) { (void)b; (void)n; (void)s; return unsupported(i, "fmi3DeserializeFMUState"); } \
    fmi3Status fmi3GetDirectionalDerivative(fmi3Instance i, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[], size_t nk, const fmi3Float64 s[], size_t ns, fmi3Float64 r[], size_t nr) { \
        (void)u; (void)nu; (void)k; (void)nk; (void)s; (void)ns; (void)r; (void)nr; return unsupported(i, "fmi3GetDirectionalDerivative"); } \
    fmi3Status fmi3GetAdjointDerivative(fmi3Instance i, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[], size_t nk, const fmi3Float64 s[], size_t ns, fmi3Float64 r[], size_t nr) { \
        (void)u; (void)nu; (void)k; (void)nk; (void)s; (void)ns; (void)r; (void)nr; return unsupported(i, "fmi3GetAdjointDerivative"); } \
    fmi3Status fmi3EnterConfigurationMode(fmi3Instance i) { return unsupported(i, "fmi3EnterConfigurationMode"); } \
    fmi3Status fmi3ExitConfigurationMode(fmi3Instance i) { return unsupported(i, "fmi3ExitConfigurationMode"); } \
    fmi3Status fmi3SetShiftDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Float64 s[]) { \
        (void)vr; (void)n; (void)s; return unsupported(i, "fmi3SetShiftDecimal"); }                       \
    fmi3Status fmi3SetShiftFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c[], const fmi3UInt64 r[]) { \
        (void)vr; (void)n; (void)c; (void)r; return unsupported(i, "fmi3SetShiftFraction"); }              \
    fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance i) { return unsupported(i, "fmi3EvaluateDiscreteStates"); } \
    fmi3Status fmi3GetOutputDerivatives(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Int32 o[], fmi3Float64 v[], size_t nv) { \
        (void)vr; (void)n; (void)o; (void)v; (void)nv; return unsupported(i, "fmi3GetOutputDerivatives"); } \
    fmi3Status fmi3SetDebugLogging(fmi3Instance i, fmi3Boolean on, size_t n, const fmi3String c[]) {       \
        (void)on; (void)n; (void)c; if (!i) return fmi3Error; return fmi3OK; }

#endif
