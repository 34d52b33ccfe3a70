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
#define CALL_LOG "CALL_RULES_LOG"
#define GUID "{c3a1e7d2-5b90-4f11-8e2a-7d6c0b9f4a21}"
enum { VR_X, VR_U, VR_Y, VR_FAIL_STEP, VR_FAIL_STATUS, VR_FAIL_INIT, VR_CRASH_STEP, VR_HANG_STEP, N_VR };
typedef struct { double t, u; int p[N_VR]; int steps, state; char name[64]; } Model;

#include "../common/fmi2_call_rules.h"

/* may fn be called now? every call is logged, a forbidden one as illegal */
static int enter(Model *m, const char *fn, int status_like) {
    int legal = !forbidden(m, status_like);
    note(m, fn, legal ? "" : NULL);
    return legal;
}
static fmi2Status result(Model *m, fmi2Status s) {
    if (s == fmi2Error) m->state = S_ERROR;
    if (s == fmi2Fatal) m->state = S_FATAL;
    return s;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Model *m = new_model(name, type, guid);
    (void)loc; (void)cb; (void)vis; (void)log;
    if (!m) return NULL;
    m->p[VR_FAIL_STATUS] = 3;
    note(m, "fmi2Instantiate", "");
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free_model((Model *)c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) {
    (void)a; (void)b; (void)d; (void)e;
    return setup((Model *)c, t0) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    return enter_from((Model *)c, "fmi2EnterInitializationMode", S_INSTANTIATED, S_INIT) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter_from(m, "fmi2ExitInitializationMode", S_INIT, S_STEPPING)) return fmi2Error;
    return m->p[VR_FAIL_INIT] ? result(m, (fmi2Status)m->p[VR_FAIL_STATUS]) : fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) {
    return enter_from((Model *)c, "fmi2Terminate", S_STEPPING, S_TERMINATED) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2Reset(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2Reset", 1)) return fmi2Error;
    m->state = S_INSTANTIATED; m->steps = 0;
    return fmi2OK;
}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2GetReal", 1)) return fmi2Error;     /* getters: allowed for inspection */
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_X) v[i] = m->t; else if (vr[i] == VR_Y || vr[i] == VR_U) v[i] = m->u; else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2SetReal", 0)) return fmi2Error;
    for (size_t i = 0; i < n; i++) { if (vr[i] != VR_U) return fmi2Error; m->u = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2GetInteger", 1)) return fmi2Error;
    for (size_t i = 0; i < n; i++) { if (vr[i] < VR_FAIL_STEP || vr[i] >= N_VR) return fmi2Error; v[i] = m->p[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!enter_in(m, "fmi2SetInteger", m->state == S_INSTANTIATED || m->state == S_INIT)) return fmi2Error;
    for (size_t i = 0; i < n; i++) { if (vr[i] < VR_FAIL_STEP || vr[i] >= N_VR) return fmi2Error; m->p[vr[i]] = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean nsp) {
    Model *m = (Model *)c;
    (void)nsp;
    if (!enter_in(m, "fmi2DoStep", m->state == S_STEPPING)) return fmi2Error;
    m->steps++;
    if (m->steps == m->p[VR_CRASH_STEP]) { volatile int *null = NULL; *null = 1; }
    if (m->steps == m->p[VR_HANG_STEP]) { for (volatile int spin = 1; spin;) {} }
    if (m->steps == m->p[VR_FAIL_STEP]) return result(m, (fmi2Status)m->p[VR_FAIL_STATUS]);
    m->t = t + h;
    return fmi2OK;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)s; if (!enter((Model *)c, "fmi2GetRealStatus", 1)) return fmi2Error; *v = ((Model *)c)->t; return fmi2OK;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s; if (!enter((Model *)c, "fmi2GetBooleanStatus", 1)) return fmi2Error; *v = fmi2False; return fmi2OK;
}
