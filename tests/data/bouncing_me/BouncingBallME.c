/* A hand-written FMI 2.0 Model Exchange-only test FMU (independent of pendulum-cosim's
 * generator). States: ball height h and speed v (h' = v, v' = -g; a state event at h = 0
 * reverses the speed: v := -e v) and a first-order lag x (x' = (u - x)/tau, input u).
 * A time event every 0.25 s increments the Integer output "ticks". */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

enum { VR_H, VR_V, VR_X, VR_U, VR_G, VR_E, VR_TAU, VR_DH, VR_DV, VR_DX, NREAL };
typedef struct { double r[NREAL]; double t, next_tick; int ticks, bounces; fmi2CallbackFunctions cb; } M;
#define GUID "{3c0b0c52-58b9-4a86-8a0e-5b1f0e7d9e21}"

static void derivs(M *m) {
    m->r[VR_DH] = m->r[VR_V];
    m->r[VR_DV] = -m->r[VR_G];
    m->r[VR_DX] = (m->r[VR_U] - m->r[VR_X]) / m->r[VR_TAU];
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) { (void)c; (void)on; (void)n; (void)cats; return fmi2OK; }
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    (void)name; (void)loc; (void)vis; (void)log;
    if (type != fmi2ModelExchange || !guid || strcmp(guid, GUID)) return NULL;
    M *m = calloc(1, sizeof(M));
    m->cb = *cb;
    m->r[VR_H] = 1.0; m->r[VR_G] = 9.81; m->r[VR_E] = 0.7; m->r[VR_TAU] = 0.5;
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real tol, fmi2Real t0, fmi2Boolean b, fmi2Real t1) {
    (void)a; (void)tol; (void)b; (void)t1; ((M *)c)->t = t0; ((M *)c)->next_tick = t0 + 0.25; return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { derivs(c); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    M *m = c; derivs(m);
    for (size_t i = 0; i < n; i++) { if (vr[i] >= NREAL) return fmi2Error; v[i] = m->r[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    M *m = c;
    for (size_t i = 0; i < n; i++) { if (vr[i] >= VR_DH) return fmi2Error; m->r[vr[i]] = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    M *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 0) v[i] = m->ticks; else if (vr[i] == 1) v[i] = m->bounces; else return fmi2Error; }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
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
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) {
    M *m = c;
    memset(e, 0, sizeof(*e));
    if (m->r[VR_H] <= 1e-9 && m->r[VR_V] < 0) {     /* the bounce */
        m->r[VR_H] = 0; m->r[VR_V] = -m->r[VR_E] * m->r[VR_V]; m->bounces++;
        e->valuesOfContinuousStatesChanged = fmi2True;
    }
    if (m->t >= m->next_tick - 1e-12) { m->ticks++; m->next_tick += 0.25; }
    e->nextEventTimeDefined = fmi2True;
    e->nextEventTime = m->next_tick;
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean p, fmi2Boolean *enter, fmi2Boolean *term) {
    (void)c; (void)p; *enter = fmi2False; *term = fmi2False; return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((M *)c)->t = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    M *m = c; if (nx != 3) return fmi2Error;
    m->r[VR_H] = x[0]; m->r[VR_V] = x[1]; m->r[VR_X] = x[2]; return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    M *m = c; if (nx != 3) return fmi2Error;
    derivs(m); dx[0] = m->r[VR_DH]; dx[1] = m->r[VR_DV]; dx[2] = m->r[VR_DX]; return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) {
    M *m = c; if (nz != 1) return fmi2Error;
    z[0] = m->r[VR_H]; return fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    M *m = c; if (nx != 3) return fmi2Error;
    x[0] = m->r[VR_H]; x[1] = m->r[VR_V]; x[2] = m->r[VR_X]; return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)c; for (size_t i = 0; i < nx; i++) x[i] = 1.0; return fmi2OK;
}
