/* A hand-written FMI 2.0 Model Exchange test FMU whose calls fail on request (independent of
 * pendulum-cosim). State x: x' = u - x (input u), output y = x; a state event where x
 * crosses 0.5 counts "crossings"; a time event every 0.25 s counts "ticks".
 *
 * The Integer parameter "fault" chooses the call that returns fmi2Error: 1
 * fmi2GetNominalsOfContinuousStates (always: an exporter that left it unimplemented), 2
 * fmi2GetContinuousStates (always), 3 fmi2GetDerivatives from t = 0.5 s, 4
 * fmi2NewDiscreteStates from t = 0.5 s, 5 fmi2GetEventIndicators from t = 0.5 s, 6
 * fmi2GetNominalsOfContinuousStates from t = 0.5 s (it worked at the start); 0 none.
 *
 * Every call is appended to the file named by the environment variable ME_FAULTS_LOG as
 * "<instance> <function>"; a call the standard forbids (anything but fmi2FreeInstance,
 * fmi2Reset and logging after fmi2Error; anything after fmi2FreeInstance; a mode function
 * in the wrong mode) as "<instance> ILLEGAL <function> after <state>". */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define GUID "{5d0e2b7a-91c4-4e3f-a6b8-2f7c1d9e0a53}"
enum { S_INSTANTIATED, S_INIT, S_EVENT, S_CONT, S_TERMINATED, S_ERROR, S_FREED };
static const char *STATE[] = {"instantiated", "initialization", "event mode", "continuous-time mode", "terminated",
                              "error", "freed"};
enum { VR_X, VR_DX, VR_U, VR_T, NREAL };
enum { VR_FAULT, VR_CROSSINGS, VR_TICKS, NINT };
typedef struct { double r[NREAL]; int i[NINT]; int state, above; double next_tick; char name[64]; } M;

static void note(M *m, const char *fn, int legal) {
    const char *path = getenv("ME_FAULTS_LOG");
    FILE *f;
    if (!path || !(f = fopen(path, "a"))) return;
    if (legal) fprintf(f, "%s %s\n", m->name, fn);
    else fprintf(f, "%s ILLEGAL %s after %s\n", m->name, fn, STATE[m->state]);
    fclose(f);
}
/* fn called: allowed in the instance's state? (mask of states; after error/free: never) */
static int enter(fmi2Component c, const char *fn, unsigned states) {
    M *m = (M *)c;
    int legal = m->state != S_ERROR && m->state != S_FREED && (states & (1u << m->state));
    note(m, fn, legal);
    return legal;
}
#define ANY ((1u << S_INSTANTIATED) | (1u << S_INIT) | (1u << S_EVENT) | (1u << S_CONT) | (1u << S_TERMINATED))
#define RUNNING ((1u << S_EVENT) | (1u << S_CONT))
static fmi2Status fault(M *m, int which, int when) {
    if (m->i[VR_FAULT] != which || !when) return fmi2OK;
    m->state = S_ERROR;
    return fmi2Error;
}
#define LATE (m->r[VR_T] >= 0.5 - 1e-12)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)on; (void)n; (void)cats; note(c, "fmi2SetDebugLogging", 1); return fmi2OK;
}
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    (void)loc; (void)cb; (void)vis; (void)log;
    if (type != fmi2ModelExchange || !guid || strcmp(guid, GUID)) return NULL;
    M *m = calloc(1, sizeof(M));
    strncpy(m->name, name ? name : "?", sizeof(m->name) - 1);
    m->r[VR_X] = 1.0;
    note(m, "fmi2Instantiate", 1);
    return m;
}
void fmi2FreeInstance(fmi2Component c) {
    M *m = c;
    note(m, "fmi2FreeInstance", m->state != S_FREED);
    m->state = S_FREED;                  /* kept (leaked on purpose) to see calls after the free */
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real tol, fmi2Real t0, fmi2Boolean b, fmi2Real t1) {
    M *m = c; (void)a; (void)tol; (void)b; (void)t1;
    if (!enter(c, "fmi2SetupExperiment", 1u << S_INSTANTIATED)) return fmi2Error;
    m->r[VR_T] = t0; m->next_tick = t0 + 0.25; return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    if (!enter(c, "fmi2EnterInitializationMode", 1u << S_INSTANTIATED)) return fmi2Error;
    ((M *)c)->state = S_INIT; return fmi2OK;
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    if (!enter(c, "fmi2ExitInitializationMode", 1u << S_INIT)) return fmi2Error;
    M *m = c;
    m->state = S_EVENT; m->above = m->r[VR_X] > 0.5; return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) {
    if (!enter(c, "fmi2Terminate", RUNNING)) return fmi2Error;
    ((M *)c)->state = S_TERMINATED; return fmi2OK;
}
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    M *m = c;
    if (!enter(c, "fmi2GetReal", ANY)) return fmi2Error;
    m->r[VR_DX] = m->r[VR_U] - m->r[VR_X];
    for (size_t k = 0; k < n; k++) { if (vr[k] >= NREAL) return fmi2Error; v[k] = m->r[vr[k]]; }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    M *m = c;
    if (!enter(c, "fmi2SetReal", ANY)) return fmi2Error;
    for (size_t k = 0; k < n; k++) { if (vr[k] != VR_U && vr[k] != VR_X) return fmi2Error; m->r[vr[k]] = v[k]; }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    M *m = c;
    if (!enter(c, "fmi2GetInteger", ANY)) return fmi2Error;
    for (size_t k = 0; k < n; k++) { if (vr[k] >= NINT) return fmi2Error; v[k] = m->i[vr[k]]; }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    M *m = c;
    if (!enter(c, "fmi2SetInteger", 1u << S_INSTANTIATED)) return fmi2Error;
    for (size_t k = 0; k < n; k++) { if (vr[k] != VR_FAULT) return fmi2Error; m->i[VR_FAULT] = v[k]; }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { (void)c; (void)s; (void)n; return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { (void)c; (void)s; (void)b; (void)n; return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { (void)c; (void)b; (void)n; (void)s; return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference a[], size_t na,
                                        const fmi2ValueReference b[], size_t nb, const fmi2Real x[], fmi2Real y[]) {
    (void)c; (void)a; (void)na; (void)b; (void)nb; (void)x; (void)y; return fmi2Error;
}
fmi2Status fmi2EnterEventMode(fmi2Component c) {
    if (!enter(c, "fmi2EnterEventMode", 1u << S_CONT)) return fmi2Error;
    ((M *)c)->state = S_EVENT; return fmi2OK;
}
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) {
    M *m = c;
    if (!enter(c, "fmi2NewDiscreteStates", 1u << S_EVENT)) return fmi2Error;
    if (fault(m, 4, LATE)) return fmi2Error;
    memset(e, 0, sizeof(*e));
    if (m->r[VR_T] >= m->next_tick - 1e-12) { m->i[VR_TICKS]++; m->next_tick += 0.25; }
    if ((m->r[VR_X] > 0.5) != m->above) { m->i[VR_CROSSINGS]++; m->above = !m->above; }
    e->nextEventTimeDefined = fmi2True;
    e->nextEventTime = m->next_tick;
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    if (!enter(c, "fmi2EnterContinuousTimeMode", 1u << S_EVENT)) return fmi2Error;
    ((M *)c)->state = S_CONT; return fmi2OK;
}
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean p, fmi2Boolean *enter_, fmi2Boolean *term) {
    (void)p;
    if (!enter(c, "fmi2CompletedIntegratorStep", 1u << S_CONT)) return fmi2Error;
    *enter_ = fmi2False; *term = fmi2False; return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) {
    if (!enter(c, "fmi2SetTime", RUNNING)) return fmi2Error;
    ((M *)c)->r[VR_T] = t; return fmi2OK;
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    M *m = c;
    if (!enter(c, "fmi2SetContinuousStates", 1u << S_CONT) || nx != 1) return fmi2Error;
    m->r[VR_X] = x[0]; return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    M *m = c;
    if (!enter(c, "fmi2GetDerivatives", RUNNING) || nx != 1) return fmi2Error;
    if (fault(m, 3, LATE)) return fmi2Error;
    dx[0] = m->r[VR_U] - m->r[VR_X]; return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) {
    M *m = c;
    if (!enter(c, "fmi2GetEventIndicators", RUNNING) || nz != 1) return fmi2Error;
    if (fault(m, 5, LATE)) return fmi2Error;
    z[0] = m->r[VR_X] - 0.5; return fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    M *m = c;
    if (!enter(c, "fmi2GetContinuousStates", ANY) || nx != 1) return fmi2Error;
    if (fault(m, 2, 1)) return fmi2Error;
    x[0] = m->r[VR_X]; return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    M *m = c;
    if (!enter(c, "fmi2GetNominalsOfContinuousStates", ANY) || nx != 1) return fmi2Error;
    if (fault(m, 1, 1) || fault(m, 6, LATE)) return fmi2Error;
    x[0] = 1.0; return fmi2OK;
}
