/* ClockBench: a minimal hand-written FMI 3.0 FMU with one clock, for the benchmark of the
 * master's cost per tick (bench/bench_clocks.py); independent of pendulum-cosim's code.
 * Co-Simulation with Event Mode and Scheduled Execution: the constant clock "tick"
 * (every 1 ms) clocks the input u and the output y = u + n (n: the ticks so far; not
 * declared in the model description, so that only Float64 values are exchanged). The few
 * checks it makes are cheap: clocks set only in Event Mode, clocked variables exchanged only
 * while "tick" is active (Scheduled Execution: after its partition ran), fmi3DoStep only in
 * Step Mode and never over a tick; a violation is an fmi3Error with a message. */
#include "../common/clock_base.h"

#define TOKEN "{c10c6e4c-0b3e-4a55-9d1e-clockbench01}"
#define INTERVAL 0.001
enum { VR_TICK = 1, VR_U = 2, VR_Y = 3, VR_N = 4 };

typedef struct {
    Base b;
    double u, next;
    int32_t n;
    bool active, ran;
} Bench;

static void *create(fmi3String name, fmi3String token, int kind, fmi3InstanceEnvironment env, fmi3LogMessageCallback cb) {
    if (kind == KIND_ME || !token || strcmp(token, TOKEN)) return NULL;    /* no Model Exchange */
    return new_instance(sizeof(Bench), name, kind, env, cb);
}
void fmi3FreeInstance(fmi3Instance i) { free(i); }
fmi3Status fmi3Reset(fmi3Instance i) { return unsupported(i, "fmi3Reset"); }
fmi3Status fmi3EnterInitializationMode(fmi3Instance i, fmi3Boolean a, fmi3Float64 b, fmi3Float64 start, fmi3Boolean c, fmi3Float64 d) {
    Bench *m = (Bench *)i;
    (void)a; (void)b; (void)c; (void)d;
    if (!m || !in_states(&m->b, "fmi3EnterInitializationMode", M(S_INSTANTIATED))) return fmi3Error;
    m->b.time = m->next = start;
    m->b.state = S_INIT;
    return fmi3OK;
}
fmi3Status fmi3ExitInitializationMode(fmi3Instance i) {
    Bench *m = (Bench *)i;
    if (!m || !in_states(&m->b, "fmi3ExitInitializationMode", M(S_INIT))) return fmi3Error;
    m->b.state = m->b.kind == KIND_SE ? S_ACTIVATION : S_EVENT;
    return fmi3OK;
}
fmi3Status fmi3EnterEventMode(fmi3Instance i) {
    Bench *m = (Bench *)i;
    if (!m || !in_states(&m->b, "fmi3EnterEventMode", M(S_STEP))) return fmi3Error;
    m->b.state = S_EVENT;
    return fmi3OK;
}
fmi3Status fmi3SetClock(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    Bench *m = (Bench *)i;
    if (!m || !in_states(&m->b, "fmi3SetClock", M(S_EVENT))) return fmi3Error;
    if (n != 1 || vr[0] != VR_TICK || !v[0]) return violation(&m->b, "fmi3SetClock: only tick, only to activate");
    if (!near(m->b.time, m->next)) return violation(&m->b, "tick activated at %.17g, due at %.17g", m->b.time, m->next);
    m->active = true;
    m->n++;
    m->next += INTERVAL;
    return fmi3OK;
}
fmi3Status fmi3GetClock(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    (void)vr; (void)n; (void)v; return unsupported(i, "fmi3GetClock"); }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance i, fmi3Boolean *need, fmi3Boolean *term, fmi3Boolean *nomc,
                                    fmi3Boolean *valc, fmi3Boolean *nextDef, fmi3Float64 *next) {
    Bench *m = (Bench *)i;
    if (!m || !in_states(&m->b, "fmi3UpdateDiscreteStates", M(S_EVENT))) return fmi3Error;
    m->active = false;
    *need = *term = *nomc = *valc = *nextDef = false;
    *next = 0;
    return fmi3OK;
}
fmi3Status fmi3EnterStepMode(fmi3Instance i) {
    Bench *m = (Bench *)i;
    if (!m || !in_states(&m->b, "fmi3EnterStepMode", M(S_EVENT))) return fmi3Error;
    if (m->active) return violation(&m->b, "fmi3EnterStepMode with tick active");
    m->b.state = S_STEP;
    return fmi3OK;
}
fmi3Status fmi3DoStep(fmi3Instance i, fmi3Float64 t, fmi3Float64 h, fmi3Boolean nsp, fmi3Boolean *ehn, fmi3Boolean *term,
                      fmi3Boolean *early, fmi3Float64 *last) {
    Bench *m = (Bench *)i;
    (void)nsp;
    if (!m || !in_states(&m->b, "fmi3DoStep", M(S_STEP))) return fmi3Error;
    if (m->next < t + h - TOL) return violation(&m->b, "fmi3DoStep over the tick at %.17g", m->next);
    m->b.time = t + h;
    *ehn = *term = *early = false;
    *last = m->b.time;
    return fmi3OK;
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance i, fmi3ValueReference vr, fmi3Float64 t) {
    Bench *m = (Bench *)i;
    if (!m || !in_states(&m->b, "fmi3ActivateModelPartition", M(S_ACTIVATION))) return fmi3Error;
    if (vr != VR_TICK) return violation(&m->b, "fmi3ActivateModelPartition of %u", vr);
    if (!near(t, m->next)) return violation(&m->b, "tick activated at %.17g, due at %.17g", t, m->next);
    m->b.time = t;
    m->n++;
    m->next += INTERVAL;
    m->ran = true;
    return fmi3OK;
}
static bool clocked_ok(Bench *m, const char *fn) {
    if (m->b.state == S_INSTANTIATED || m->b.state == S_INIT) return true;
    if (m->b.kind == KIND_SE ? m->ran : (m->b.state == S_EVENT && m->active)) return true;
    violation(&m->b, "%s of a variable clocked by tick while it is not active", fn);
    return false;
}
fmi3Status fmi3GetFloat64(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    Bench *m = (Bench *)i;
    if (!m || !usable(&m->b, "fmi3GetFloat64") || !scalars(&m->b, "fmi3GetFloat64", n, nv)) return fmi3Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == 0) { v[k] = m->b.time; continue; }
        if (!clocked_ok(m, "fmi3GetFloat64")) return fmi3Error;
        if (vr[k] == VR_U) v[k] = m->u;
        else if (vr[k] == VR_Y) v[k] = m->u + m->n;
        else return violation(&m->b, "fmi3GetFloat64 of %u", vr[k]);
    }
    return fmi3OK;
}
fmi3Status fmi3SetFloat64(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv) {
    Bench *m = (Bench *)i;
    if (!m || !usable(&m->b, "fmi3SetFloat64") || !scalars(&m->b, "fmi3SetFloat64", n, nv)) return fmi3Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != VR_U) return violation(&m->b, "fmi3SetFloat64 of %u", vr[k]);
        if (m->b.kind != KIND_SE && !clocked_ok(m, "fmi3SetFloat64")) return fmi3Error;
        m->u = v[k];
    }
    return fmi3OK;
}
fmi3Status fmi3GetInt32(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Int32 v[], size_t nv) {
    Bench *m = (Bench *)i;
    if (!m || !usable(&m->b, "fmi3GetInt32") || !scalars(&m->b, "fmi3GetInt32", n, nv)) return fmi3Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != VR_N || !clocked_ok(m, "fmi3GetInt32")) return violation(&m->b, "fmi3GetInt32 of %u", vr[k]);
        v[k] = m->n;
    }
    return fmi3OK;
}
fmi3Status fmi3SetInt32(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Int32 v[], size_t nv) {
    (void)vr; (void)n; (void)v; (void)nv; return unsupported(i, "fmi3SetInt32"); }
fmi3Status fmi3Terminate(fmi3Instance i) {
    Bench *m = (Bench *)i;
    if (!m || !in_states(&m->b, "fmi3Terminate", M(S_EVENT) | M(S_STEP) | M(S_ACTIVATION))) return fmi3Error;
    m->b.state = S_TERMINATED;
    return fmi3OK;
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[], fmi3IntervalQualifier q[]) {
    (void)vr; for (size_t k = 0; k < n; k++) iv[k] = INTERVAL, q[k] = fmi3IntervalUnchanged; (void)i; return fmi3OK; }
DECIMAL_INTERVAL_STUBS
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance i) { return unsupported(i, "fmi3EnterContinuousTimeMode"); }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance i, fmi3Boolean a, fmi3Boolean *b, fmi3Boolean *c) {
    (void)a; (void)b; (void)c; return unsupported(i, "fmi3CompletedIntegratorStep"); }
fmi3Status fmi3SetTime(fmi3Instance i, fmi3Float64 t) { (void)t; return unsupported(i, "fmi3SetTime"); }
fmi3Status fmi3SetContinuousStates(fmi3Instance i, const fmi3Float64 x[], size_t n) { (void)x; (void)n; return unsupported(i, "fmi3SetContinuousStates"); }
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance i, fmi3Float64 d[], size_t n) { (void)d; (void)n; return unsupported(i, "fmi3GetContinuousStateDerivatives"); }
fmi3Status fmi3GetEventIndicators(fmi3Instance i, fmi3Float64 z[], size_t n) { (void)z; (void)n; return unsupported(i, "fmi3GetEventIndicators"); }
fmi3Status fmi3GetContinuousStates(fmi3Instance i, fmi3Float64 x[], size_t n) { (void)x; (void)n; return unsupported(i, "fmi3GetContinuousStates"); }
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance i, fmi3Float64 x[], size_t n) { (void)x; (void)n; return unsupported(i, "fmi3GetNominalsOfContinuousStates"); }
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance i, size_t *n) { (void)n; return unsupported(i, "fmi3GetNumberOfEventIndicators"); }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance i, size_t *n) { (void)n; return unsupported(i, "fmi3GetNumberOfContinuousStates"); }

COMMON_STUBS
