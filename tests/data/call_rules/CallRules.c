/* A hand-written FMI 2.0 Co-Simulation test FMU that checks its importer against the FMI
 * call rules (independent of pendulum-cosim). Every call is appended to the file named by
 * the environment variable CALL_RULES_LOG as "<instance> <function>"; a call the standard
 * forbids in the instance's state is written as "<instance> ILLEGAL <function> after
 * <state>". The rules checked: after a function returned fmi2Error only fmi2FreeInstance,
 * fmi2Reset and the status/logging functions; after fmi2Fatal nothing; nothing but
 * setters before initialisation is entered; doStep only after initialisation; after
 * fmi2FreeInstance nothing (the instance is kept, marked freed, to see such calls).
 *
 * Parameters choose a failure: "fail_step" (1-based doStep count, 0 never) returns
 * "fail_status" (1 warning, 2 discard, 3 error, 4 fatal); "fail_init" makes
 * ExitInitializationMode return fail_status; "crash_step" dereferences NULL in that doStep;
 * "hang_step" loops forever in that doStep. Output "x" = time, "y" = input "u". */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define GUID "{c3a1e7d2-5b90-4f11-8e2a-7d6c0b9f4a21}"
enum { S_INSTANTIATED, S_INIT, S_STEPPING, S_TERMINATED, S_ERROR, S_FATAL, S_FREED };
static const char *STATE[] = {"instantiated", "initialization", "stepping", "terminated", "error", "fatal", "freed"};
enum { VR_X, VR_U, VR_Y, VR_FAIL_STEP, VR_FAIL_STATUS, VR_FAIL_INIT, VR_CRASH_STEP, VR_HANG_STEP, N_VR };
typedef struct { double t, u; int p[N_VR]; int steps, state; char name[64]; } Model;

static void note(Model *m, const char *fn, int legal) {
    const char *path = getenv("CALL_RULES_LOG");
    FILE *f;
    if (!path || !(f = fopen(path, "a"))) return;
    if (legal) fprintf(f, "%s %s\n", m->name, fn);
    else fprintf(f, "%s ILLEGAL %s after %s\n", m->name, fn, STATE[m->state]);
    fclose(f);
}
/* may fn be called now? after error: only FreeInstance/Reset/status; after fatal/free: nothing */
static int enter(fmi2Component c, const char *fn, int status_like) {
    Model *m = (Model *)c;
    int legal = 1;
    if (m->state == S_FATAL || m->state == S_FREED) legal = 0;
    else if (m->state == S_ERROR && !status_like) legal = 0;
    note(m, fn, legal);
    return legal;
}
/* a call in the wrong state (e.g. doStep before initialisation): logged as illegal */
static int in_state(Model *m, const char *fn, int ok) {
    if (!ok) note(m, fn, 0);
    return ok;
}
static fmi2Status result(Model *m, fmi2Status s) {
    if (s == fmi2Error) m->state = S_ERROR;
    if (s == fmi2Fatal) m->state = S_FATAL;
    return s;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)on; (void)n; (void)cat;
    return enter(c, "fmi2SetDebugLogging", 1) ? fmi2OK : fmi2Error;
}
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Model *m;
    (void)loc; (void)cb; (void)vis; (void)log;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID)) return NULL;
    m = (Model *)calloc(1, sizeof(Model));
    strncpy(m->name, name ? name : "?", sizeof(m->name) - 1);
    m->p[VR_FAIL_STATUS] = 3;
    note(m, "fmi2Instantiate", 1);
    return m;
}
void fmi2FreeInstance(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2FreeInstance", m->state != S_FATAL)) return;
    m->state = S_FREED;            /* kept (leaked on purpose) to see calls after the free */
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) {
    Model *m = (Model *)c;
    (void)a; (void)b; (void)d; (void)e;
    if (!enter(c, "fmi2SetupExperiment", 0) || !in_state(m, "fmi2SetupExperiment", m->state == S_INSTANTIATED)) return fmi2Error;
    m->t = t0;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2EnterInitializationMode", 0) || !in_state(m, "fmi2EnterInitializationMode", m->state == S_INSTANTIATED)) return fmi2Error;
    m->state = S_INIT;
    return fmi2OK;
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2ExitInitializationMode", 0) || !in_state(m, "fmi2ExitInitializationMode", m->state == S_INIT)) return fmi2Error;
    m->state = S_STEPPING;
    return m->p[VR_FAIL_INIT] ? result(m, (fmi2Status)m->p[VR_FAIL_STATUS]) : fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2Terminate", 0)) return fmi2Error;
    if (!in_state(m, "fmi2Terminate", m->state == S_STEPPING)) return fmi2Error;
    m->state = S_TERMINATED;
    return fmi2OK;
}
fmi2Status fmi2Reset(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2Reset", 1)) return fmi2Error;
    m->state = S_INSTANTIATED; m->steps = 0;
    return fmi2OK;
}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2GetReal", 1)) return fmi2Error;     /* getters: allowed for inspection */
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_X) v[i] = m->t; else if (vr[i] == VR_Y || vr[i] == VR_U) v[i] = m->u; else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2SetReal", 0)) return fmi2Error;
    for (size_t i = 0; i < n; i++) { if (vr[i] != VR_U) return fmi2Error; m->u = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2GetInteger", 1)) return fmi2Error;
    for (size_t i = 0; i < n; i++) { if (vr[i] < VR_FAIL_STEP || vr[i] >= N_VR) return fmi2Error; v[i] = m->p[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!enter(c, "fmi2SetInteger", 0)) return fmi2Error;
    if (!in_state(m, "fmi2SetInteger", m->state == S_INSTANTIATED || m->state == S_INIT)) return fmi2Error;
    for (size_t i = 0; i < n; i++) { if (vr[i] < VR_FAIL_STEP || vr[i] >= N_VR) return fmi2Error; m->p[vr[i]] = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean nsp) {
    Model *m = (Model *)c;
    (void)nsp;
    if (!enter(c, "fmi2DoStep", 0)) return fmi2Error;
    if (!in_state(m, "fmi2DoStep", m->state == S_STEPPING)) return fmi2Error;
    m->steps++;
    if (m->steps == m->p[VR_CRASH_STEP]) { volatile int *null = NULL; *null = 1; }
    if (m->steps == m->p[VR_HANG_STEP]) { for (volatile int spin = 1; spin;) {} }
    if (m->steps == m->p[VR_FAIL_STEP]) return result(m, (fmi2Status)m->p[VR_FAIL_STATUS]);
    m->t = t + h;
    return fmi2OK;
}
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)s; if (!enter(c, "fmi2GetStatus", 1)) return fmi2Error; *v = fmi2OK; return fmi2OK;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)s; if (!enter(c, "fmi2GetRealStatus", 1)) return fmi2Error; *v = ((Model *)c)->t; return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)s; (void)v; return enter(c, "fmi2GetIntegerStatus", 1) ? fmi2Discard : fmi2Error;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s; if (!enter(c, "fmi2GetBooleanStatus", 1)) return fmi2Error; *v = fmi2False; return fmi2OK;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)s; (void)v; return enter(c, "fmi2GetStringStatus", 1) ? fmi2Discard : fmi2Error;
}

/* not used by a Co-Simulation importer: each call is logged as illegal */
#define NO(fn) { note((Model *)c, fn, 0); return fmi2Error; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { (void)vr; (void)n; (void)v; NO("fmi2GetBoolean") }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { (void)vr; (void)n; (void)v; NO("fmi2GetString") }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { (void)vr; (void)n; (void)v; NO("fmi2SetBoolean") }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { (void)vr; (void)n; (void)v; NO("fmi2SetString") }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; NO("fmi2GetFMUstate") }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)s; NO("fmi2SetFMUstate") }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; NO("fmi2FreeFMUstate") }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { (void)s; (void)n; NO("fmi2SerializedFMUstateSize") }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { (void)s; (void)b; (void)n; NO("fmi2SerializeFMUstate") }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { (void)b; (void)n; (void)s; NO("fmi2DeSerializeFMUstate") }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference k[], size_t nk, const fmi2Real dk[], fmi2Real du[]) { (void)u; (void)nu; (void)k; (void)nk; (void)dk; (void)du; NO("fmi2GetDirectionalDerivative") }
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]) { (void)vr; (void)n; (void)o; (void)v; NO("fmi2SetRealInputDerivatives") }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]) { (void)vr; (void)n; (void)o; (void)v; NO("fmi2GetRealOutputDerivatives") }
fmi2Status fmi2CancelStep(fmi2Component c) { NO("fmi2CancelStep") }
