/* Mass-spring-damper m x'' = F - k x - c x', FMI 2.0 Co-Simulation, written by hand for
 * the tests: a third-party FMU, independent of pendulum-cosim's FMU generator.
 * doStep integrates with 10 semi-implicit Euler substeps per communication step. */
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define GUID "{5f1c6c3e-0b7e-4a55-9d4b-2f0d7b1d9a01}"
typedef struct { double v[6]; double t; int steps; fmi2CallbackFunctions cb; } Model;
enum { M, K, C, POS, VEL, FORCE };

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
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { NO(); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) { NO(); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) { NO(); }
#include "../common/fmi2_cs_minimal.h"
