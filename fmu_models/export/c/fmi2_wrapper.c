/* pendulum-cosim: FMI 2.0 Model Exchange + Co-Simulation wrapper around a model core
 * (core_api.h: a plant, an estimator or a signal). Every refused call returns fmi2Error with
 * a message through the logger callback. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include "fmi2Functions.h"
#include "core_api.h"
#include "wrapper_modes.h"

typedef struct {
    CoreData d;
    CoreWork wk;
    fmi2Type type;
    Mode mode;
    fmi2CallbackFunctions cb;
    char name[128];
    int logging;
    char err[ERRLEN];
} Instance;

static void logmsg(Instance *c, fmi2Status st, const char *cat, const char *fn, const char *text) {
    char msg[2 * ERRLEN + 200];
    size_t j = 0;
    char buf[ERRLEN + 200];
    if (!c || !c->cb.logger || (st < fmi2Warning && !c->logging)) return;
    snprintf(buf, sizeof buf, "%s: %s", fn, text);
    /* the logger treats the message as a printf format and '#' as a reference marker:
     * pass it with no arguments and every '%' and '#' doubled */
    for (size_t i = 0; buf[i] && j + 2 < sizeof msg; i++) {
        if (buf[i] == '%' || buf[i] == '#') msg[j++] = buf[i];
        msg[j++] = buf[i];
    }
    msg[j] = 0;
    c->cb.logger(c->cb.componentEnvironment, c->name, st, cat, msg);
}

#define STATUS fmi2Status
#define STATUS_OK fmi2OK
#define STATUS_ERROR fmi2Error
#define IS_CS(c) ((c)->type == fmi2CoSimulation)
#include "wrapper_common.h"

#define ALLOW(fn, mask) ALLOW_IN(comp, fn, mask)

/* ------------------------------------------------------------------ lifecycle */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    ALLOW("fmi2SetDebugLogging", ANY_LIVE | B(M_ERROR));
    (void)n; (void)cats;
    c->logging = on ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Instance *c;
    (void)loc; (void)visible;
    if (!cb || !cb->allocateMemory || !cb->freeMemory) return NULL;
    c = (Instance *)cb->allocateMemory(1, sizeof(Instance));
    if (!c) return NULL;
    memset(c, 0, sizeof(*c));
    c->cb = *cb;
    snprintf(c->name, sizeof c->name, "%s", name ? name : "");
    c->logging = logging ? 1 : 0;
    if (!guid || strcmp(guid, MODEL_GUID) != 0) {
        fail(c, "fmi2Instantiate", "GUID %s does not match this FMU's %s", guid ? guid : "(null)", MODEL_GUID);
        cb->freeMemory(c);
        return NULL;
    }
    if (type != fmi2CoSimulation && !(type == fmi2ModelExchange && CORE_HAS_ME)) {
        fail(c, "fmi2Instantiate", "this FMU has no %s interface",
             type == fmi2ModelExchange ? "Model Exchange" : "such");
        cb->freeMemory(c);
        return NULL;
    }
    c->type = type;
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (c) c->cb.freeMemory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean tolDef, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stopDef, fmi2Real stop) {
    ALLOW("fmi2SetupExperiment", B(M_INSTANTIATED));
    (void)tolDef; (void)tol;
    if (!isfinite(start)) return fail(c, "fmi2SetupExperiment", "start time must be finite");
    if (stopDef && !(stop >= start)) return fail(c, "fmi2SetupExperiment", "stop time %g < start time %g", stop, start);
    core_set_time(&c->d, start);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    ALLOW("fmi2EnterInitializationMode", B(M_INSTANTIATED));
    c->mode = M_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    ALLOW("fmi2ExitInitializationMode", B(M_INIT));
    if (core_exit_init(&c->wk, &c->d, c->err)) { c->mode = M_ERROR; return core(c, "fmi2ExitInitializationMode", 1); }
    c->mode = c->type == fmi2CoSimulation ? M_STEP : M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    ALLOW("fmi2Terminate", RUNNING | B(M_ERROR));
    c->mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    ALLOW("fmi2Reset", ANY_LIVE | B(M_ERROR));
    core_defaults(&c->d);
    c->mode = M_INSTANTIATED;
    return fmi2OK;
}

/* ------------------------------------------------------------------ values */
fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    ALLOW("fmi2GetReal", ANY_LIVE);
    return core(c, "fmi2GetReal", core_get_real(&c->wk, &c->d, vr, n, v, c->err));
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    ALLOW("fmi2SetReal", ANY_LIVE & ~B(M_TERMINATED));
    return core(c, "fmi2SetReal", core_set_real(&c->d, vr, n, v, BEFORE_RUN(c), c->err));
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    long long tmp;
    ALLOW("fmi2GetInteger", ANY_LIVE);
    for (size_t i = 0; i < n; i++) {
        if (core_get_int(&c->d, &vr[i], 1, &tmp, INT_NONE, c->err)) return core(c, "fmi2GetInteger", 1);
        v[i] = (fmi2Integer)tmp;
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    ALLOW("fmi2SetInteger", ANY_LIVE & ~B(M_TERMINATED));
    for (size_t i = 0; i < n; i++) {
        long long tmp = v[i];
        if (core_set_int(&c->d, &vr[i], 1, &tmp, INT_NONE, BEFORE_RUN(c), c->err)) return core(c, "fmi2SetInteger", 1);
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    ALLOW("fmi2GetBoolean", ANY_LIVE);
    for (size_t i = 0; i < n; i++) {
        int tmp;
        if (core_get_bool(&c->d, &vr[i], 1, &tmp, c->err)) return core(c, "fmi2GetBoolean", 1);
        v[i] = tmp ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    ALLOW("fmi2SetBoolean", ANY_LIVE & ~B(M_TERMINATED));
    for (size_t i = 0; i < n; i++) {
        int tmp = v[i] ? 1 : 0;
        if (core_set_bool(&c->d, &vr[i], 1, &tmp, BEFORE_RUN(c), c->err)) return core(c, "fmi2SetBoolean", 1);
    }
    return fmi2OK;
}

static fmi2Status no_such(Instance *c, const char *fn, const char *type, size_t n, const fmi2ValueReference vr[]) {
    return n ? fail(c, fn, "no %s variable has value reference %u", type, vr[0]) : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    ALLOW("fmi2GetString", ANY_LIVE); (void)v; return no_such(c, "fmi2GetString", "String", n, vr);
}
fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    ALLOW("fmi2SetString", ANY_LIVE); (void)v; return no_such(c, "fmi2SetString", "String", n, vr);
}

/* ------------------------------------------------------------------ FMU state */
fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *s) {
    ALLOW("fmi2GetFMUstate", ANY_LIVE);
    if (!s) return fail(c, "fmi2GetFMUstate", "FMUstate pointer is NULL");
    if (!*s && !(*s = c->cb.allocateMemory(1, sizeof(SavedState))))
        return fail(c, "fmi2GetFMUstate", "out of memory");
    save_state((SavedState *)*s, c);
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate s) {
    ALLOW("fmi2SetFMUstate", ANY_LIVE);
    return restore_state(c, "fmi2SetFMUstate", (const SavedState *)s);
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *s) {
    ALLOW("fmi2FreeFMUstate", ANY_LIVE | B(M_ERROR));
    if (s && *s) { c->cb.freeMemory(*s); *s = NULL; }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate s, size_t *size) {
    ALLOW("fmi2SerializedFMUstateSize", ANY_LIVE);
    (void)s;
    *size = sizeof(SavedState);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate s, fmi2Byte out[], size_t size) {
    ALLOW("fmi2SerializeFMUstate", ANY_LIVE);
    if (!s) return fail(c, "fmi2SerializeFMUstate", "FMUstate is NULL");
    if (size < sizeof(SavedState)) return fail(c, "fmi2SerializeFMUstate", "buffer of %zu bytes, need %zu", size, sizeof(SavedState));
    memcpy(out, s, sizeof(SavedState));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte in[], size_t size, fmi2FMUstate *s) {
    SavedState tmp;
    ALLOW("fmi2DeSerializeFMUstate", ANY_LIVE);
    if (deserialize_state((const unsigned char *)in, size, &tmp, c->err)) return core(c, "fmi2DeSerializeFMUstate", 1);
    if (!*s && !(*s = c->cb.allocateMemory(1, sizeof(SavedState))))
        return fail(c, "fmi2DeSerializeFMUstate", "out of memory");
    memcpy(*s, &tmp, sizeof tmp);
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference unk[], size_t nU,
                                        const fmi2ValueReference kn[], size_t nK,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    ALLOW("fmi2GetDirectionalDerivative", B(M_INIT) | RUNNING);
    if (!CORE_HAS_DERIVATIVES) return fail(c, "fmi2GetDirectionalDerivative", "not provided by this FMU");
    return core(c, "fmi2GetDirectionalDerivative",
                core_directional(&c->wk, &c->d, unk, nU, kn, nK, dvKnown, dvUnknown, c->err));
}

/* ------------------------------------------------------------------ Model Exchange */
fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    ALLOW("fmi2EnterEventMode", B(M_EVENT) | B(M_CONT));
    c->mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *e) {
    ALLOW("fmi2NewDiscreteStates", B(M_EVENT));
    memset(e, 0, sizeof(*e));   /* no discrete states, no events, no time events */
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    ALLOW("fmi2EnterContinuousTimeMode", B(M_EVENT));
    c->mode = M_CONT;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetPrior,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminate) {
    ALLOW("fmi2CompletedIntegratorStep", B(M_CONT));
    (void)noSetPrior;
    *enterEventMode = fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real t) {
    ALLOW("fmi2SetTime", B(M_EVENT) | B(M_CONT));
    if (!isfinite(t)) return fail(c, "fmi2SetTime", "time %g is not finite", t);
    core_set_time(&c->d, t);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    ALLOW("fmi2SetContinuousStates", B(M_CONT));
    return core(c, "fmi2SetContinuousStates", core_set_states(&c->d, x, nx, c->err));
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx) {
    ALLOW("fmi2GetDerivatives", B(M_INIT) | B(M_EVENT) | B(M_CONT) | B(M_TERMINATED));
    if (nx != CORE_NX) return fail(c, "fmi2GetDerivatives", "nx = %zu, this model has %d states", nx, CORE_NX);
    return core(c, "fmi2GetDerivatives", core_derivatives(&c->wk, &c->d, dx, c->err));
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real ind[], size_t ni) {
    ALLOW("fmi2GetEventIndicators", ANY_LIVE);
    (void)ind;
    return ni ? fail(c, "fmi2GetEventIndicators", "this model has no event indicators") : fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    ALLOW("fmi2GetContinuousStates", ANY_LIVE);
    if (nx != CORE_NX) return fail(c, "fmi2GetContinuousStates", "nx = %zu, this model has %d states", nx, CORE_NX);
    core_get_states(&c->d, x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nom[], size_t nx) {
    ALLOW("fmi2GetNominalsOfContinuousStates", ANY_LIVE);
    if (nx != CORE_NX) return fail(c, "fmi2GetNominalsOfContinuousStates", "nx = %zu, this model has %d states", nx, CORE_NX);
    for (size_t i = 0; i < nx; i++) nom[i] = 1.0;
    return fmi2OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    ALLOW("fmi2SetRealInputDerivatives", ANY_LIVE);
    (void)vr; (void)order; (void)v;
    return n ? fail(c, "fmi2SetRealInputDerivatives", "inputs are held constant over a step (canInterpolateInputs=false)") : fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    ALLOW("fmi2GetRealOutputDerivatives", ANY_LIVE);
    (void)vr; (void)order; (void)v;
    return n ? fail(c, "fmi2GetRealOutputDerivatives", "output derivatives are not provided (maxOutputDerivativeOrder=0)") : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    ALLOW("fmi2DoStep", B(M_STEP));
    (void)noSetPrior;
    return core(c, "fmi2DoStep", core_do_step(&c->wk, &c->d, t, h, c->err));
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    ALLOW("fmi2CancelStep", B(M_STEP));
    return fail(c, "fmi2CancelStep", "doStep is synchronous: nothing to cancel");
}

#define NO_STATUS(fn, T) fmi2Status fn(fmi2Component comp, const fmi2StatusKind s, T *v) { \
    ALLOW(#fn, ANY_LIVE); (void)s; (void)v; \
    return fail(c, #fn, "doStep is synchronous: there is no pending status"); }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetRealStatus, fmi2Real)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
NO_STATUS(fmi2GetStringStatus, fmi2String)
