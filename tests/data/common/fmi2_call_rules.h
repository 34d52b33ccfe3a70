/* Shared by the hand-written FMI 2.0 test FMUs that log their calls and the call rules they
 * receive (Co-Simulation: tests/data/call_rules, tests/data/chaos; Model Exchange, which makes
 * its own instances: tests/data/me_faults); independent of pendulum-cosim's code.
 *
 * Include after defining CALL_LOG (the environment variable naming the call log), GUID and the
 * instance type Model (fields `char name[64]`, `int state`, one of the states below, and
 * `double t`, the time); the FMU
 * then defines
 *   static int enter(Model *m, const char *fn, int status_like);

 * which says whether fn may be called now (see forbidden) and logs the call as the FMU does.
 * The rules: after fmi2Error only fmi2FreeInstance, fmi2Reset and the status and logging
 * functions; after fmi2Fatal nothing; nothing after fmi2FreeInstance (the instance is kept,
 * marked freed, to see such calls). */
#ifndef FMI2_CALL_RULES_H
#define FMI2_CALL_RULES_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

enum { S_INSTANTIATED, S_INIT, S_STEPPING, S_TERMINATED, S_ERROR, S_FATAL, S_FREED };
static const char *STATE[] = {"instantiated", "initialization", "stepping", "terminated", "error", "fatal", "freed"};

/* A line of the call log: "<instance> <fn>" followed by `what` unless it is empty, or (what
 * NULL) a call the standard forbids, "<instance> ILLEGAL <fn> after <state>". */
static void note(Model *m, const char *fn, const char *what) {
    const char *path = getenv(CALL_LOG);
    FILE *f;
    if (!path || !(f = fopen(path, "a"))) return;
    if (!what) fprintf(f, "%s ILLEGAL %s after %s\n", m->name, fn, STATE[m->state]);
    else if (*what) fprintf(f, "%s %s %s\n", m->name, fn, what);
    else fprintf(f, "%s %s\n", m->name, fn);
    fclose(f);
}

/* 1 if the rules forbid a call now (status_like: a status, logging, reset or free function) */
static int forbidden(const Model *m, int status_like) {
    return m->state == S_FATAL || m->state == S_FREED || (m->state == S_ERROR && !status_like);
}

static int enter(Model *m, const char *fn, int status_like);

/* may fn be called now, `ok` saying whether the instance's state allows it (a call in the wrong
 * state, e.g. doStep before initialisation, is logged as illegal)? */
static int enter_in(Model *m, const char *fn, int ok) {
    if (!enter(m, fn, 0)) return 0;
    if (!ok) note(m, fn, NULL);
    return ok;
}

/* enter_in for a call that moves the instance from the state `from` to `to` */
static int enter_from(Model *m, const char *fn, int from, int to) {
    if (!enter_in(m, fn, m->state == from)) return 0;
    m->state = to;
    return 1;
}

/* A new instance named `name` (NULL: not a Co-Simulation instance of this FMU's GUID, or out of
 * memory). */
static Model *new_model(fmi2String name, fmi2Type type, fmi2String guid) {
    Model *m;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID)) return NULL;
    m = (Model *)calloc(1, sizeof(Model));
    if (m) strncpy(m->name, name ? name : "?", sizeof(m->name) - 1);
    return m;
}

/* fmi2FreeInstance: the instance is kept (leaked on purpose), marked freed, to see calls after
 * the free; 0 if the call was refused */
static int free_model(Model *m) {
    if (!m || !enter(m, "fmi2FreeInstance", m->state != S_FATAL)) return 0;
    m->state = S_FREED;
    return 1;
}

/* fmi2SetupExperiment: the start time t0 (0 if the call was refused) */
static int setup(Model *m, double t0) {
    if (!enter_in(m, "fmi2SetupExperiment", m->state == S_INSTANTIATED)) return 0;
    m->t = t0;
    return 1;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)on; (void)n; (void)cat;
    return enter((Model *)c, "fmi2SetDebugLogging", 1) ? fmi2OK : fmi2Error;
}
/* no asynchronous step: nothing pending, no integer or string status */
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)s;
    if (!enter((Model *)c, "fmi2GetStatus", 1)) return fmi2Error;
    *v = fmi2OK;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)s; (void)v; return enter((Model *)c, "fmi2GetIntegerStatus", 1) ? fmi2Discard : fmi2Error;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)s; (void)v; return enter((Model *)c, "fmi2GetStringStatus", 1) ? fmi2Discard : fmi2Error;
}

/* not offered: each call is logged as illegal */
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

#endif
