/* A hand-written FMI 3.0 Model Exchange test FMU (independent of pendulum-cosim's generator): a
 * damped oscillator x0' = x1, x1' = -k x0 - c x1 + u, output y = x0 + 0.1 x1, that misbehaves
 * on request (the parameter mode) once x0 exceeds the parameter limit:
 *   1 its derivatives are NaN, 2 GetContinuousStateDerivatives returns Error, 3 its event
 *   indicator x0 - limit changes sign (a state event), 5 GetContinuousStateDerivatives returns
 *   Fatal, 6 CompletedIntegratorStep asks for Event Mode (a step event);
 *   4 it schedules a time event at t = 0.5 s; 7 its directional derivatives are 1.5 times the
 *   true ones.
 * Every call is checked against the FMI 3.0 state machine (after Error only FreeInstance, Reset
 * or SetFMUState; after Fatal nothing): a forbidden call is appended to the file named by the
 * environment variable HOSTILE_LOG ("VIOLATION <call> in <state>"), as is every Error and Fatal
 * returned ("RETURNED <status> <call>"). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"

enum { INSTANTIATED = 1, INIT = 2, EVENT = 4, CONT = 8, TERMINATED = 16, ERROR = 32, FATAL = 64 };
enum { VR_TIME, VR_X0, VR_DX0, VR_X1, VR_DX1, VR_U, VR_Y, VR_K, VR_C, VR_MODE, VR_LIMIT, NVR };
#define TOKEN "{5f1d7a2e-0c4b-4e8e-9a51-3b2f0c9d7e11}"

typedef struct {
    double v[NVR];
    int state, saved_state;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} M;

static const char *state_name(int s) {
    switch (s) {
    case INSTANTIATED: return "Instantiated";
    case INIT: return "InitializationMode";
    case EVENT: return "EventMode";
    case CONT: return "ContinuousTimeMode";
    case TERMINATED: return "Terminated";
    case ERROR: return "Error";
    default: return "Fatal";
    }
}

static void note(const char *what) {
    const char *path = getenv("HOSTILE_LOG");
    FILE *f = path ? fopen(path, "a") : NULL;
    if (f) {
        fprintf(f, "%s\n", what);
        fclose(f);
    }
}

static int allowed(M *m, const char *call, int mask) {
    char line[200];
    if (m->state & mask) return 1;
    snprintf(line, sizeof line, "VIOLATION %s in %s", call, state_name(m->state));
    note(line);
    return 0;
}

static fmi3Status fail(M *m, const char *call, fmi3Status st, const char *msg) {
    char line[200];
    snprintf(line, sizeof line, "RETURNED %s %s", st == fmi3Fatal ? "Fatal" : "Error", call);
    note(line);
    if (m->log) m->log(m->env, st, "logStatusError", msg);
    m->state = st == fmi3Fatal ? FATAL : ERROR;
    return st;
}

#define MODE(m) ((int)(m)->v[VR_MODE])
#define PAST(m) ((m)->v[VR_X0] > (m)->v[VR_LIMIT])
#define CHECK(m, call, mask) do { if (!allowed(m, call, mask)) return fmi3Error; } while (0)
#define ANY (INSTANTIATED | INIT | EVENT | CONT | TERMINATED)

static void derivs(M *m) {
    m->v[VR_DX0] = m->v[VR_X1];
    m->v[VR_DX1] = -m->v[VR_K] * m->v[VR_X0] - m->v[VR_C] * m->v[VR_X1] + m->v[VR_U];
    m->v[VR_Y] = m->v[VR_X0] + 0.1 * m->v[VR_X1];
    if (MODE(m) == 1 && PAST(m)) m->v[VR_DX1] = NAN;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance inst, fmi3Boolean on, size_t n, const fmi3String cats[]) {
    (void)inst; (void)on; (void)n; (void)cats;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String resources,
                                          fmi3Boolean visible, fmi3Boolean logging, fmi3InstanceEnvironment env,
                                          fmi3LogMessageCallback log) {
    M *m;
    (void)name; (void)resources; (void)visible; (void)logging;
    if (!token || strcmp(token, TOKEN)) return NULL;
    m = calloc(1, sizeof(M));
    m->v[VR_X0] = 0.5, m->v[VR_K] = 4, m->v[VR_C] = 0.4, m->v[VR_LIMIT] = 1;
    m->state = INSTANTIATED, m->env = env, m->log = log;
    return m;
}

void fmi3FreeInstance(fmi3Instance inst) {
    M *m = inst;
    if (m && m->state == FATAL) note("VIOLATION fmi3FreeInstance in Fatal");
    free(m);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance inst, fmi3Boolean td, fmi3Float64 tol, fmi3Float64 t0,
                                       fmi3Boolean sd, fmi3Float64 t1) {
    M *m = inst;
    (void)td; (void)tol; (void)sd; (void)t1;
    CHECK(m, "fmi3EnterInitializationMode", INSTANTIATED);
    m->v[VR_TIME] = t0, m->state = INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance inst) {
    M *m = inst;
    CHECK(m, "fmi3ExitInitializationMode", INIT);
    derivs(m);
    m->state = EVENT;
    return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance inst, fmi3Boolean *update, fmi3Boolean *terminate,
                                    fmi3Boolean *nominals, fmi3Boolean *values, fmi3Boolean *defined,
                                    fmi3Float64 *next) {
    M *m = inst;
    CHECK(m, "fmi3UpdateDiscreteStates", EVENT);
    *update = *terminate = *nominals = *values = fmi3False;
    *defined = MODE(m) == 4;
    *next = 0.5;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance inst) {
    M *m = inst;
    CHECK(m, "fmi3EnterContinuousTimeMode", EVENT);
    m->state = CONT;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance inst) {
    M *m = inst;
    CHECK(m, "fmi3EnterEventMode", CONT);
    m->state = EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance inst) {
    M *m = inst;
    CHECK(m, "fmi3Terminate", EVENT | CONT);
    m->state = TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance inst) {
    M *m = inst;
    CHECK(m, "fmi3Reset", ANY | ERROR);
    return fmi3Error;
}

fmi3Status fmi3SetTime(fmi3Instance inst, fmi3Float64 t) {
    M *m = inst;
    CHECK(m, "fmi3SetTime", EVENT | CONT);
    m->v[VR_TIME] = t;
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance inst, const fmi3Float64 x[], size_t n) {
    M *m = inst;
    CHECK(m, "fmi3SetContinuousStates", CONT);
    if (n != 2) return fmi3Error;
    m->v[VR_X0] = x[0], m->v[VR_X1] = x[1];
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance inst, fmi3Float64 dx[], size_t n) {
    M *m = inst;
    CHECK(m, "fmi3GetContinuousStateDerivatives", INIT | EVENT | CONT | TERMINATED);
    if (n != 2) return fmi3Error;
    if (MODE(m) == 2 && PAST(m)) return fail(m, "fmi3GetContinuousStateDerivatives", fmi3Error, "x0 is past the limit");
    if (MODE(m) == 5 && PAST(m)) return fail(m, "fmi3GetContinuousStateDerivatives", fmi3Fatal, "x0 is past the limit");
    derivs(m);
    dx[0] = m->v[VR_DX0], dx[1] = m->v[VR_DX1];
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance inst, fmi3Float64 z[], size_t n) {
    M *m = inst;
    CHECK(m, "fmi3GetEventIndicators", INIT | EVENT | CONT | TERMINATED);
    if (n != 1) return fmi3Error;
    z[0] = MODE(m) == 3 ? m->v[VR_X0] - m->v[VR_LIMIT] : 1.0;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance inst, fmi3Boolean noSetPrior, fmi3Boolean *enter,
                                       fmi3Boolean *terminate) {
    M *m = inst;
    (void)noSetPrior;
    CHECK(m, "fmi3CompletedIntegratorStep", CONT);
    *enter = MODE(m) == 6 && PAST(m);
    *terminate = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    M *m = inst;
    size_t i;
    CHECK(m, "fmi3GetFloat64", INIT | EVENT | CONT | TERMINATED);
    if (n != nv) return fmi3Error;
    derivs(m);
    for (i = 0; i < n; i++) {
        if (vr[i] >= NVR) return fmi3Error;
        v[i] = m->v[vr[i]];
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance inst, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[],
                          size_t nv) {
    M *m = inst;
    size_t i;
    CHECK(m, "fmi3SetFloat64", INSTANTIATED | INIT | EVENT | CONT);
    if (n != nv) return fmi3Error;
    for (i = 0; i < n; i++) {
        int parameter = vr[i] >= VR_K, input = vr[i] == VR_U;
        if (!(parameter || input) || (parameter && !(m->state & (INSTANTIATED | INIT)))) {
            allowed(m, "fmi3SetFloat64 (this variable)", 0);
            return fmi3Error;
        }
        m->v[vr[i]] = v[i];
    }
    return fmi3OK;
}

/* d(der(x0), der(x1), y)/d(x0, x1, u): row by unknown, column by known */
static double partial(M *m, fmi3ValueReference unknown, fmi3ValueReference known) {
    double scale = MODE(m) == 7 ? 1.5 : 1.0;
    if (unknown == VR_DX0) return scale * (known == VR_X1);
    if (unknown == VR_DX1)
        return scale * (known == VR_X0 ? -m->v[VR_K] : known == VR_X1 ? -m->v[VR_C] : known == VR_U ? 1.0 : 0.0);
    if (unknown == VR_Y) return scale * (known == VR_X0 ? 1.0 : known == VR_X1 ? 0.1 : 0.0);
    return 0.0;
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance inst, const fmi3ValueReference unknowns[], size_t nu,
                                        const fmi3ValueReference knowns[], size_t nk, const fmi3Float64 seed[],
                                        size_t ns, fmi3Float64 sens[], size_t nsens) {
    M *m = inst;
    size_t i, j;
    CHECK(m, "fmi3GetDirectionalDerivative", INIT | EVENT | CONT | TERMINATED);
    if (ns != nk || nsens != nu) return fmi3Error;
    for (i = 0; i < nu; i++) {
        sens[i] = 0;
        for (j = 0; j < nk; j++) sens[i] += partial(m, unknowns[i], knowns[j]) * seed[j];
    }
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance inst, fmi3FMUState *state) {
    M *m = inst;
    M *copy;
    CHECK(m, "fmi3GetFMUState", ANY);
    copy = malloc(sizeof(M));
    memcpy(copy, m, sizeof(M));
    *state = copy;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance inst, fmi3FMUState state) {
    M *m = inst;
    CHECK(m, "fmi3SetFMUState", ANY | ERROR);
    memcpy(m, state, sizeof(M));
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance inst, fmi3FMUState *state) {
    M *m = inst;
    CHECK(m, "fmi3FreeFMUState", ANY | ERROR);
    free(*state);
    *state = NULL;
    return fmi3OK;
}
