/* A hand-written FMI 2.0 Model Exchange test FMU whose calls fail on request (independent of
 * pendulum-cosim). State x: x' = u - x (input u), output x; a state event where x crosses 0.5
 * counts "crossings"; a time event every 0.25 s counts "ticks".
 *
 * The Integer parameter "fault" chooses the call that returns fmi2Error: 1
 * fmi2GetNominalsOfContinuousStates (always: an exporter that left it unimplemented), 2
 * fmi2GetContinuousStates (always), 3 fmi2GetDerivatives from t = 0.5 s, 4
 * fmi2NewDiscreteStates from t = 0.5 s, 5 fmi2GetEventIndicators from t = 0.5 s, 6
 * fmi2GetNominalsOfContinuousStates from t = 0.5 s (it worked at the start); 0 none.
 *
 * Every call is appended to the file named by the environment variable ME_FAULTS_LOG, a call
 * the standard forbids marked ILLEGAL (the rules of ../common/fmi2_call_rules.h, and each
 * Model Exchange function only in its mode: Event Mode or Continuous-Time Mode). */
#define CALL_LOG "ME_FAULTS_LOG"
#define GUID "{5d0e2b7a-91c4-4e3f-a6b8-2f7c1d9e0a53}"
enum { VR_X, VR_DX, VR_U };
enum { VR_FAULT, VR_CROSSINGS, VR_TICKS, NINT };
typedef struct { double t, x, u, next_tick; int i[NINT]; int state, event_mode, above; char name[64]; } Model;

#include "../common/fmi2_call_rules.h"

static int enter(Model *m, const char *fn, int status_like) {
    int legal = !forbidden(m, status_like);
    note(m, fn, legal ? "" : NULL);
    return legal;
}
/* may the Model Exchange function fn be called now (initialised, in Event Mode if `event`, in
 * Continuous-Time Mode if `continuous`)? */
static int in_mode(Model *m, const char *fn, int event, int continuous) {
    return enter_in(m, fn, m->state == S_STEPPING && (m->event_mode ? event : continuous));
}
/* fmi2Error if `fault` is the one chosen and `when` holds */
static fmi2Status fault(Model *m, int which, int when) {
    if (m->i[VR_FAULT] != which || !when) return fmi2OK;
    m->state = S_ERROR;
    return fmi2Error;
}
#define LATE (m->t >= 0.5 - 1e-12)

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Model *m;
    (void)loc; (void)cb; (void)vis; (void)log;
    if (type != fmi2ModelExchange || !guid || strcmp(guid, GUID) || !(m = calloc(1, sizeof(Model)))) return NULL;
    strncpy(m->name, name ? name : "?", sizeof(m->name) - 1);
    m->x = 1.0;
    note(m, "fmi2Instantiate", "");
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free_model((Model *)c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real tol, fmi2Real t0, fmi2Boolean b, fmi2Real t1) {
    Model *m = c; (void)a; (void)tol; (void)b; (void)t1;
    if (!setup(m, t0)) return fmi2Error;
    m->next_tick = t0 + 0.25;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    return enter_from(c, "fmi2EnterInitializationMode", S_INSTANTIATED, S_INIT) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Model *m = c;
    if (!enter_from(m, "fmi2ExitInitializationMode", S_INIT, S_STEPPING)) return fmi2Error;
    m->event_mode = 1; m->above = m->x > 0.5;
    return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) {
    return enter_from(c, "fmi2Terminate", S_STEPPING, S_TERMINATED) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Model *m = c;
    if (!enter(m, "fmi2GetReal", 1)) return fmi2Error;     /* getters: allowed for inspection */
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == VR_X) v[k] = m->x; else if (vr[k] == VR_DX) v[k] = m->u - m->x;
        else if (vr[k] == VR_U) v[k] = m->u; else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Model *m = c;
    if (!enter(m, "fmi2SetReal", 0)) return fmi2Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == VR_U) m->u = v[k]; else if (vr[k] == VR_X && m->state == S_INSTANTIATED) m->x = v[k];
        else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Model *m = c;
    if (!enter(m, "fmi2GetInteger", 1)) return fmi2Error;
    for (size_t k = 0; k < n; k++) { if (vr[k] >= NINT) return fmi2Error; v[k] = m->i[vr[k]]; }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Model *m = c;
    if (!enter_in(m, "fmi2SetInteger", m->state == S_INSTANTIATED)) return fmi2Error;
    for (size_t k = 0; k < n; k++) { if (vr[k] != VR_FAULT) return fmi2Error; m->i[VR_FAULT] = v[k]; }
    return fmi2OK;
}
fmi2Status fmi2EnterEventMode(fmi2Component c) {
    Model *m = c;
    if (!in_mode(m, "fmi2EnterEventMode", 0, 1)) return fmi2Error;
    m->event_mode = 1; return fmi2OK;
}
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) {
    Model *m = c;
    if (!in_mode(m, "fmi2NewDiscreteStates", 1, 0)) return fmi2Error;
    if (fault(m, 4, LATE)) return fmi2Error;
    memset(e, 0, sizeof(*e));
    if (m->t >= m->next_tick - 1e-12) { m->i[VR_TICKS]++; m->next_tick += 0.25; }
    if ((m->x > 0.5) != m->above) { m->i[VR_CROSSINGS]++; m->above = !m->above; }
    e->nextEventTimeDefined = fmi2True;
    e->nextEventTime = m->next_tick;
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    Model *m = c;
    if (!in_mode(m, "fmi2EnterContinuousTimeMode", 1, 0)) return fmi2Error;
    m->event_mode = 0; return fmi2OK;
}
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean p, fmi2Boolean *enter_, fmi2Boolean *term) {
    (void)p;
    if (!in_mode(c, "fmi2CompletedIntegratorStep", 0, 1)) return fmi2Error;
    *enter_ = fmi2False; *term = fmi2False; return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) {
    if (!in_mode(c, "fmi2SetTime", 1, 1)) return fmi2Error;
    ((Model *)c)->t = t; return fmi2OK;
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    if (!in_mode(c, "fmi2SetContinuousStates", 0, 1) || nx != 1) return fmi2Error;
    ((Model *)c)->x = x[0]; return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    Model *m = c;
    if (!in_mode(m, "fmi2GetDerivatives", 1, 1) || nx != 1) return fmi2Error;
    if (fault(m, 3, LATE)) return fmi2Error;
    dx[0] = m->u - m->x; return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) {
    Model *m = c;
    if (!in_mode(m, "fmi2GetEventIndicators", 1, 1) || nz != 1) return fmi2Error;
    if (fault(m, 5, LATE)) return fmi2Error;
    z[0] = m->x - 0.5; return fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    Model *m = c;
    if (!enter(m, "fmi2GetContinuousStates", 0) || nx != 1) return fmi2Error;
    if (fault(m, 2, 1)) return fmi2Error;
    x[0] = m->x; return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    Model *m = c;
    if (!enter(m, "fmi2GetNominalsOfContinuousStates", 0) || nx != 1) return fmi2Error;
    if (fault(m, 1, 1) || fault(m, 6, LATE)) return fmi2Error;
    x[0] = 1.0; return fmi2OK;
}
