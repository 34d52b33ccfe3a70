/* A hand-written FMI 3.0 Co-Simulation test FMU with typed ports (independent of
 * pendulum-cosim's generator): every output copies its input of the same type at once
 * (direct feedthrough), and "count" counts the doStep calls. Each typed getter refuses a
 * value reference of another type, as the Reference FMUs do. Functions this test does not
 * use are exported as stubs that return fmi3Error (fmpy loads every FMI 3.0 symbol). */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3PlatformTypes.h"

#define EXPORT __attribute__((visibility("default")))
#define OK 0
#define ERR 3
typedef struct { float f32[2]; int32_t i32[2]; bool b[2]; int64_t e[2]; double f64[2]; int64_t count; double t; } M;
/* value references: 1/2 float32 in/out, 3/4 int32, 5/6 bool, 7/8 enum, 9/10 float64, 11 count */

EXPORT const char *fmi3GetVersion(void) { return "3.0"; }
EXPORT void *fmi3InstantiateCoSimulation(const char *n, const char *tok, const char *res, bool vis, bool log,
                                         bool evt, bool early, const unsigned *req, size_t nreq, void *env,
                                         void *logcb, void *upd) {
    (void)n; (void)res; (void)vis; (void)log; (void)evt; (void)early; (void)req; (void)nreq; (void)env; (void)logcb; (void)upd;
    if (!tok || strcmp(tok, "{7f2d5c1e-3a44-4e0b-9a51-0c8f7d2e6b10}")) return NULL;
    M *m = calloc(1, sizeof(M));
    m->e[0] = m->e[1] = 1;
    return m;
}
EXPORT void fmi3FreeInstance(void *c) { free(c); }
EXPORT int fmi3EnterInitializationMode(void *c, bool tolDef, double tol, double start, bool stopDef, double stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop; ((M *)c)->t = start; return OK;
}
EXPORT int fmi3ExitInitializationMode(void *c) { (void)c; return OK; }
EXPORT int fmi3Terminate(void *c) { (void)c; return OK; }
EXPORT int fmi3SetDebugLogging(void *c, bool on, size_t n, const char *const cats[]) { (void)c; (void)on; (void)n; (void)cats; return OK; }

#define ACCESS(T, NAME, FIELD, VR_IN)                                                              \
EXPORT int fmi3Get##NAME(void *c, const unsigned vr[], size_t n, T v[], size_t nv) {              \
    M *m = c; if (nv != n) return ERR;                                                             \
    for (size_t i = 0; i < n; i++) {                                                               \
        if (vr[i] == VR_IN) v[i] = m->FIELD[0]; else if (vr[i] == VR_IN + 1) v[i] = m->FIELD[1];    \
        else return ERR; }                                                                         \
    return OK; }                                                                                   \
EXPORT int fmi3Set##NAME(void *c, const unsigned vr[], size_t n, const T v[], size_t nv) {        \
    M *m = c; if (nv != n) return ERR;                                                             \
    for (size_t i = 0; i < n; i++) {                                                               \
        if (vr[i] != VR_IN) return ERR;                                                            \
        m->FIELD[0] = v[i]; m->FIELD[1] = v[i]; }  /* feedthrough: the output follows at once */   \
    return OK; }
ACCESS(float, Float32, f32, 1)
ACCESS(int32_t, Int32, i32, 3)
ACCESS(bool, Boolean, b, 5)
ACCESS(double, Float64, f64, 9)

EXPORT int fmi3GetInt64(void *c, const unsigned vr[], size_t n, int64_t v[], size_t nv) {
    M *m = c; if (nv != n) return ERR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 7) v[i] = m->e[0]; else if (vr[i] == 8) v[i] = m->e[1];
        else if (vr[i] == 11) v[i] = m->count; else return ERR; }
    return OK;
}
EXPORT int fmi3SetInt64(void *c, const unsigned vr[], size_t n, const int64_t v[], size_t nv) {
    M *m = c; if (nv != n) return ERR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 7 || v[i] < 1 || v[i] > 3) return ERR;
        m->e[0] = m->e[1] = v[i]; }
    return OK;
}
EXPORT int fmi3DoStep(void *c, double t, double h, bool noSet, bool *evt, bool *term, bool *early, double *last) {
    M *m = c; (void)noSet;
    m->count++; m->t = t + h;
    *evt = false; *term = false; *early = false; *last = m->t;
    return OK;
}

#define STUB(name) EXPORT int name(void) { return ERR; }
STUB(fmi3InstantiateModelExchange) STUB(fmi3InstantiateScheduledExecution) STUB(fmi3EnterEventMode)
STUB(fmi3Reset) STUB(fmi3GetInt8) STUB(fmi3GetUInt8) STUB(fmi3GetInt16) STUB(fmi3GetUInt16)
STUB(fmi3GetUInt32) STUB(fmi3GetUInt64) STUB(fmi3GetString) STUB(fmi3GetBinary) STUB(fmi3GetClock)
STUB(fmi3SetInt8) STUB(fmi3SetUInt8) STUB(fmi3SetInt16) STUB(fmi3SetUInt16) STUB(fmi3SetUInt32)
STUB(fmi3SetUInt64) STUB(fmi3SetString) STUB(fmi3SetBinary) STUB(fmi3SetClock)
STUB(fmi3GetNumberOfVariableDependencies) STUB(fmi3GetVariableDependencies) STUB(fmi3GetFMUState)
STUB(fmi3SetFMUState) STUB(fmi3FreeFMUState) STUB(fmi3SerializedFMUStateSize) STUB(fmi3SerializeFMUState)
STUB(fmi3DeserializeFMUState) STUB(fmi3GetDirectionalDerivative) STUB(fmi3GetAdjointDerivative)
STUB(fmi3EnterConfigurationMode) STUB(fmi3ExitConfigurationMode) STUB(fmi3GetIntervalDecimal)
STUB(fmi3GetIntervalFraction) STUB(fmi3GetShiftDecimal) STUB(fmi3GetShiftFraction) STUB(fmi3SetIntervalDecimal)
STUB(fmi3SetIntervalFraction) STUB(fmi3SetShiftDecimal) STUB(fmi3SetShiftFraction) STUB(fmi3EvaluateDiscreteStates)
STUB(fmi3UpdateDiscreteStates) STUB(fmi3EnterContinuousTimeMode) STUB(fmi3CompletedIntegratorStep)
STUB(fmi3SetTime) STUB(fmi3SetContinuousStates) STUB(fmi3GetContinuousStateDerivatives)
STUB(fmi3GetEventIndicators) STUB(fmi3GetContinuousStates) STUB(fmi3GetNominalsOfContinuousStates)
STUB(fmi3GetNumberOfEventIndicators) STUB(fmi3GetNumberOfContinuousStates) STUB(fmi3EnterStepMode)
STUB(fmi3GetOutputDerivatives) STUB(fmi3ActivateModelPartition)
