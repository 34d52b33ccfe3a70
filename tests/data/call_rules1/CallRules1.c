/* A hand-written FMI 1.0 test FMU, Co-Simulation and Model Exchange in one library (the
 * model descriptions cs.xml, async.xml and me.xml choose the interface), that checks its
 * importer against the FMI 1.0 call sequences (independent of pendulum-cosim). Every call is
 * appended to the file named by the environment variable CALL_RULES_LOG as "<instance>
 * <function>"; a call the standard forbids in the instance's state as "<instance> ILLEGAL
 * <function> after <state>". The rules: nothing but setters (and fmiSetTime) before
 * initialisation; after fmiError only the free function (and fmiResetSlave); after fmiFatal
 * nothing; while a step is Pending only fmiGetStatus, fmiGetStringStatus and fmiCancelStep;
 * after fmiCancelStep only fmiResetSlave and the free function; after the free function
 * nothing (the instance is kept, marked freed, to see such calls).
 *
 * Co-Simulation: outputs time, y = u, ko = k, bo = b (Real, Integer, Boolean inputs).
 * "fail_step" (1-based fmiDoStep count, 0 never) returns "fail_status" (1 warning, 2 discard,
 * 3 error, 4 fatal, 5 pending: fmiGetStatus(fmiDoStepStatus) answers pending "pending_polls"
 * times, then ok, the step done); "fail_init" makes fmiInitializeSlave return fail_status;
 * "crash_step" dereferences NULL in that fmiDoStep.
 * Each failure is logged through the logger with the time ("%g" formatted).
 *
 * Model Exchange: state x' = u - x (x(0) = 1), a state event where x crosses 0.5 counts
 * "crossings", a time event every 0.25 s counts "ticks". "fail_call" makes a call return
 * fmiError: 1 fmiGetDerivatives from t = 0.5 s, 2 fmiEventUpdate from t = 0.5 s, 3
 * fmiGetNominalContinuousStates (always), 4 fmiInitialize. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi1Functions.h"

#define F(name) CallRules1_fmi##name
#define GUID "{8e4f1a2b-3c5d-4e6f-9a0b-1c2d3e4f5a61}"
enum { S_INSTANTIATED, S_RUNNING, S_PENDING, S_TERMINATED, S_ERROR, S_FATAL, S_CANCELLED, S_FREED };
static const char *STATE[] = {"instantiated", "initialized", "pending", "terminated", "error", "fatal", "cancelled",
                              "freed"};
enum { R_X, R_U, R_Y, R_DX, R_T, NR };
enum { I_K, I_KO, I_FAIL_STEP, I_FAIL_STATUS, I_FAIL_INIT, I_PENDING_POLLS, I_FAIL_CALL, I_CROSSINGS, I_TICKS,
       I_CRASH_STEP, NI };
enum { B_B, B_BO, NB };
typedef struct {
    double r[NR], t, next_tick, last_ok;
    int i[NI], b[NB], steps, state, polls, above;
    char name[64];
    fmi1CallbackFunctions cb;
} M;

static void note(M *m, const char *fn, int legal) {
    const char *path = getenv("CALL_RULES_LOG");
    FILE *f;
    if (!path || !(f = fopen(path, "a"))) return;
    if (legal) fprintf(f, "%s %s\n", m->name, fn);
    else fprintf(f, "%s ILLEGAL %s after %s\n", m->name, fn, STATE[m->state]);
    fclose(f);
}
#define BIT(s) (1u << (s))
#define LIVE (BIT(S_INSTANTIATED) | BIT(S_RUNNING) | BIT(S_TERMINATED))
/* fn called in a state of the mask `states`? logged either way */
static int enter(fmi1Component c, const char *fn, unsigned states) {
    M *m = (M *)c;
    int legal = (states & BIT(m->state)) != 0;
    note(m, fn, legal);
    return legal;
}
static fmi1Status fail(M *m, int status, const char *what) {
    if (status >= fmi1Error) m->state = status == fmi1Error ? S_ERROR : S_FATAL;
    if (m->cb.logger) m->cb.logger(m, m->name, (fmi1Status)status, "error", "%s failed on request at t = %g s",
                                   what, m->t);
    return (fmi1Status)status;
}

/* ---------------------------------------------------------------- common */
const char *F(GetVersion)(void) { return "1.0"; }
const char *F(GetTypesPlatform)(void) { return "standard32"; }
const char *F(GetModelTypesPlatform)(void) { return "standard32"; }
fmi1Status F(SetDebugLogging)(fmi1Component c, fmi1Boolean on) {
    (void)on; return enter(c, "fmiSetDebugLogging", LIVE) ? fmi1OK : fmi1Error;
}
static M *make(fmi1String name, fmi1String guid, fmi1CallbackFunctions cb) {
    if (!guid || strcmp(guid, GUID)) return NULL;
    M *m = calloc(1, sizeof(M));
    strncpy(m->name, name ? name : "?", sizeof(m->name) - 1);
    m->cb = cb;
    m->r[R_X] = 1.0; m->i[I_FAIL_STATUS] = 3; m->next_tick = 0.25;
    return m;
}
fmi1Status F(SetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Real v[]) {
    M *m = c;
    if (!enter(c, "fmiSetReal", BIT(S_INSTANTIATED) | BIT(S_RUNNING))) return fmi1Error;
    for (size_t k = 0; k < n; k++) { if (vr[k] != R_U && vr[k] != R_X) return fmi1Error; m->r[vr[k]] = v[k]; }
    return fmi1OK;
}
fmi1Status F(GetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1Real v[]) {
    M *m = c;
    if (!enter(c, "fmiGetReal", LIVE)) return fmi1Error;
    m->r[R_Y] = m->r[R_U]; m->r[R_DX] = m->r[R_U] - m->r[R_X]; m->r[R_T] = m->t;
    for (size_t k = 0; k < n; k++) { if (vr[k] >= NR) return fmi1Error; v[k] = m->r[vr[k]]; }
    return fmi1OK;
}
fmi1Status F(SetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Integer v[]) {
    M *m = c;
    if (!enter(c, "fmiSetInteger", BIT(S_INSTANTIATED) | BIT(S_RUNNING))) return fmi1Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] >= NI || vr[k] == I_KO || (vr[k] != I_K && m->state != S_INSTANTIATED)) return fmi1Error;
        m->i[vr[k]] = v[k];
    }
    return fmi1OK;
}
fmi1Status F(GetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1Integer v[]) {
    M *m = c;
    if (!enter(c, "fmiGetInteger", LIVE)) return fmi1Error;
    m->i[I_KO] = m->i[I_K];
    for (size_t k = 0; k < n; k++) { if (vr[k] >= NI) return fmi1Error; v[k] = m->i[vr[k]]; }
    return fmi1OK;
}
fmi1Status F(SetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Boolean v[]) {
    M *m = c;
    if (!enter(c, "fmiSetBoolean", BIT(S_INSTANTIATED) | BIT(S_RUNNING))) return fmi1Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != B_B || (v[k] != fmi1True && v[k] != fmi1False)) return fmi1Error;   /* exactly 0 or 1 */
        m->b[B_B] = v[k];
    }
    return fmi1OK;
}
fmi1Status F(GetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1Boolean v[]) {
    M *m = c;
    if (!enter(c, "fmiGetBoolean", LIVE)) return fmi1Error;
    m->b[B_BO] = m->b[B_B];
    for (size_t k = 0; k < n; k++) { if (vr[k] >= NB) return fmi1Error; v[k] = (fmi1Boolean)m->b[vr[k]]; }
    return fmi1OK;
}
fmi1Status F(SetString)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1String v[]) {
    (void)vr; (void)v; return enter(c, "fmiSetString", LIVE) && !n ? fmi1OK : fmi1Error;
}
fmi1Status F(GetString)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1String v[]) {
    (void)vr; (void)v; return enter(c, "fmiGetString", LIVE) && !n ? fmi1OK : fmi1Error;
}

/* ---------------------------------------------------------------- Co-Simulation */
fmi1Component F(InstantiateSlave)(fmi1String name, fmi1String guid, fmi1String location, fmi1String mime,
                                   fmi1Real timeout, fmi1Boolean visible, fmi1Boolean interactive,
                                   fmi1CallbackFunctions cb, fmi1Boolean log) {
    (void)location; (void)mime; (void)timeout; (void)visible; (void)interactive; (void)log;
    M *m = make(name, guid, cb);
    if (m) note(m, "fmiInstantiateSlave", 1);
    return m;
}
fmi1Status F(InitializeSlave)(fmi1Component c, fmi1Real t0, fmi1Boolean stop_defined, fmi1Real t1) {
    M *m = c; (void)stop_defined; (void)t1;
    if (!enter(c, "fmiInitializeSlave", BIT(S_INSTANTIATED))) return fmi1Error;
    m->t = m->last_ok = t0; m->state = S_RUNNING;
    return m->i[I_FAIL_INIT] ? fail(m, m->i[I_FAIL_STATUS], "fmiInitializeSlave") : fmi1OK;
}
fmi1Status F(TerminateSlave)(fmi1Component c) {
    if (!enter(c, "fmiTerminateSlave", BIT(S_RUNNING))) return fmi1Error;
    ((M *)c)->state = S_TERMINATED; return fmi1OK;
}
fmi1Status F(ResetSlave)(fmi1Component c) {
    M *m = c;
    if (!enter(c, "fmiResetSlave", LIVE | BIT(S_ERROR) | BIT(S_CANCELLED))) return fmi1Error;
    m->state = S_INSTANTIATED; m->steps = 0; return fmi1OK;
}
void F(FreeSlaveInstance)(fmi1Component c) {
    M *m = c;
    note(m, "fmiFreeSlaveInstance", m->state != S_FATAL && m->state != S_FREED && m->state != S_PENDING);
    m->state = S_FREED;            /* kept (leaked on purpose) to see calls after the free */
}
fmi1Status F(SetRealInputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Integer o[],
                                      const fmi1Real v[]) {
    (void)vr; (void)n; (void)o; (void)v; enter(c, "fmiSetRealInputDerivatives", 0); return fmi1Error;
}
fmi1Status F(GetRealOutputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Integer o[],
                                       fmi1Real v[]) {
    (void)vr; (void)n; (void)o; (void)v; enter(c, "fmiGetRealOutputDerivatives", 0); return fmi1Error;
}
fmi1Status F(CancelStep)(fmi1Component c) {
    if (!enter(c, "fmiCancelStep", BIT(S_PENDING))) return fmi1Error;
    ((M *)c)->state = S_CANCELLED; return fmi1OK;
}
fmi1Status F(DoStep)(fmi1Component c, fmi1Real t, fmi1Real h, fmi1Boolean new_step) {
    M *m = c;
    if (!enter(c, "fmiDoStep", BIT(S_RUNNING))) return fmi1Error;
    if (new_step != fmi1True || t < m->t - 1e-9 * (1 + t) || t > m->t + 1e-9 * (1 + t)) {
        note(m, "fmiDoStep (not newStep, or not at the last communication point)", 0);
        return fmi1Error;
    }
    m->steps++;
    if (m->steps == m->i[I_CRASH_STEP]) *(volatile int *)0 = 1;
    if (m->steps == m->i[I_FAIL_STEP]) {
        int st = m->i[I_FAIL_STATUS];
        if (st == 5) { m->state = S_PENDING; m->polls = m->i[I_PENDING_POLLS]; m->t = t + h; return (fmi1Status)5; }
        if (st == fmi1Discard) { m->last_ok = t; return fail(m, st, "fmiDoStep"); }
        if (st >= fmi1Error) return fail(m, st, "fmiDoStep");
        m->t = m->last_ok = t + h;
        return fail(m, st, "fmiDoStep");
    }
    m->t = m->last_ok = t + h;
    return fmi1OK;
}
fmi1Status F(GetStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Status *value) {
    M *m = c;
    if (!enter(c, "fmiGetStatus", BIT(S_PENDING) | LIVE) || s != fmi1DoStepStatus) return fmi1Discard;
    if (m->state == S_PENDING && m->polls > 0) { m->polls--; *value = (fmi1Status)5; return fmi1OK; }
    if (m->state == S_PENDING) { m->state = S_RUNNING; m->last_ok = m->t; }
    *value = fmi1OK;
    return fmi1OK;
}
fmi1Status F(GetRealStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Real *value) {
    M *m = c;
    if (!enter(c, "fmiGetRealStatus", LIVE) || s != fmi1LastSuccessfulTime) return fmi1Discard;
    *value = m->last_ok; return fmi1OK;
}
fmi1Status F(GetIntegerStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Integer *value) {
    (void)s; (void)value; enter(c, "fmiGetIntegerStatus", LIVE); return fmi1Discard;
}
fmi1Status F(GetBooleanStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Boolean *value) {
    (void)s; (void)value; enter(c, "fmiGetBooleanStatus", LIVE); return fmi1Discard;
}
fmi1Status F(GetStringStatus)(fmi1Component c, const fmi1StatusKind s, fmi1String *value) {
    (void)s; *value = "busy"; return enter(c, "fmiGetStringStatus", BIT(S_PENDING) | LIVE) ? fmi1OK : fmi1Error;
}

/* ---------------------------------------------------------------- Model Exchange */
#define ME_FAIL(n) (m->i[I_FAIL_CALL] == (n))
#define LATE (m->t >= 0.5 - 1e-12)
fmi1Component F(InstantiateModel)(fmi1String name, fmi1String guid, fmi1CallbackFunctions cb, fmi1Boolean log) {
    (void)log;
    cb.stepFinished = NULL;        /* not in Model Exchange's callbacks: never read */
    M *m = make(name, guid, cb);
    if (m) note(m, "fmiInstantiateModel", 1);
    return m;
}
void F(FreeModelInstance)(fmi1Component c) {
    M *m = c;
    note(m, "fmiFreeModelInstance", m->state != S_FATAL && m->state != S_FREED);
    m->state = S_FREED;
}
fmi1Status F(SetTime)(fmi1Component c, fmi1Real t) {
    if (!enter(c, "fmiSetTime", BIT(S_INSTANTIATED) | BIT(S_RUNNING))) return fmi1Error;
    ((M *)c)->t = t; return fmi1OK;
}
static void event_info(M *m, fmi1EventInfo *e) {
    memset(e, 0, sizeof(*e));
    e->iterationConverged = fmi1True;
    e->upcomingTimeEvent = fmi1True;
    e->nextEventTime = m->next_tick;
}
fmi1Status F(Initialize)(fmi1Component c, fmi1Boolean tol_controlled, fmi1Real rtol, fmi1EventInfo *e) {
    M *m = c; (void)tol_controlled; (void)rtol;
    if (!enter(c, "fmiInitialize", BIT(S_INSTANTIATED))) return fmi1Error;
    m->state = S_RUNNING; m->above = m->r[R_X] > 0.5; m->next_tick = m->t + 0.25;
    if (ME_FAIL(4)) return fail(m, fmi1Error, "fmiInitialize");
    event_info(m, e);
    return fmi1OK;
}
fmi1Status F(SetContinuousStates)(fmi1Component c, const fmi1Real x[], size_t nx) {
    if (!enter(c, "fmiSetContinuousStates", BIT(S_RUNNING)) || nx != 1) return fmi1Error;
    ((M *)c)->r[R_X] = x[0]; return fmi1OK;
}
fmi1Status F(CompletedIntegratorStep)(fmi1Component c, fmi1Boolean *call_event_update) {
    if (!enter(c, "fmiCompletedIntegratorStep", BIT(S_RUNNING))) return fmi1Error;
    *call_event_update = fmi1False; return fmi1OK;
}
fmi1Status F(GetDerivatives)(fmi1Component c, fmi1Real dx[], size_t nx) {
    M *m = c;
    if (!enter(c, "fmiGetDerivatives", BIT(S_RUNNING)) || nx != 1) return fmi1Error;
    if (ME_FAIL(1) && LATE) return fail(m, fmi1Error, "fmiGetDerivatives");
    dx[0] = m->r[R_U] - m->r[R_X]; return fmi1OK;
}
fmi1Status F(GetEventIndicators)(fmi1Component c, fmi1Real z[], size_t nz) {
    if (!enter(c, "fmiGetEventIndicators", BIT(S_RUNNING)) || nz != 1) return fmi1Error;
    z[0] = ((M *)c)->r[R_X] - 0.5; return fmi1OK;
}
fmi1Status F(EventUpdate)(fmi1Component c, fmi1Boolean intermediate, fmi1EventInfo *e) {
    M *m = c; (void)intermediate;
    if (!enter(c, "fmiEventUpdate", BIT(S_RUNNING))) return fmi1Error;
    if (ME_FAIL(2) && LATE) return fail(m, fmi1Error, "fmiEventUpdate");
    if (m->t >= m->next_tick - 1e-12) { m->i[I_TICKS]++; m->next_tick += 0.25; }
    if ((m->r[R_X] > 0.5) != m->above) { m->i[I_CROSSINGS]++; m->above = !m->above; }
    event_info(m, e);
    return fmi1OK;
}
fmi1Status F(GetContinuousStates)(fmi1Component c, fmi1Real x[], size_t nx) {
    if (!enter(c, "fmiGetContinuousStates", BIT(S_RUNNING)) || nx != 1) return fmi1Error;
    x[0] = ((M *)c)->r[R_X]; return fmi1OK;
}
fmi1Status F(GetNominalContinuousStates)(fmi1Component c, fmi1Real x[], size_t nx) {
    M *m = c;
    if (!enter(c, "fmiGetNominalContinuousStates", BIT(S_RUNNING)) || nx != 1) return fmi1Error;
    if (ME_FAIL(3)) return fail(m, fmi1Error, "fmiGetNominalContinuousStates");
    x[0] = 1.0; return fmi1OK;
}
fmi1Status F(GetStateValueReferences)(fmi1Component c, fmi1ValueReference vrx[], size_t nx) {
    if (!enter(c, "fmiGetStateValueReferences", BIT(S_RUNNING)) || nx != 1) return fmi1Error;
    vrx[0] = R_X; return fmi1OK;
}
fmi1Status F(Terminate)(fmi1Component c) {
    if (!enter(c, "fmiTerminate", BIT(S_RUNNING))) return fmi1Error;
    ((M *)c)->state = S_TERMINATED; return fmi1OK;
}
