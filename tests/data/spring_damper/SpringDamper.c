/* Mass-spring-damper m x'' = F - k x - c x', FMI 2.0 Co-Simulation, written by hand for
 * the tests: a third-party FMU, independent of pendulum-cosim's FMU generator.
 * doStep integrates with 10 semi-implicit Euler substeps per communication step. */
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define GUID "{5f1c6c3e-0b7e-4a55-9d4b-2f0d7b1d9a01}"
typedef struct { double v[6]; double t; int steps; fmi2CallbackFunctions cb; } Model;
enum { M, K, C, POS, VEL, FORCE };

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Model *m;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID)) return NULL;
    m = (Model *)calloc(1, sizeof(Model));
    m->v[M] = 1.0; m->v[K] = 4.0; m->v[C] = 0.4; m->v[POS] = 1.0;
    if (cb) m->cb = *cb;
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) { ((Model *)c)->t = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return ((Model *)c)->v[M] > 0 ? fmi2OK : fmi2Error; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] > FORCE) return fmi2Error; v[i] = ((Model *)c)->v[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] > FORCE) return fmi2Error; ((Model *)c)->v[vr[i]] = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean nsp) {
    Model *m = (Model *)c;
    double dt = h / 10;
    for (int i = 0; i < 10; i++) {
        double a = (m->v[FORCE] - m->v[K] * m->v[POS] - m->v[C] * m->v[VEL]) / m->v[M];
        m->v[VEL] += dt * a;
        m->v[POS] += dt * m->v[VEL];
    }
    m->t = t + h;
    m->steps++;
    return fmi2OK;
}

/* everything below is unused by this model */
#define NO(x) return fmi2Error
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] != 0) return fmi2Error; v[i] = ((Model *)c)->steps; }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { NO(); }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { NO(); }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { NO(); }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { NO(); }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { NO(); }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { NO(); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { NO(); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { NO(); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { NO(); }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { NO(); }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { NO(); }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference k[], size_t nk, const fmi2Real dk[], fmi2Real du[]) { NO(); }
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]) { NO(); }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]) { NO(); }
fmi2Status fmi2CancelStep(fmi2Component c) { NO(); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { NO(); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) { NO(); }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { NO(); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) { NO(); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { NO(); }
fmi2Status fmi2EnterEventMode(fmi2Component c) { NO(); }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) { NO(); }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { NO(); }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean a, fmi2Boolean *b, fmi2Boolean *d) { NO(); }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { NO(); }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) { NO(); }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) { NO(); }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real e[], size_t n) { NO(); }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { NO(); }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { NO(); }
