/* A hand-written FMI 2.0 Co-Simulation test FMU of configurable cost per step, for the
 * parallel stepping of the master's native kernel (independent of pendulum-cosim).
 *
 * doStep integrates a driven pendulum x'' = -sin(x) + u over [t, t + h] with
 * round(work_us * SUBSTEPS_PER_US) semi-implicit Euler substeps: about work_us microseconds
 * of CPU on a current x86-64 core, and the same numbers on every run (the output depends on
 * work_us, u and h only). Outputs: x, and the CLOCK_MONOTONIC times [s] at which the last
 * doStep began and ended (to see which steps overlapped). Parameters choose a failure:
 * doStep number "fail_step" (1-based, 0 never) returns "fail_status" (3 error and 4 fatal
 * without making the step; 1 warning, and 2 discard with fmi2Terminated true and the step's
 * end as fmi2LastSuccessfulTime, after making it), saying so through the logger first; doStep
 * number "crash_step" dereferences NULL. */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "fmi2Functions.h"

#define GUID "{9d3e4b8a-2c61-4f0e-b7a5-31f6c2d8e9a4}"
#define SUBSTEPS_PER_US 60.0
enum { VR_U, VR_WORK_US, VR_X, VR_BEGAN, VR_ENDED, N_REAL };
enum { VR_FAIL_STEP, VR_FAIL_STATUS, VR_CRASH_STEP, N_INT };
typedef struct {
    double r[N_REAL], v, t;
    int p[N_INT], steps, terminated;
    fmi2CallbackFunctions cb;
    char name[64];
} Model;

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Model *m;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID)) return NULL;
    m = (Model *)calloc(1, sizeof(Model));
    if (!m) return NULL;
    if (cb) m->cb = *cb;
    strncpy(m->name, name ? name : "?", sizeof m->name - 1);
    m->r[VR_WORK_US] = 100.0;
    m->r[VR_X] = 0.5;
    m->p[VR_FAIL_STATUS] = 3;
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) { ((Model *)c)->t = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] >= N_REAL) return fmi2Error; v[i] = ((Model *)c)->r[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] > VR_WORK_US) return fmi2Error; ((Model *)c)->r[vr[i]] = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] >= N_INT) return fmi2Error; v[i] = ((Model *)c)->p[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] >= N_INT) return fmi2Error; ((Model *)c)->p[vr[i]] = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean nsp) {
    Model *m = (Model *)c;
    long n = lround(m->r[VR_WORK_US] * SUBSTEPS_PER_US);
    double dt, x = m->r[VR_X], v = m->v, u = m->r[VR_U];
    m->r[VR_BEGAN] = now();
    m->steps++;
    if (m->steps == m->p[VR_CRASH_STEP]) { volatile int *null = NULL; *null = 1; }
    if (m->steps == m->p[VR_FAIL_STEP] && m->cb.logger)
        m->cb.logger(m->cb.componentEnvironment, m->name, (fmi2Status)m->p[VR_FAIL_STATUS], "logStatusError",
                     "doStep %d of %s failed as asked (fail_step)", m->steps, m->name);
    if (m->steps == m->p[VR_FAIL_STEP] && m->p[VR_FAIL_STATUS] >= fmi2Error)
        return (fmi2Status)m->p[VR_FAIL_STATUS];
    if (n < 1) n = 1;
    dt = h / (double)n;
    for (long i = 0; i < n; i++) {
        v += dt * (u - sin(x));
        x += dt * v;
    }
    m->r[VR_X] = x;
    m->v = v;
    m->t = t + h;
    m->r[VR_ENDED] = now();
    if (m->steps != m->p[VR_FAIL_STEP]) return fmi2OK;
    m->terminated = m->p[VR_FAIL_STATUS] == fmi2Discard;  /* the step made, then the end asked */
    return (fmi2Status)m->p[VR_FAIL_STATUS];
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    if (s != fmi2Terminated) return fmi2Discard;
    *v = ((Model *)c)->terminated;
    return fmi2OK;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    if (s != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = ((Model *)c)->t;
    return fmi2OK;
}

/* the version functions, debug logging, and the functions not offered */
#include "../common/fmi2_cs_minimal.h"
