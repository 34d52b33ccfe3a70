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
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "fmi2Functions.h"

#define GUID "{5e0c9b7a-3d1f-4a62-9c8e-1b2a4f6d8e03}"
enum { S_INSTANTIATED, S_INIT, S_STEPPING, S_TERMINATED, S_ERROR, S_FATAL, S_FREED };
static const char *STATE[] = {"instantiated", "initialization", "stepping", "terminated", "error", "fatal", "freed"};
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

static void note(Model *m, const char *fn, const char *what) {
    const char *path = getenv("CHAOS_LOG");
    FILE *f;
    if (!path || !(f = fopen(path, "a"))) return;
    if (what) fprintf(f, "%s %s %s\n", m->name, fn, what);
    else fprintf(f, "%s ILLEGAL %s after %s\n", m->name, fn, STATE[m->state]);
    fclose(f);
}
static uint64_t next(Model *m) {
    uint64_t x = m->rng ? m->rng : 0x9e3779b97f4a7c15ULL;
    x ^= x << 13; x ^= x >> 7; x ^= x << 17;
    return m->rng = x;
}
/* may fn be called now? after error: only FreeInstance/Reset/status; after fatal/free: nothing */
static int allowed(Model *m, const char *fn, int status_like) {
    if (m->state == S_FATAL || m->state == S_FREED || (m->state == S_ERROR && !status_like)) {
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

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)on; (void)n; (void)cat;
    return allowed((Model *)c, "fmi2SetDebugLogging", 1) ? fmi2OK : fmi2Error;
}
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Model *m;
    (void)loc; (void)vis; (void)log;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID)) return NULL;
    m = (Model *)calloc(1, sizeof(Model));
    if (!m) return NULL;
    strncpy(m->name, name ? name : "?", sizeof(m->name) - 1);
    if (cb) m->cb = *cb;
    m->sleep_us = 1000;
    note(m, "fmi2Instantiate", "OK");
    return m;
}
void fmi2FreeInstance(fmi2Component c) {
    Model *m = (Model *)c;
    if (!m || !allowed(m, "fmi2FreeInstance", m->state != S_FATAL)) return;
    note(m, "fmi2FreeInstance", "OK");
    m->state = S_FREED;            /* kept (leaked on purpose) to see calls after the free */
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) {
    Model *m = (Model *)c;
    (void)a; (void)b; (void)d; (void)e;
    if (!allowed(m, "fmi2SetupExperiment", 0)) return fmi2Error;
    if (m->state != S_INSTANTIATED) { note(m, "fmi2SetupExperiment", NULL); return fmi2Error; }
    m->t = t0;
    return done(m, "fmi2SetupExperiment", fmi2OK);
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Model *m = (Model *)c;
    if (!allowed(m, "fmi2EnterInitializationMode", 0)) return fmi2Error;
    if (m->state != S_INSTANTIATED) { note(m, "fmi2EnterInitializationMode", NULL); return fmi2Error; }
    m->state = S_INIT;
    m->rng = 0x2545f4914f6cdd1dULL * (uint64_t)(m->seed + 1);
    return done(m, "fmi2EnterInitializationMode", chaos(m, "fmi2EnterInitializationMode"));
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Model *m = (Model *)c;
    fmi2Status s;
    if (!allowed(m, "fmi2ExitInitializationMode", 0)) return fmi2Error;
    if (m->state != S_INIT) { note(m, "fmi2ExitInitializationMode", NULL); return fmi2Error; }
    s = chaos(m, "fmi2ExitInitializationMode");
    if (m->state == S_INIT) m->state = S_STEPPING;
    return done(m, "fmi2ExitInitializationMode", s);
}
fmi2Status fmi2Terminate(fmi2Component c) {
    Model *m = (Model *)c;
    if (!allowed(m, "fmi2Terminate", 0)) return fmi2Error;
    if (m->state != S_STEPPING) { note(m, "fmi2Terminate", NULL); return fmi2Error; }
    m->state = S_TERMINATED;
    return done(m, "fmi2Terminate", fmi2OK);
}
fmi2Status fmi2Reset(fmi2Component c) {
    Model *m = (Model *)c;
    if (!allowed(m, "fmi2Reset", 1)) return fmi2Error;
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
    if (!allowed(m, "fmi2GetReal", 1)) return fmi2Error;      /* getters: allowed for inspection */
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
    if (!allowed(m, "fmi2SetReal", 0)) return fmi2Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_U) m->u = v[i];
        else if (vr[i] == VR_RATE && (m->state == S_INSTANTIATED || m->state == S_INIT)) m->rate = v[i];
        else { logmsg(m, fmi2Error, "fmi2SetReal", "not settable"); m->state = S_ERROR; return done(m, "fmi2SetReal", fmi2Error); }
    }
    return done(m, "fmi2SetReal", chaos(m, "fmi2SetReal"));
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!allowed(m, "fmi2GetInteger", 1)) return fmi2Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_SEED) v[i] = m->seed; else if (vr[i] == VR_ACTIONS) v[i] = m->actions;
        else if (vr[i] == VR_SLEEP) v[i] = m->sleep_us; else return fmi2Error;
    }
    return done(m, "fmi2GetInteger", fmi2OK);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Model *m = (Model *)c;
    if (!allowed(m, "fmi2SetInteger", 0)) return fmi2Error;
    if (m->state != S_INSTANTIATED && m->state != S_INIT) { note(m, "fmi2SetInteger", NULL); return fmi2Error; }
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
    if (!allowed(m, "fmi2DoStep", 0)) return fmi2Error;
    if (m->state != S_STEPPING) { note(m, "fmi2DoStep", NULL); return fmi2Error; }
    m->poisoned = 0;
    s = chaos(m, "fmi2DoStep");
    if (s == fmi2OK || s == fmi2Warning) m->t = t + h;
    return done(m, "fmi2DoStep", s);
}
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)s; if (!allowed((Model *)c, "fmi2GetStatus", 1)) return fmi2Error; *v = fmi2OK; return fmi2OK;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    Model *m = (Model *)c;
    if (!allowed(m, "fmi2GetRealStatus", 1)) return fmi2Error;
    if (s != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = m->t;
    return done(m, "fmi2GetRealStatus", fmi2OK);
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)s; (void)v; return allowed((Model *)c, "fmi2GetIntegerStatus", 1) ? fmi2Discard : fmi2Error;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s; if (!allowed((Model *)c, "fmi2GetBooleanStatus", 1)) return fmi2Error; *v = fmi2False;
    return done((Model *)c, "fmi2GetBooleanStatus", fmi2OK);
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)s; (void)v; return allowed((Model *)c, "fmi2GetStringStatus", 1) ? fmi2Discard : fmi2Error;
}

/* not offered (canGetAndSetFMUstate etc. false): each call is logged as illegal */
#define NO(fn) { note((Model *)c, fn, NULL); return fmi2Error; }
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
