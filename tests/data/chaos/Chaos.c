/* A hand-written FMI 2.0 Co-Simulation test FMU that misbehaves on purpose (independent of
 * pendulum-cosim): a master driving it must end every run normally or with a named error,
 * keep the rows so far, and follow the FMI call rules on every path.
 *
 * Each call an importer makes in a run (setting inputs, doStep, getting outputs, the
 * initialisation and termination calls) draws from a xorshift generator seeded by the
 * parameter "seed"; with probability "rate" it misbehaves in one of the ways the bit mask
 * "actions" allows: 1 return fmi2Warning, 2 fmi2Discard, 4 fmi2Error, 8 fmi2Fatal, 16 NaN
 * outputs, 32 inf outputs, 64 sleep "sleep_us" microseconds (then answer normally),
 * 128 crash (dereference NULL). Outputs: "x" = time, "y" = input "u" (feed-through),
 * "z" = 2 u + 1.
 *
 * Like tests/data/call_rules, every call is appended to the file named by CHAOS_LOG as
 * "<instance> <function> <status>", and a call the standard forbids in the instance's state
 * as "<instance> ILLEGAL <function> after <state>": after fmi2Error only fmi2FreeInstance,
 * fmi2Reset and the status/logging functions; after fmi2Fatal nothing; doStep only when
 * initialised; nothing after fmi2FreeInstance (the instance is kept, marked freed). */
#include <math.h>
#include <stdint.h>
#include <time.h>
#include "fmi2Functions.h"

#define CALL_LOG "CHAOS_LOG"
#define GUID "{5e0c9b7a-3d1f-4a62-9c8e-1b2a4f6d8e03}"
enum { VR_X, VR_U, VR_Y, VR_Z, VR_RATE, VR_SEED, VR_ACTIONS, VR_SLEEP, N_VR };
enum { A_WARNING = 1, A_DISCARD = 2, A_ERROR = 4, A_FATAL = 8, A_NAN = 16, A_INF = 32, A_SLEEP = 64, A_CRASH = 128 };
typedef struct {
    double t, u, rate;
    int seed, actions, sleep_us, state, poisoned;   /* poisoned: NaN/inf outputs until the next step */
    double poison;
    uint64_t rng;
    char name[64];
    fmi2CallbackFunctions cb;
} Model;

static const char *STATUS[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};

#include "../common/fmi2_call_rules.h"

static uint64_t next(Model *m) {
    uint64_t x = m->rng ? m->rng : 0x9e3779b97f4a7c15ULL;
    x ^= x << 13; x ^= x >> 7; x ^= x << 17;
    return m->rng = x;
}
/* may fn be called now? a forbidden call is logged as illegal (the others when they end) */
static int enter(Model *m, const char *fn, int status_like) {
    if (forbidden(m, status_like)) {
        note(m, fn, NULL);
        return 0;
    }
    return 1;
}
static void logmsg(Model *m, fmi2Status s, const char *fn, const char *text) {
    if (m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, s, "logStatusError", "%s: %s", fn, text);
}
/* the chaos of one call: the status to return (fmi2OK to behave) */
static fmi2Status chaos(Model *m, const char *fn) {
    int picks[8], n = 0;
    if (m->state != S_INIT && m->state != S_STEPPING) return fmi2OK;
    if ((double)(next(m) >> 11) / 9007199254740992.0 >= m->rate) return fmi2OK;
    for (int b = 0; b < 8; b++) if (m->actions & (1 << b)) picks[n++] = 1 << b;
    if (!n) return fmi2OK;
    switch (picks[next(m) % (uint64_t)n]) {
    case A_WARNING: logmsg(m, fmi2Warning, fn, "chaos: warning"); return fmi2Warning;
    case A_DISCARD: logmsg(m, fmi2Discard, fn, "chaos: discard"); return fmi2Discard;
    case A_ERROR: logmsg(m, fmi2Error, fn, "chaos: error"); m->state = S_ERROR; return fmi2Error;
    case A_FATAL: logmsg(m, fmi2Fatal, fn, "chaos: fatal"); m->state = S_FATAL; return fmi2Fatal;
    case A_NAN: m->poisoned = 1; m->poison = NAN; return fmi2OK;
    case A_INF: m->poisoned = 1; m->poison = (next(m) & 1) ? INFINITY : -INFINITY; return fmi2OK;
    case A_SLEEP: {
        struct timespec ts = {m->sleep_us / 1000000, (long)(m->sleep_us % 1000000) * 1000};
        nanosleep(&ts, NULL);
        return fmi2OK;
    }
    case A_CRASH: { volatile int *null = NULL; *null = 1; return fmi2Fatal; }
    }
    return fmi2OK;
}
static fmi2Status done(Model *m, const char *fn, fmi2Status s) {
    note(m, fn, STATUS[s]);
    return s;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Model *m = new_model(name, type, guid);
    (void)loc; (void)vis; (void)log;
    if (!m) return NULL;
    if (cb) m->cb = *cb;
    m->sleep_us = 1000;
    note(m, "fmi2Instantiate", "OK");
    return m;
}
void fmi2FreeInstance(fmi2Component c) {
    if (free_model((Model *)c)) note((Model *)c, "fmi2FreeInstance", "OK");
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) {
    (void)a; (void)b; (void)d; (void)e;
    return setup((Model *)c, t0) ? done((Model *)c, "fmi2SetupExperiment", fmi2OK) : fmi2Error;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter_from(m, "fmi2EnterInitializationMode", S_INSTANTIATED, S_INIT)) return fmi2Error;
    m->rng = 0x2545f4914f6cdd1dULL * (uint64_t)(m->seed + 1);
    return done(m, "fmi2EnterInitializationMode", chaos(m, "fmi2EnterInitializationMode"));
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Model *m = (Model *)c;
    fmi2Status s;
    if (!enter_in(m, "fmi2ExitInitializationMode", m->state == S_INIT)) return fmi2Error;
    s = chaos(m, "fmi2ExitInitializationMode");
    if (m->state == S_INIT) m->state = S_STEPPING;
    return done(m, "fmi2ExitInitializationMode", s);
}
fmi2Status fmi2Terminate(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter_from(m, "fmi2Terminate", S_STEPPING, S_TERMINATED)) return fmi2Error;
    return done(m, "fmi2Terminate", fmi2OK);
}
fmi2Status fmi2Reset(fmi2Component c) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2Reset", 1)) return fmi2Error;
    m->state = S_INSTANTIATED; m->poisoned = 0;
    return done(m, "fmi2Reset", fmi2OK);
}
static double value(Model *m, fmi2ValueReference vr) {
    double v = vr == VR_X ? m->t : vr == VR_Y || vr == VR_U ? m->u : vr == VR_Z ? 2 * m->u + 1 : m->rate;
    return m->poisoned && (vr == VR_Y || vr == VR_Z) ? m->poison : v;
}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Model *m = (Model *)c;
    fmi2Status s;
    if (!enter(m, "fmi2GetReal", 1)) return fmi2Error;      /* getters: allowed for inspection */
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_X && vr[i] != VR_U && vr[i] != VR_Y && vr[i] != VR_Z && vr[i] != VR_RATE) return fmi2Error;
        v[i] = value(m, vr[i]);
    }
    if (m->state == S_ERROR) return done(m, "fmi2GetReal", fmi2OK);
    s = chaos(m, "fmi2GetReal");
    if (s == fmi2OK && m->poisoned) for (size_t i = 0; i < n; i++) v[i] = value(m, vr[i]);
    return done(m, "fmi2GetReal", s);
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2SetReal", 0)) return fmi2Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_U) m->u = v[i];
        else if (vr[i] == VR_RATE && (m->state == S_INSTANTIATED || m->state == S_INIT)) m->rate = v[i];
        else { logmsg(m, fmi2Error, "fmi2SetReal", "not settable"); m->state = S_ERROR; return done(m, "fmi2SetReal", fmi2Error); }
    }
    return done(m, "fmi2SetReal", chaos(m, "fmi2SetReal"));
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2GetInteger", 1)) return fmi2Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_SEED) v[i] = m->seed; else if (vr[i] == VR_ACTIONS) v[i] = m->actions;
        else if (vr[i] == VR_SLEEP) v[i] = m->sleep_us; else return fmi2Error;
    }
    return done(m, "fmi2GetInteger", fmi2OK);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!enter_in(m, "fmi2SetInteger", m->state == S_INSTANTIATED || m->state == S_INIT)) return fmi2Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_SEED) m->seed = v[i]; else if (vr[i] == VR_ACTIONS) m->actions = v[i];
        else if (vr[i] == VR_SLEEP && v[i] >= 0 && v[i] <= 100000) m->sleep_us = v[i]; else return fmi2Error;
    }
    return done(m, "fmi2SetInteger", fmi2OK);
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean nsp) {
    Model *m = (Model *)c;
    fmi2Status s;
    (void)nsp;
    if (!enter_in(m, "fmi2DoStep", m->state == S_STEPPING)) return fmi2Error;
    m->poisoned = 0;
    s = chaos(m, "fmi2DoStep");
    if (s == fmi2OK || s == fmi2Warning) m->t = t + h;
    return done(m, "fmi2DoStep", s);
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    Model *m = (Model *)c;
    if (!enter(m, "fmi2GetRealStatus", 1)) return fmi2Error;
    if (s != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = m->t;
    return done(m, "fmi2GetRealStatus", fmi2OK);
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s; if (!enter((Model *)c, "fmi2GetBooleanStatus", 1)) return fmi2Error; *v = fmi2False;
    return done((Model *)c, "fmi2GetBooleanStatus", fmi2OK);
}
